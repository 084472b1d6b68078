"""Blocking single-session A2V client, a drop-in replacement for ``decart_oasis.A2VClient``.

Same constructor, methods, properties, errors and local checks as the official SDK (0.0.2).
Differences a caller can notice, all opt-in or strictly more robust:

- Transient gRPC failures (UNAVAILABLE, RESOURCE_EXHAUSTED; DEADLINE_EXCEEDED on Infer, which
  the server replays idempotently) are retried with the default :class:`RetryPolicy`; a final
  failure is a :class:`TransportError`, itself a ``grpc.RpcError`` like the official's.
  ``retry=RetryPolicy.never()`` restores the official single attempt.
- VP9 and JPEG are both offered (``accepted_formats``; add ``FrameFormat.RAW_RGB24`` for
  uncompressed frames from the embedded server: by default this drop-in decodes what the
  official client decodes); ``resize=(h, w)`` decodes straight to that size;
  ``prompt(..., seed=)`` picks the world; ``last_truth``, ``depth()`` and ``scene()`` reach the
  embedded simulator's ground truth, depth and scene layout, ``ping()`` the gRPC health service.
- ``close()`` inside a failing ``with`` block never hides the block's exception, and a failed
  ``__enter__`` releases the channel. The API key is masked in ``repr`` and error messages.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterable, Sequence
from types import TracebackType
from typing import Any

import grpc
import numpy as np
from grpc_health.v1 import health_pb2_grpc

from oasis_torchrl.client import health, wire
from oasis_torchrl.client.channel import TlsSetting, create_channel, parse_endpoint
from oasis_torchrl.client.decoding import decode_chunk, validate_resize
from oasis_torchrl.client.errors import MASK, DecartRoboticsError, TransportError
from oasis_torchrl.client.ground_truth import depth_maps, raise_sim_error
from oasis_torchrl.client.retry import RetryPolicy, call_with_retry
from oasis_torchrl.client.session import Call, SessionState
from oasis_torchrl.client.types import JPEG, VP9, A2VResult, FrameConsumer, StreamInfo
from oasis_torchrl.proto import a2v_pb2_grpc, sim_pb2, sim_pb2_grpc
from oasis_torchrl.protocol import API_KEY_ENV_VAR, CAMERAS, DEFAULT_ENDPOINT, ENDPOINT_ENV_VAR

logger = logging.getLogger(__name__)

# The decart-oasis release whose protocol this client speaks; the service may check it.
DEFAULT_SDK_VERSION = "0.0.2"


class A2VClient:
    """Sync client for one A2V session (drop-in for ``decart_oasis.A2VClient``).

    >>> client = A2VClient("http://127.0.0.1:1", api_key="secret-key")
    >>> "secret-key" in repr(client)
    False
    >>> client.infer([[0.0, 0.0]] * 4)
    Traceback (most recent call last):
    ...
    oasis_torchrl.client.errors.DecartRoboticsError: A2V session is not initialized
    >>> client.close()
    """

    def __init__(
        self,
        endpoint: str | None = None,
        *,
        api_key: str | None = None,
        client_sdk_version: str = DEFAULT_SDK_VERSION,
        timeout: float | None = 120.0,
        tls: TlsSetting = None,
        required_streams: Sequence[str] = CAMERAS,
        frame_consumer: FrameConsumer | None = None,
        stub: a2v_pb2_grpc.A2VServiceStub | None = None,
        channel: grpc.Channel | None = None,
        accepted_formats: Sequence[int] = (VP9, JPEG),
        resize: tuple[int, int] | None = None,
        retry: RetryPolicy | None = None,
    ) -> None:
        endpoint = DEFAULT_ENDPOINT if endpoint is None else endpoint
        if not endpoint and stub is None:
            raise ValueError("endpoint is required")
        self.endpoint = endpoint
        self.api_key = api_key if api_key is not None else os.getenv(API_KEY_ENV_VAR)
        self.client_sdk_version = client_sdk_version
        self.timeout = timeout
        self.tls = tls
        self.required_streams = tuple(required_streams)
        self.frame_consumer = frame_consumer
        self.accepted_formats = wire.accepted_format_list(accepted_formats, endpoint)
        self.resize = validate_resize(resize)
        self.retry = RetryPolicy() if retry is None else retry
        self._target = parse_endpoint(endpoint, tls).address if endpoint else None
        self._owned_channel = channel is None and stub is None
        self._channel = create_channel(endpoint, tls) if self._owned_channel else channel
        self._stub = stub if stub is not None else a2v_pb2_grpc.A2VServiceStub(self._channel)
        self._state = SessionState(
            self.api_key,
            sdk_version=client_sdk_version,
            accepted_formats=self.accepted_formats,
            required_streams=self.required_streams,
        )
        self._streams: tuple[StreamInfo, ...] = ()
        self._last_truth: sim_pb2.InferTruth | None = None

    @classmethod
    def from_env(
        cls,
        *,
        env_var: str = ENDPOINT_ENV_VAR,
        default_endpoint: str | None = DEFAULT_ENDPOINT,
        **kwargs: Any,
    ) -> A2VClient:
        """Create a client for the endpoint in ``env_var`` (else ``default_endpoint``).

        >>> client = A2VClient.from_env(env_var="UNSET_VARIABLE", default_endpoint="http://h:1")
        >>> client.endpoint
        'http://h:1'
        >>> client.close()
        """
        endpoint = os.getenv(env_var) or default_endpoint
        if not endpoint:
            raise DecartRoboticsError(f"{env_var} is not set")
        return cls(endpoint, **kwargs)

    @property
    def session_id(self) -> str | None:
        """The current session's id (None before initialize or after close)."""
        return self._state.session_id

    @property
    def streams(self) -> tuple[StreamInfo, ...]:
        """The streams the server advertised at initialize."""
        return self._streams

    @property
    def session_target(self) -> str | None:
        """The ``x-session-target`` pin the server returned at initialize, if any."""
        info = self._state.info
        return info.session_target if info else None

    @property
    def last_truth(self) -> sim_pb2.InferTruth | None:
        """Ground truth of the last Infer (embedded simulator only), else None."""
        return self._last_truth

    def __repr__(self) -> str:
        key = MASK if self.api_key else None
        return (
            f"{type(self).__name__}(endpoint={self.endpoint!r}, api_key={key!r}, "
            f"session_id={self.session_id!r})"
        )

    def __enter__(self) -> A2VClient:
        try:
            self.initialize()
        except BaseException:
            self._close_quietly()
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc is None:
            self.close()
        else:
            self._close_quietly()

    def initialize(self) -> tuple[StreamInfo, ...]:
        """Open a session: negotiate the frame format and check the required streams."""
        call = self._state.initialize()
        logger.info(
            "Initialize: endpoint=%s sdk_version=%s accepted_output_formats=%s",
            self.endpoint,
            self.client_sdk_version,
            [f.name for f in self.accepted_formats],
        )
        response, grpc_call = self._send(call)
        try:
            session = self._state.on_initialize(
                response, grpc_call.initial_metadata() if grpc_call else ()
            )
        except DecartRoboticsError:
            self._finish_quietly()
            raise
        self._streams = session.streams
        logger.info(
            "InitializeResponse: session_id=%s output_format=%s streams=%s",
            session.session_id,
            wire.format_name(session.output_format),
            [f"{s.name}({s.width}x{s.height})" for s in session.streams],
        )
        return session.streams

    def prompt(self, prompt: str, *, seed: int | None = None) -> None:
        """Set the scene (``seed`` picks the world; None lets the server use seed 0)."""
        response, _ = self._send(self._state.prompt(prompt, seed))
        self._state.on_prompt(response)
        if self.frame_consumer is not None:
            self.frame_consumer.new_clip()

    def infer(self, actions: Iterable[Iterable[float]]) -> A2VResult:
        """Send 4 ``[throttle, steering]`` actions; returns 4 decoded frames per stream."""
        call = self._state.infer(wire.validate_action_chunk(actions))
        response, grpc_call = self._send(call)
        reply = self._state.on_infer(response, grpc_call.trailing_metadata() if grpc_call else None)
        self._last_truth = reply.truth
        frames = self._decode_streams(reply.packets)
        if self.frame_consumer is not None:
            self.frame_consumer.submit(frames)
        return A2VResult(sequence_num=reply.sequence_num, frames=frames, streams=self.streams)

    def depth(self) -> dict[str, np.ndarray]:
        """Metric depth (float32 ``[H, W]``, sky +inf) of the last frame of each stream.

        Only the embedded simulator implements this (``oasis_torchrl.sim.v1.SimService``).
        """
        try:
            response, _ = self._send(self._state.depth())
        except TransportError as error:
            raise_sim_error(error, "depth")
        return depth_maps(response)

    def scene(self) -> sim_pb2.SceneResponse:
        """The static world of the current prompt and seed: road centreline and width, lanes,
        obstacles, the size of the car (for top-down views, e.g.
        :class:`~oasis_torchrl.client.scenes.SceneSource`).

        Only the embedded simulator implements this (``oasis_torchrl.sim.v1.SimService``).
        """
        try:
            response, _ = self._send(self._state.scene())
        except TransportError as error:
            raise_sim_error(error, "the scene")
        return response

    def ping(self) -> bool:
        """Ask the server's gRPC health service whether it is SERVING (False if unreachable)."""
        stub = health_pb2_grpc.HealthStub(self._require_channel("ping"))
        try:
            response, _ = self._call(
                stub.Check, "Check", health.health_request(), retry=RetryPolicy.never()
            )
        except TransportError as error:
            return health.ping_outcome(error)
        return health.is_serving(response)

    def close(self) -> None:
        """Finish the session (if any) and release the channel this client created."""
        try:
            self._finish()
        finally:
            if self._owned_channel and self._channel is not None:
                self._channel.close()
                self._channel = None

    def _finish(self) -> None:
        call = self._state.finish()
        if call is not None:
            response, _ = self._send(call)
            self._state.on_finish(response)

    def _finish_quietly(self) -> None:
        try:
            self._finish()
        except Exception:
            logger.warning("finishing the A2V session failed", exc_info=True)

    def _close_quietly(self) -> None:
        try:
            self.close()
        except Exception:
            logger.warning("closing the A2V client failed", exc_info=True)

    def _require_channel(self, feature: str) -> grpc.Channel:
        if self._channel is None:
            raise DecartRoboticsError(
                f"{feature} needs an open channel: the client is closed or was given only a stub"
            )
        return self._channel

    def _send(self, call: Call) -> tuple[Any, grpc.Call | None]:
        """Send one of the session's calls; returns the response and the gRPC call, if any."""
        if call.on_sim_service:
            stub = sim_pb2_grpc.SimServiceStub(self._require_channel(call.method))
        else:
            stub = self._stub
        method = getattr(stub, call.method)
        return self._call(method, call.method, call.request, call.metadata, with_call=True)

    def _call(
        self,
        method: Callable[..., Any],
        name: str,
        request: object,
        metadata: wire.Metadata = (),
        *,
        with_call: bool = False,
        retry: RetryPolicy | None = None,
    ) -> tuple[Any, grpc.Call | None]:
        """One unary call with retries; returns the response and, if asked, the call."""
        use_call = with_call and hasattr(method, "with_call")
        invoke = method.with_call if use_call else method
        kwargs = {"metadata": metadata}

        def attempt(timeout: float | None) -> Any:
            return invoke(request, timeout=timeout, **kwargs)

        result = call_with_retry(
            attempt,
            policy=self.retry if retry is None else retry,
            method=name,
            timeout=self.timeout,
            secret=self.api_key,
            target=self._target,
        )
        return result if use_call else (result, None)

    def _decode_streams(self, packets: dict[str, Sequence[bytes]]) -> dict[str, list[np.ndarray]]:
        """Decode each advertised stream's packets into one fresh ``[n, H, W, 3]`` array."""
        sizes = {s.name: self.resize or (s.height, s.width) for s in self.streams}
        frames: dict[str, list[np.ndarray]] = {}
        for name, stream_packets in packets.items():
            if name not in sizes:
                logger.warning("ignoring stream %r the server did not advertise", name)
                continue
            out = np.empty((len(stream_packets), *sizes[name], 3), np.uint8)
            decode_chunk(self._state.decoders[name], stream_packets, out)
            frames[name] = list(out)
        missing = set(self.required_streams) - set(frames)
        if missing:
            raise DecartRoboticsError(
                "A2V response did not include required streams: " + ", ".join(sorted(missing))
            )
        return frames
