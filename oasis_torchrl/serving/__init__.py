"""A trained policy served over the network: ``oasis-torchrl serve-policy``.

- :mod:`.server`: the gRPC service (``oasis_torchrl.policy.v1.PolicyService``) and
  :class:`~oasis_torchrl.serving.server.PolicyServer`.
- :mod:`.served`: the loaded policy (any driver :func:`~oasis_torchrl.drivers.load_driver`
  names); :mod:`.host`: loading and state; :mod:`.batching`: one forward pass for concurrent
  requests; :mod:`.sessions`: SelectAction's queues; :mod:`.limits`: per-key limits.

The client that drives with a served policy is :mod:`oasis_torchrl.remote`.
"""
