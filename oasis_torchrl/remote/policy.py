"""``RemotePolicy``: a policy served by ``oasis-torchrl serve-policy``, used like a local one.

It is a TorchRL policy module (``env.rollout(n, RemotePolicy("grpc://host:port"))``) reading
the policy's inputs from the TensorDict and writing ``"action"`` (the next actions of each
row's queue on the server; a row starting an episode drops its queue first), and it has
LeRobot's inference calls (``select_action``, ``predict_action_chunk``, ``reset``). Transient faults
(UNAVAILABLE, a per-key limit) are retried with capped, jittered backoff
(:class:`~oasis_torchrl.client.retry.RetryPolicy`); failures are typed
(:mod:`oasis_torchrl.remote.errors`). Observations are checked against the policy's inputs
before they are sent, so a bad one fails with the same message without a round trip.
"""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TypeVar

import grpc
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase

from oasis_torchrl.client.channel import TlsSetting, create_channel
from oasis_torchrl.client.errors import TransportError
from oasis_torchrl.client.retry import RetryPolicy, call_with_retry
from oasis_torchrl.closing import Closing
from oasis_torchrl.proto import policy_pb2, policy_pb2_grpc
from oasis_torchrl.protocol import (
    API_KEY_METADATA,
    CHUNK,
    POLICY_API_KEY_ENV_VAR,
    POLICY_SCHEMES,
)
from oasis_torchrl.remote.errors import (
    AuthError,
    InvalidInputError,
    RequestTooLargeError,
    UnavailableError,
    is_too_large,
    typed_error,
)
from oasis_torchrl.remote.features import Feature, check_observation
from oasis_torchrl.remote.tensors import decode, decode_map, encode_map

_Response = TypeVar("_Response")
Observation = Mapping[str, torch.Tensor] | TensorDictBase
STEP_COUNT = "step_count"
EPISODE_SEED = "episode_seed"
STATES = {
    policy_pb2.STATE_LOADING: "loading",
    policy_pb2.STATE_READY: "ready",
    policy_pb2.STATE_FAILED: "failed",
}


def is_policy_url(spec: str) -> bool:
    """Whether ``spec`` names a policy server (``grpc://host:port`` or ``grpcs://``).

    Example:
        >>> is_policy_url("grpc://127.0.0.1:50052"), is_policy_url("policy.pt")
        (True, False)
    """
    return spec.startswith(tuple(POLICY_SCHEMES))


def channel_endpoint(url: str) -> tuple[str, bool | None]:
    """The gRPC endpoint of a policy URL and whether it uses TLS (None: as the endpoint says).

    Example:
        >>> channel_endpoint("grpcs://policy.example:443"), channel_endpoint("localhost:5")
        (('policy.example:443', True), ('localhost:5', None))
    """
    for scheme, tls in POLICY_SCHEMES.items():
        if url.startswith(scheme):
            return url.removeprefix(scheme), tls
    return url, None


@dataclass(frozen=True)
class PolicyStatus:
    """What a policy server says of its policy: ``loading``, ``ready`` or ``failed`` (with
    the reason)."""

    state: str
    reason: str
    policy: str


@dataclass(frozen=True)
class PolicyDescription:
    """What a policy reads and writes, and what the server accepts per request."""

    inputs: tuple[Feature, ...]
    action: Feature
    chunk_size: int
    n_action_steps: int
    policy: str
    max_batch_rows: int
    max_request_bytes: int

    @classmethod
    def from_proto(cls, message: policy_pb2.DescribeResponse) -> PolicyDescription:
        """The description a Describe answer holds."""
        return cls(
            inputs=tuple(Feature.from_proto(feature) for feature in message.inputs),
            action=Feature.from_proto(message.action),
            chunk_size=message.chunk_size,
            n_action_steps=message.n_action_steps,
            policy=message.policy,
            max_batch_rows=message.max_batch_rows,
            max_request_bytes=message.max_request_bytes,
        )


