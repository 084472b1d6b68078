"""``oasis-torchrl serve-policy PATH``: serve a trained policy over gRPC until SIGTERM or
SIGINT (settings: :class:`~oasis_torchrl.config.policy_serving.ServePolicyConfig`).

The policy is named as everywhere else (:func:`~oasis_torchrl.drivers.load_driver`): a shipped
policy (``pretrained:ppo-scratch``), a LeRobot policy folder, a PPO checkpoint, a TorchScript
or ``torch.save`` file (a plain module with its inputs declared: ``--input
pixels.front:uint8:4x64x96x3 --input state:float32:2``). It loads in the background while the
server already answers Status. Clients drive with ``RemotePolicy("grpc://host:port")`` or
``oasis-torchrl eval policy=grpc://host:port``. API keys are better passed in
``OASIS_POLICY_SERVER_API_KEYS`` than with ``--api-key``: command lines are visible to every
user of the machine.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

from omegaconf import DictConfig

from oasis_torchrl.config import to_object
from oasis_torchrl.config.policy_serving import ServePolicyConfig

logger = logging.getLogger(__name__)

NAME = "serve-policy"
HELP = "serve a trained policy over gRPC (batched, API keys) until SIGTERM/SIGINT"
CONFIG = ServePolicyConfig


def run(settings: DictConfig) -> int:
    """Start the server and load the policy in the background, serve until a signal, then
    stop cleanly. A policy that fails to load is reported by Status (and logged) while the
    server runs on; exit code 2 when the policy does not exist or the server cannot start.

    Example:
        >>> from oasis_torchrl.config import load_config
        >>> run(load_config("serve-policy", ["policy=nowhere.pt", "api_keys=[k]"]))
        2
    """
    import torch

    from oasis_torchrl.drivers.pretrained import resolve_pretrained
    from oasis_torchrl.serving.served import load_served_policy
    from oasis_torchrl.serving.server import PolicyServer
    from oasis_torchrl.sim.serving import wait_for_signal, write_port_file

    cfg: ServePolicyConfig = to_object(settings)
    try:
        policy = resolve_pretrained(cfg.policy)
    except ValueError as error:
        logger.error("cannot serve %s: %s", cfg.policy, error)
        return 2
    if not Path(policy).exists():
        logger.error("cannot serve %s: no such file or folder", cfg.policy)
        return 2
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    inputs = cfg.input_features()
    server = PolicyServer(cfg, lambda: load_served_policy(policy, inputs), name=cfg.policy)
    try:
        server.start()
    except (OSError, RuntimeError) as error:
        logger.error("cannot start the policy server: %s", error)
        return 2
    if cfg.port_file is not None:
        write_port_file(Path(cfg.port_file), server.port)
    logger.info("serving %s on %s; stop with SIGTERM or Ctrl-C", cfg.policy, server.endpoint)
    try:
        wait_for_signal(threading.Event())
    finally:
        logger.info("shutting down")
        server.stop(cfg.grace)
    return 0
