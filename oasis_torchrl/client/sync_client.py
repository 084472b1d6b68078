"""Blocking single-session A2V client, a drop-in replacement for ``decart_oasis.A2VClient``.

Same constructor, methods, properties, errors and local checks as the official SDK (0.0.2).
Differences a caller can notice, all opt-in or strictly more robust:

- Transient gRPC failures (UNAVAILABLE, RESOURCE_EXHAUSTED; DEADLINE_EXCEEDED on Infer, which
  the server replays idempotently) are retried with the default :class:`RetryPolicy`; a final
  failure is a :class:`TransportError`, itself a ``grpc.RpcError`` like the official's.
  ``retry=RetryPolicy.never()`` restores the official single attempt.
- VP9 and JPEG are both offered (``accepted_formats``); ``resize=(h, w)`` decodes straight to
  that size; ``prompt(..., seed=)`` picks the world; ``last_truth``, ``depth()`` and ``ping()``
  reach the embedded simulator's extras.
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

from oasis_torchrl.client import extras, wire
from oasis_torchrl.client.channel import TlsSetting, create_channel, parse_endpoint
from oasis_torchrl.client.decoding import (
    FrameDecoder,
    decode_chunk,
    make_decoder,
    validate_resize,
)
from oasis_torchrl.client.errors import (
    MASK,
    DecartRoboticsError,
    TransportError,
)
from oasis_torchrl.client.retry import RetryPolicy, call_with_retry
from oasis_torchrl.client.types import (
    JPEG,
    VP9,
    A2VResult,
    FrameConsumer,
    StreamInfo,
)
from oasis_torchrl.proto import a2v_pb2, a2v_pb2_grpc, sim_pb2, sim_pb2_grpc
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
        self.accepted_formats = wire.accepted_format_list(accepted_formats)
        self.resize = validate_resize(resize)
        self.retry = RetryPolicy() if retry is None else retry
        self._target = parse_endpoint(endpoint, tls).address if endpoint else None
        self._owned_channel = channel is None and stub is None
        self._channel = create_channel(endpoint, tls) if self._owned_channel else channel
        self._stub = stub if stub is not None else a2v_pb2_grpc.A2VServiceStub(self._channel)
        self._session: wire.SessionInfo | None = None
        self._session_id: str | None = None
        self._metadata: wire.Metadata = wire.call_metadata(self.api_key)
        self._sequence_num = 0
        self._decoders: dict[str, FrameDecoder] = {}
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
        return self._session_id

    @property
    def streams(self) -> tuple[StreamInfo, ...]:
        """The streams the server advertised at initialize."""
        return self._session.streams if self._session else ()

    @property
    def session_target(self) -> str | None:
        """The ``x-session-target`` pin the server returned at initialize, if any."""
        return self._session.session_target if self._session else None

    @property
    def last_truth(self) -> sim_pb2.InferTruth | None:
        """Ground truth of the last Infer (embedded simulator only), else None."""
        return self._last_truth

    def __repr__(self) -> str:
        key = MASK if self.api_key else None
        return (
            f"{type(self).__name__}(endpoint={self.endpoint!r}, api_key={key!r}, "
            f"session_id={self._session_id!r})"
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
        if not self.api_key:
            raise wire.missing_api_key_error()
        request = wire.initialize_request(
            self.client_sdk_version, self.api_key, self.accepted_formats
        )
        logger.info(
            "Initialize: endpoint=%s sdk_version=%s accepted_output_formats=%s",
            self.endpoint,
            self.client_sdk_version,
            [f.name for f in self.accepted_formats],
        )
        response, call = self._call(self._stub.Initialize, "Initialize", request, with_call=True)
        wire.raise_if_error(response, self.api_key)
        session = wire.parse_session(response, call.initial_metadata() if call else ())
        self._session, self._session_id = session, session.session_id
        self._metadata = wire.call_metadata(self.api_key, session.session_target)
        try:
            wire.check_session(
                session,
                accepted_formats=self.accepted_formats,
                required_streams=self.required_streams,
            )
        except DecartRoboticsError:
            self._finish_quietly()
            raise
        self._sequence_num = 0
        self._decoders = {
            s.name: make_decoder(session.output_format, s.name) for s in session.streams
        }
        logger.info(
            "InitializeResponse: session_id=%s output_format=%s streams=%s",
            session.session_id,
            wire.format_name(session.output_format),
            [f"{s.name}({s.width}x{s.height})" for s in session.streams],
        )
        return session.streams

    def prompt(self, prompt: str, *, seed: int | None = None) -> None:
        """Set the scene (``seed`` picks the world; None lets the server use seed 0)."""
        session_id = self._require_session()
        metadata = wire.prompt_metadata(self._metadata, seed)
        request = a2v_pb2.PromptRequest(session_id=session_id, prompt=prompt)
        response, _ = self._call(self._stub.Prompt, "Prompt", request, metadata=metadata)
        wire.raise_if_error(response, self.api_key)
        # A Prompt restarts the rollout: sequence numbers restart at 0 and a new clip begins.
        self._sequence_num = 0
        for decoder in self._decoders.values():
            decoder.reset()
        if self.frame_consumer is not None:
            self.frame_consumer.new_clip()

    def infer(self, actions: Iterable[Iterable[float]]) -> A2VResult:
        """Send 4 ``[throttle, steering]`` actions; returns 4 decoded frames per stream."""
        session_id = self._require_session()
        chunk = wire.validate_action_chunk(actions)
        request = wire.infer_request(session_id, self._sequence_num, chunk)
        response, call = self._call(self._stub.Infer, "Infer", request, with_call=True)
        wire.raise_if_error(response, self.api_key)
        self._sequence_num += 1
        self._last_truth = extras.parse_truth(call.trailing_metadata() if call else None)
        frames = self._decode_streams(response.streams)
        if self.frame_consumer is not None:
            self.frame_consumer.submit(frames)
        return A2VResult(sequence_num=response.sequence_num, frames=frames, streams=self.streams)

    def depth(self) -> dict[str, np.ndarray]:
        """Metric depth (float32 ``[H, W]``, sky +inf) of the last frame of each stream.

        Only the embedded simulator implements this (``oasis_torchrl.sim.v1.SimService``).
        """
        session_id = self._require_session()
        stub = sim_pb2_grpc.SimServiceStub(self._require_channel("depth"))
        request = sim_pb2.DepthRequest(session_id=session_id)
        try:
            response, _ = self._call(stub.GetDepth, "GetDepth", request)
        except TransportError as error:
            extras.raise_depth_error(error)
        return extras.depth_maps(response)

    def ping(self) -> bool:
        """Ask the server's gRPC health service whether it is SERVING (False if unreachable)."""
        stub = health_pb2_grpc.HealthStub(self._require_channel("ping"))
        try:
            response, _ = self._call(
                stub.Check, "Check", extras.health_request(), retry=RetryPolicy.never()
            )
        except TransportError as error:
            return extras.ping_outcome(error)
        return extras.is_serving(response)

    def close(self) -> None:
        """Finish the session (if any) and release the channel this client created."""
        try:
            self._finish()
        finally:
            if self._owned_channel and self._channel is not None:
                self._channel.close()
                self._channel = None

    def _finish(self) -> None:
        if self._session_id is None:
            return
        # Forget the id first so a failing Finish is never retried by a second close.
        session_id, self._session_id = self._session_id, None
        request = a2v_pb2.FinishRequest(session_id=session_id)
        response, _ = self._call(self._stub.Finish, "Finish", request)
        wire.raise_if_error(response, self.api_key)

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

    def _require_session(self) -> str:
        if self._session_id is None:
            raise DecartRoboticsError("A2V session is not initialized")
        return self._session_id

    def _require_channel(self, feature: str) -> grpc.Channel:
        if self._channel is None:
            raise DecartRoboticsError(
                f"{feature} needs an open channel: the client is closed or was given only a stub"
            )
        return self._channel

    def _call(
        self,
        method: Callable[..., Any],
        name: str,
        request: object,
        *,
        metadata: wire.Metadata | None = None,
        with_call: bool = False,
        retry: RetryPolicy | None = None,
    ) -> tuple[Any, grpc.Call | None]:
        """One unary call with retries; returns the response and, if asked, the call."""
        use_call = with_call and hasattr(method, "with_call")
        invoke = method.with_call if use_call else method
        kwargs = {"metadata": self._metadata if metadata is None else metadata}

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

    def _decode_streams(
        self, streams: Sequence[a2v_pb2.OutputStream]
    ) -> dict[str, list[np.ndarray]]:
        """Decode each advertised stream's packets into one fresh ``[n, H, W, 3]`` array."""
        sizes = {s.name: self.resize or (s.height, s.width) for s in self.streams}
        frames: dict[str, list[np.ndarray]] = {}
        for stream in streams:
            if stream.name not in sizes:
                logger.warning("ignoring stream %r the server did not advertise", stream.name)
                continue
            out = np.empty((len(stream.frames), *sizes[stream.name], 3), np.uint8)
            decode_chunk(self._decoders[stream.name], stream.frames, out)
            frames[stream.name] = list(out)
        missing = set(self.required_streams) - set(frames)
        if missing:
            raise DecartRoboticsError(
                "A2V response did not include required streams: " + ", ".join(sorted(missing))
            )
        return frames