class RemotePolicy(TensorDictModuleBase, Closing):
    """A policy on a policy server, as a TorchRL policy module and a LeRobot-style policy.

    Construction waits for the server's policy to be ready and reads its description
    (inputs, action, chunk size); the module's ``in_keys`` are the policy's inputs.

    As a TorchRL module it writes the next ``actions`` actions of each row's queue on the
    server: a world-model chunk ``[N, 4, 2]`` by default, as an in-process driver does (a row
    whose queue is empty gets a new chunk from its observation). A row starting an episode (its
    ``"step_count"`` is 0, or, without one, its ``"episode_seed"`` changed) drops its queue first.

    Args:
        endpoint: ``grpc://host:port`` (plain text), ``grpcs://host:port`` (TLS), or
            ``host:port`` with ``tls``.
        api_key: the key (default: ``$OASIS_POLICY_API_KEY``).
        actions: actions per row ``forward`` writes: ``[N, actions, ...]``, or one action
            ``[N, ...]`` with None (an env built with ``chunk_actions=False``).
        session_id: the session of this client's action queues (default: a fresh random id).
        timeout: seconds per call attempt.
        retry: the retry policy of transient faults.
        tls: TLS for a ``host:port`` endpoint (a bool or ``grpc.ChannelCredentials``).
        wait: seconds to wait for the policy to be ready (None: do not wait).

    Example:
        >>> from oasis_torchrl.config.policy_serving import PolicyServerConfig
        >>> from oasis_torchrl.drivers import PolicyDriver
        >>> from oasis_torchrl.models import DrivingNet
        >>> from oasis_torchrl.serving.served import ServedPolicy
        >>> from oasis_torchrl.serving.server import PolicyServer
        >>> net = lambda: ServedPolicy.of_driver(PolicyDriver.of_network(DrivingNet()), "net")
        >>> with PolicyServer(PolicyServerConfig(api_keys=("secret",)), net) as server:
        ...     with RemotePolicy(server.endpoint, api_key="secret") as policy:
        ...         observation = policy.sample_input(batch_size=2)
        ...         chunk = policy.predict_action_chunk(observation)
        ...         first = policy.select_action(observation)
        ...         rest = policy.next_actions(observation, 3)
        >>> policy.in_keys[-1], chunk.shape, first.shape, policy.image_size
        ('state', torch.Size([2, 4, 2]), torch.Size([2, 2]), (64, 96))
        >>> torch.equal(torch.cat([first.unsqueeze(1), rest], dim=1), chunk)
        True
    """

    def __init__(
        self,
        endpoint: str,
        *,
        api_key: str | None = None,
        actions: int | None = CHUNK,
        session_id: str | None = None,
        timeout: float = 30.0,
        retry: RetryPolicy | None = None,
        tls: TlsSetting = None,
        wait: float | None = 60.0,
    ) -> None:
        super().__init__()
        if actions is not None and actions < 1:
            raise ValueError(f"actions must be >= 1 or None, got {actions}")
        address, scheme_tls = channel_endpoint(endpoint)
        key = api_key or _key_from_env()
        self.endpoint = endpoint
        self.actions = actions
        self.session_id = session_id or uuid.uuid4().hex
        self.timeout = timeout
        self.retry = retry or RetryPolicy()
        self._key = key
        self._metadata = ((API_KEY_METADATA, key),)
        self._channel = create_channel(address, scheme_tls if tls is None else tls)
        self._stub = policy_pb2_grpc.PolicyServiceStub(self._channel)
        if wait is not None:
            self.wait_until_ready(wait)
        self.description = self.describe()
        self.in_keys = [feature.key for feature in self.description.inputs]
        self.out_keys = ["action"]
        self._episodes: torch.Tensor | None = None  # each row's last episode seed

    # -- LeRobot-style inference ---------------------------------------------------------

    def predict_action_chunk(self, observation: Observation) -> torch.Tensor:
        """The policy's chunk for each row: ``[rows, chunk_size, *action.shape]``."""
        request = policy_pb2.PredictChunkRequest()
        encode_map(self._checked(observation), request.observation)
        response = self._call("PredictChunk", self._stub.PredictChunk, request)
        return decode(response.actions, "actions")

    def select_action(self, observation: Observation) -> torch.Tensor:
        """The next action of each row, ``[rows, *action.shape]``, from this client's session
        queues on the server (a row whose queue is empty gets a new chunk)."""
        return self.next_actions(observation, 1)[:, 0]

    def next_actions(self, observation: Observation, count: int) -> torch.Tensor:
        """The next ``count`` actions of each row's queue, ``[rows, count, *action.shape]``
        (a queue that runs out is refilled from the same observation)."""
        request = policy_pb2.SelectActionRequest(session_id=self.session_id, count=count)
        encode_map(self._checked(observation), request.observation)
        response = self._call("SelectAction", self._stub.SelectAction, request)
        return decode(response.actions, "actions")

    def reset(self, rows: Sequence[int] | None = None) -> None:
        """Drop the queued actions of ``rows`` (default: all) of this client's session; call it
        at the start of every episode."""
        request = policy_pb2.ResetRequest(session_id=self.session_id, rows=list(rows or ()))
        self._call("Reset", self._stub.Reset, request)

    # -- the server ------------------------------------------------------------------------

    def ping(self) -> str:
        """The server's version (the server is up and the key is accepted)."""
        return self._call("Ping", self._stub.Ping, policy_pb2.PingRequest()).server_version

    def status(self) -> PolicyStatus:
        """Whether the policy is loading, ready or failed (with the reason)."""
        response = self._call("Status", self._stub.Status, policy_pb2.StatusRequest())
        return PolicyStatus(STATES.get(response.state, "unknown"), response.reason, response.policy)

    def wait_until_ready(self, timeout: float) -> PolicyStatus:
        """Poll :meth:`status` until the policy is ready; :class:`UnavailableError` if it failed
        to load or is not ready within ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        polls = 0
        while True:
            try:
                status = self.status()
            except UnavailableError:  # the server is not up yet
                if time.monotonic() >= deadline:
                    raise
            else:
                if status.state == "ready":
                    return status
                if status.state == "failed":
                    raise self._unavailable(f"the policy {status.policy} failed: {status.reason}")
                if time.monotonic() >= deadline:
                    raise self._unavailable(
                        f"the policy {status.policy} is not ready in {timeout} s"
                    )
            time.sleep(min(0.05 * 2**polls, 1.0, max(deadline - time.monotonic(), 0.0)))
            polls += 1

    def describe(self) -> PolicyDescription:
        """The policy's inputs, action and chunk size, and the server's request limits."""
        response = self._call("Describe", self._stub.Describe, policy_pb2.DescribeRequest())
        return PolicyDescription.from_proto(response)

    def sample_input(self, batch_size: int = 1, seed: int = 0) -> dict[str, torch.Tensor]:
        """A valid random observation of ``batch_size`` rows, made by the server."""
        request = policy_pb2.SampleInputRequest(batch_size=batch_size, seed=seed)
        return decode_map(self._call("SampleInput", self._stub.SampleInput, request).observation)

    @property
    def input_features(self) -> dict[str, Feature]:
        """The policy's inputs by name."""
        return {feature.name: feature for feature in self.description.inputs}

    @property
    def output_features(self) -> dict[str, Feature]:
        """The policy's output (one action) by name."""
        return {self.description.action.name: self.description.action}

    @property
    def image_size(self) -> tuple[int, int] | None:
        """``(height, width)`` of the frames the policy looks at (channels-last images), or
        None if it reads no image."""
        image = self._image_shape()
        return None if image is None else (image[-3], image[-2])

    @property
    def frame_stack(self) -> int | None:
        """Frames per camera the policy reads (the leading axis of its ``[K, H, W, 3]`` image
        inputs), or None if it reads single frames or no image."""
        image = self._image_shape()
        return image[0] if image is not None and len(image) == 4 else None

    def _image_shape(self) -> tuple[int, ...] | None:
        """The shape of the policy's first channels-last uint8 image input, if any."""
        for feature in self.description.inputs:
            if feature.dtype == torch.uint8 and len(feature.shape) >= 3 and feature.shape[-1] == 3:
                return tuple(feature.shape)
        return None

    # -- TorchRL ---------------------------------------------------------------------------

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Write ``"action"``: the next ``actions`` actions of each row (see the class)."""
        starting = self._episode_starts(tensordict)
        if starting:
            self.reset(rows=starting)
        chosen = self.next_actions(self.observation_of(tensordict), self.actions or 1)
        action = chosen if self.actions else chosen[:, 0]
        tensordict.set("action", action.to(tensordict.device or "cpu"))
        return tensordict

    def _episode_starts(self, tensordict: TensorDictBase) -> list[int]:
        """Rows starting an episode: ``"step_count"`` 0, or a changed ``"episode_seed"``."""
        counter = tensordict.get(STEP_COUNT, None)
        if counter is not None:
            return counter.reshape(len(counter), -1)[:, 0].eq(0).nonzero()[:, 0].tolist()
        seeds = tensordict.get(EPISODE_SEED, None)
        if seeds is None:
            return []
        seeds = seeds.reshape(len(seeds), -1)[:, 0].cpu()
        previous, self._episodes = self._episodes, seeds.clone()
        if previous is None or previous.shape != seeds.shape:
            return list(range(len(seeds)))
        return seeds.ne(previous).nonzero()[:, 0].tolist()

    def observation_of(self, tensordict: TensorDictBase) -> dict[str, torch.Tensor]:
        """The policy's inputs read from a TensorDict with one batch dimension. Where the env
        gives more frames than the policy reads (its 4 frames per chunk), the newest ones go:
        the last 2 for a policy reading 2 frames, the last one for a policy reading a frame."""
        return {
            feature.name: _newest(tensordict.get(feature.key), feature.shape)
            for feature in self.description.inputs
        }

    def close(self) -> None:
        """Close the channel."""
        self._channel.close()

    # -- calls -----------------------------------------------------------------------------

    def _checked(self, observation: Observation) -> Mapping[str, torch.Tensor]:
        if isinstance(observation, TensorDictBase):
            observation = self.observation_of(observation)
        try:
            check_observation(observation, self.description.inputs, self.description.max_batch_rows)
        except ValueError as error:
            raise InvalidInputError(
                grpc.StatusCode.INVALID_ARGUMENT, str(error), method="check", target=self.endpoint
            ) from None
        return observation

    def _call(self, method: str, rpc: Callable[..., _Response], request: object) -> _Response:
        def attempt(timeout: float | None) -> _Response:
            try:
                return rpc(request, metadata=self._metadata, timeout=timeout)
            except grpc.RpcError as error:
                if is_too_large(error):  # permanent: no retry
                    raise RequestTooLargeError(
                        grpc.StatusCode.RESOURCE_EXHAUSTED,
                        f"{error.details()}: send fewer rows per call",
                        method=method,
                        target=self.endpoint,
                    ) from None
                raise

        try:
            return call_with_retry(
                attempt,
                policy=self.retry,
                method=method,
                timeout=self.timeout,
                secret=self._key,
                target=self.endpoint,
            )
        except RequestTooLargeError:
            raise
        except TransportError as error:
            raise typed_error(error) from None

    def _unavailable(self, text: str) -> UnavailableError:
        return UnavailableError(
            grpc.StatusCode.UNAVAILABLE, text, method="wait_until_ready", target=self.endpoint
        )


def _newest(value: torch.Tensor, shape: tuple[int, ...]) -> torch.Tensor:
    """``value`` ``[N, ...]`` cut to ``[N, *shape]`` along its time axis (dimension 1), keeping
    the newest entries, when only that axis is longer or extra; else as it is."""
    rows_shape = (value.shape[0], *shape)
    if value.dim() == len(rows_shape) + 1 and value.shape[2:] == shape:
        return value[:, -1]
    if shape and value.dim() == len(rows_shape) and value.shape[2:] == shape[1:]:
        return value[:, -shape[0] :] if value.shape[1] > shape[0] else value
    return value


def _key_from_env() -> str:
    key = os.environ.get(POLICY_API_KEY_ENV_VAR)
    if not key:
        raise AuthError(
            grpc.StatusCode.UNAUTHENTICATED,
            f"no API key: pass api_key= or set {POLICY_API_KEY_ENV_VAR}",
            method="connect",
        )
    return key
