"""The embedded A2V gRPC server: A2VService, the local SimService and gRPC health checking.

Every rule of the A2V protocol is enforced here (see ``docs/PROTOCOL.md``); request
failures are in-band ``error`` fields, transport conditions are gRPC statuses:

- UNAVAILABLE: an injected transient failure (``failure_rate``), raised before any state
  changes, so the same request can simply be retried.
- RESOURCE_EXHAUSTED: the total or per-key session limit is reached (Initialize), or a request
  exceeds ``max_message_bytes`` (rejected by gRPC itself).
- INTERNAL: an unexpected server fault (logged); other sessions are unaffected.

``SimService`` has no ``error`` field, so its request failures map to statuses:
INVALID_API_KEY -> UNAUTHENTICATED, INVALID_SESSION -> NOT_FOUND, ALREADY_FINISHED and
PROMPT_SET -> FAILED_PRECONDITION, anything else -> INVALID_ARGUMENT.

A hosted-like server (``ServerConfig(hosted=True)``) sends what the hosted service sends and
nothing more: VP9 frames, the error codes and the session-pinning header, but no ground-truth
metadata and no SimService; it ignores the seed and expert metadata (each Prompt draws a fresh
random scene, so its episodes cannot be paired) and grants no frame subsets.
"""

from __future__ import annotations

import logging
import secrets
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import AbstractContextManager
from typing import Any

import grpc
from google.protobuf import message_factory
from google.protobuf.descriptor import ServiceDescriptor
from grpc_health.v1 import health, health_pb2, health_pb2_grpc

from oasis_torchrl.proto import a2v_pb2, common_pb2, sim_pb2
from oasis_torchrl.protocol import (
    API_KEY_METADATA,
    CAMERAS,
    EXPERT_METADATA,
    EXPERT_ON,
    FRAMES_METADATA,
    LAST_FRAME_ONLY,
    MAX_SEED,
    SEED_METADATA,
    SESSION_TARGET_METADATA,
    TRUTH_METADATA,
    FrameFormat,
)
from oasis_torchrl.sim.auth import ApiKeyAuthority
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.errors import RequestError, StatusError
from oasis_torchrl.sim.faults import FailureInjector
from oasis_torchrl.sim.session_world import LocalWorlds, SimulatorFactory, WorldHost
from oasis_torchrl.sim.sessions import Session, SessionRegistry
from oasis_torchrl.sim.simulator import Simulator
from oasis_torchrl.sim.validation import (
    actions_to_array,
    check_prompt,
    check_sdk_version,
    negotiate_format,
    parse_seed,
)
from oasis_torchrl.sim.worker_pool import WorkerPool

logger = logging.getLogger(__name__)

A2V_SERVICE = a2v_pb2.DESCRIPTOR.services_by_name["A2VService"]
SIM_SERVICE = sim_pb2.DESCRIPTOR.services_by_name["SimService"]

_SIM_STATUS = {
    common_pb2.ERROR_CODE_INVALID_API_KEY: grpc.StatusCode.UNAUTHENTICATED,
    common_pb2.ERROR_CODE_INVALID_SESSION: grpc.StatusCode.NOT_FOUND,
    common_pb2.ERROR_CODE_ALREADY_FINISHED: grpc.StatusCode.FAILED_PRECONDITION,
    common_pb2.ERROR_CODE_PROMPT_SET: grpc.StatusCode.FAILED_PRECONDITION,
}


def _metadata(context: grpc.ServicerContext, key: str) -> str | bytes | None:
    """The first value of invocation metadata ``key`` (str, or bytes for ``-bin`` keys)."""
    for item in context.invocation_metadata() or ():
        if item.key == key:
            return item.value
    return None


def _text_metadata(context: grpc.ServicerContext, key: str) -> str | None:
    """Metadata ``key`` as text (gRPC hands ``-bin`` keys over as bytes)."""
    value = _metadata(context, key)
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else value


def _run_rpc[Response](
    context: grpc.ServicerContext,
    handler: Callable[[], Response],
    on_request_error: Callable[[RequestError], Response],
) -> Response:
    """Run ``handler``; a :class:`RequestError` goes to ``on_request_error``, the rest aborts."""
    try:
        return handler()
    except RequestError as error:
        return on_request_error(error)
    except StatusError as error:
        status = error
    except Exception:
        logger.exception("internal error in a gRPC handler")
        status = StatusError(grpc.StatusCode.INTERNAL, "internal server error")
    context.abort(status.status, status.message)
    raise AssertionError("context.abort returned")  # pragma: no cover


class _Gate:
    """Checks shared by every session call: injected failures, API key, session resolution."""

    def __init__(
        self,
        registry: SessionRegistry,
        authority: ApiKeyAuthority,
        failures: FailureInjector | None = None,
    ) -> None:
        self.registry = registry
        self.authority = authority
        self.failures = failures

    def admit(self, method: str, api_key: str | None) -> bytes:
        """Fail transiently if injected, then return the digest of the caller's valid key."""
        if self.failures is not None:
            self.failures.maybe_fail(method)
        return self.authority.authenticate(api_key)

    def use(
        self, method: str, session_id: str, context: grpc.ServicerContext
    ) -> AbstractContextManager[Session]:
        """The caller's session, locked (a context manager), after all access checks."""
        key_digest = self.admit(method, _text_metadata(context, API_KEY_METADATA))
        target = _text_metadata(context, SESSION_TARGET_METADATA)
        return self.registry.use(session_id, key_digest, target)


class A2VServicer:
    """``decart.inference.a2v.A2VService`` backed by the procedural simulator.

    Example:
        >>> from oasis_torchrl.sim.session_world import LocalWorlds
        >>> config = ServerConfig(width=64, height=48, api_keys=("k",))
        >>> registry = SessionRegistry(config, LocalWorlds(config))
        >>> servicer = A2VServicer(config, registry, ApiKeyAuthority(config.api_keys))
        >>> [info.name for info in servicer.stream_infos]
        ['left_forward', 'front', 'right_forward']
    """

    def __init__(
        self, config: ServerConfig, registry: SessionRegistry, authority: ApiKeyAuthority
    ) -> None:
        self._config = config
        self._registry = registry
        self._gate = _Gate(
            registry, authority, FailureInjector(config.failure_rate, config.failure_seed)
        )
        self.stream_infos = [
            a2v_pb2.StreamInfo(
                name=name, type=a2v_pb2.SENSOR_TYPE_RGB, width=config.width, height=config.height
            )
            for name in CAMERAS
        ]

    def Initialize(
        self, request: a2v_pb2.InitializeRequest, context: grpc.ServicerContext
    ) -> a2v_pb2.InitializeResponse:
        """Authenticate, check the SDK version, negotiate a format and open a session."""
        return _run_rpc(
            context,
            lambda: self._initialize(request, context),
            lambda error: a2v_pb2.InitializeResponse(error=error.to_proto()),
        )

    def Prompt(
        self, request: a2v_pb2.PromptRequest, context: grpc.ServicerContext
    ) -> a2v_pb2.PromptResponse:
        """Set the session's scene from the prompt and the ``x-oasis-seed`` metadata (and run
        the expert beside it if ``x-oasis-expert`` asks)."""
        return _run_rpc(
            context,
            lambda: self._prompt(request, context),
            lambda error: a2v_pb2.PromptResponse(error=error.to_proto()),
        )

    def Infer(
        self, request: a2v_pb2.InferRequest, context: grpc.ServicerContext
    ) -> a2v_pb2.InferResponse:
        """Step the world by 4 actions; 4 frames per stream plus ground-truth trailing metadata
        (none when hosted-like)."""
        return _run_rpc(
            context,
            lambda: self._infer(request, context),
            lambda error: a2v_pb2.InferResponse(
                sequence_num=request.sequence_num, error=error.to_proto()
            ),
        )

    def Finish(
        self, request: a2v_pb2.FinishRequest, context: grpc.ServicerContext
    ) -> a2v_pb2.FinishResponse:
        """End the session."""
        return _run_rpc(
            context,
            lambda: self._finish(request, context),
            lambda error: a2v_pb2.FinishResponse(error=error.to_proto()),
        )

    def _initialize(
        self, request: a2v_pb2.InitializeRequest, context: grpc.ServicerContext
    ) -> a2v_pb2.InitializeResponse:
        key_digest = self._gate.admit("Initialize", self._initialize_key(request, context))
        check_sdk_version(request.client_sdk_version)
        output_format = negotiate_format(request.accepted_output_formats, self._config.formats)
        last_frame_only = (
            _text_metadata(context, FRAMES_METADATA) == LAST_FRAME_ONLY
            and output_format == FrameFormat.RAW_RGB24
        )
        session = self._registry.open(key_digest, output_format, last_frame_only=last_frame_only)
        granted = ((FRAMES_METADATA, LAST_FRAME_ONLY),) if last_frame_only else ()
        context.send_initial_metadata(((SESSION_TARGET_METADATA, session.target), *granted))
        return a2v_pb2.InitializeResponse(
            session_id=session.session_id, output_format=output_format, streams=self.stream_infos
        )

    @staticmethod
    def _initialize_key(
        request: a2v_pb2.InitializeRequest, context: grpc.ServicerContext
    ) -> str | None:
        """The key from the request body or ``x-api-key`` metadata; both must agree if both set."""
        metadata_key = _text_metadata(context, API_KEY_METADATA)
        if request.api_key and metadata_key and request.api_key != metadata_key:
            raise RequestError(
                common_pb2.ERROR_CODE_INVALID_API_KEY,
                "InitializeRequest.api_key and x-api-key metadata name different keys",
            )
        return request.api_key or metadata_key

    def _prompt(
        self, request: a2v_pb2.PromptRequest, context: grpc.ServicerContext
    ) -> a2v_pb2.PromptResponse:
        with self._gate.use("Prompt", request.session_id, context) as session:
            check_prompt(request.prompt, self._config.max_prompt_chars)
            seed, expert = self._scene_options(context)
            session.world.prompt(request.prompt, seed, expert=expert)
        return a2v_pb2.PromptResponse()

    def _scene_options(self, context: grpc.ServicerContext) -> tuple[int, bool]:
        """The Prompt's seed and whether the expert runs: what its metadata asks or, hosted-like,
        a fresh random seed and no expert (the hosted service ignores both)."""
        if self._config.hosted:
            return secrets.randbelow(MAX_SEED + 1), False
        seed = parse_seed(_metadata(context, SEED_METADATA))
        return seed, _text_metadata(context, EXPERT_METADATA) == EXPERT_ON

    def _infer(
        self, request: a2v_pb2.InferRequest, context: grpc.ServicerContext
    ) -> a2v_pb2.InferResponse:
        with self._gate.use("Infer", request.session_id, context) as session:
            actions = actions_to_array(request.actions)
            # Only this session waits: its lock serialises its own calls, like one GPU stream.
            if self._config.latency_ms:
                time.sleep(self._config.latency_ms / 1000.0)
            record = session.world.infer(request.sequence_num, actions)
        if not self._config.hosted:
            context.set_trailing_metadata(((TRUTH_METADATA, record.truth),))
        return record.response  # serialised already (see _serialise)

    def _finish(
        self, request: a2v_pb2.FinishRequest, context: grpc.ServicerContext
    ) -> a2v_pb2.FinishResponse:
        with self._gate.use("Finish", request.session_id, context) as session:
            self._registry.finish(session)
        return a2v_pb2.FinishResponse()


class SimServicer:
    """``oasis_torchrl.sim.v1.SimService``: depth and scene of a session, for local analysis.

    Same authentication and session pinning as A2V calls; no injected failures.

    Example:
        >>> from oasis_torchrl.sim.session_world import LocalWorlds
        >>> config = ServerConfig(api_keys=("k",))
        >>> registry = SessionRegistry(config, LocalWorlds(config))
        >>> servicer = SimServicer(registry, ApiKeyAuthority(config.api_keys))
        >>> callable(servicer.GetDepth) and callable(servicer.GetScene)
        True
    """

    def __init__(self, registry: SessionRegistry, authority: ApiKeyAuthority) -> None:
        self._gate = _Gate(registry, authority)

    def GetDepth(
        self, request: sim_pb2.DepthRequest, context: grpc.ServicerContext
    ) -> sim_pb2.DepthResponse:
        """Float16 depth of the last frame of each stream."""
        return self._query("GetDepth", request.session_id, context, lambda s: s.world.depth())

    def GetScene(
        self, request: sim_pb2.SceneRequest, context: grpc.ServicerContext
    ) -> sim_pb2.SceneResponse:
        """The static world of the session's current scene."""
        return self._query("GetScene", request.session_id, context, lambda s: s.world.scene())

    def _query[Response](
        self,
        method: str,
        session_id: str,
        context: grpc.ServicerContext,
        answer: Callable[[Session], Response],
    ) -> Response:
        def handler() -> Response:
            with self._gate.use(method, session_id, context) as session:
                return answer(session)

        return _run_rpc(context, handler, self._abort_with_status(context))

    @staticmethod
    def _abort_with_status(context: grpc.ServicerContext) -> Callable[[RequestError], Any]:
        def abort(error: RequestError) -> Any:
            status = _SIM_STATUS.get(error.code, grpc.StatusCode.INVALID_ARGUMENT)
            context.abort(status, f"{common_pb2.ErrorCode.Name(error.code)}: {error.message}")

        return abort


class A2VServer:
    """The embedded A2V server: gRPC server, services, sessions and where their worlds run.

    With ``config.hosted`` it serves A2V alone (no SimService), as the hosted service does.
    With ``config.processes`` worker processes (default: one per core) the sessions' worlds run
    in those workers (:mod:`~oasis_torchrl.sim.worker_pool`), one worker per session for its
    life; with ``processes=0`` they run in this process.

    Args:
        config: Server settings; it must name API keys or set ``allow_any_key``.
        simulator_factory: Builds one world per session from ``width=, height=, fps=``
            (default: the procedural :class:`~oasis_torchrl.sim.simulator.Simulator`); with
            worker processes it must pickle.

    Example:
        >>> server = A2VServer(ServerConfig(width=96, height=64, api_keys=("secret",)))
        >>> port = server.start()
        >>> server.address == f"127.0.0.1:{port}"
        True
        >>> server.stop()
    """

    def __init__(
        self, config: ServerConfig, *, simulator_factory: SimulatorFactory | None = None
    ) -> None:
        self.config = config
        simulator_factory = simulator_factory or Simulator
        self._authority = ApiKeyAuthority(config.api_keys, allow_any_key=config.allow_any_key)
        self._workers: WorkerPool | None = None
        if config.resolved_processes:
            self._workers = WorkerPool(
                config,
                config.resolved_processes,
                on_lost=self._sessions_lost,
                simulator_factory=simulator_factory,
            )
            self._worlds: WorldHost = self._workers
        else:
            self._worlds = LocalWorlds(config, simulator_factory)
        self._registry = SessionRegistry(config, self._worlds)
        self._health = health.HealthServicer()
        self._handler_pool = ThreadPoolExecutor(config.workers, thread_name_prefix="oasis-grpc")
        self._server = grpc.server(
            self._handler_pool,
            options=[
                ("grpc.max_receive_message_length", config.max_message_bytes),
                ("grpc.so_reuseport", 0),
            ],
        )
        a2v = A2VServicer(config, self._registry, self._authority)
        add_service(self._server, A2V_SERVICE, a2v)
        self._services = (A2V_SERVICE,)
        if not config.hosted:
            add_service(self._server, SIM_SERVICE, SimServicer(self._registry, self._authority))
            self._services = (A2V_SERVICE, SIM_SERVICE)
        health_pb2_grpc.add_HealthServicer_to_server(self._health, self._server)
        self.port: int | None = None

    @property
    def worker_pids(self) -> list[int]:
        """Process ids of the worker processes, by worker index (empty without workers)."""
        return [] if self._workers is None else self._workers.pids

    @property
    def address(self) -> str:
        """``host:port`` a client on this machine dials (wildcard hosts become loopback)."""
        return self.config.client_address(self._bound_port())

    @property
    def endpoint(self) -> str:
        """The endpoint URL clients take: ``http://`` or, with TLS, ``https://``."""
        return self.config.endpoint(self._bound_port())

    def _bound_port(self) -> int:
        if self.port is None:
            raise RuntimeError("the server is not started; call start() first")
        return self.port

    def start(self) -> int:
        """Bind, start serving and report SERVING; returns the bound port."""
        self.port = self.config.bind(self._server)
        self._worlds.start()
        self._server.start()
        self._registry.start_reaper()
        for service in ("", *(service.full_name for service in self._services)):
            self._health.set(service, health_pb2.HealthCheckResponse.SERVING)
        logger.info(
            "A2V server listening on %s (TLS %s%s)",
            self.address,
            self.config.tls_enabled,
            ", hosted-like: frames only" if self.config.hosted else "",
        )
        return self.port

    def stop(self, grace: float | None = 1.0) -> None:
        """Report NOT_SERVING, finish in-flight calls within ``grace`` seconds, release all."""
        self._health.enter_graceful_shutdown()
        self._server.stop(grace).wait()
        self._registry.close()
        self._worlds.close()
        self._handler_pool.shutdown(wait=False)
        logger.info("A2V server on port %s stopped", self.port)

    def _sessions_lost(self, session_ids: list[str], cause: str) -> None:
        self._registry.lose(session_ids, cause)

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the server stops (or ``timeout``); True if it stopped."""
        return self._server.wait_for_termination(timeout)


def _serialise(response: Any) -> bytes:
    """A response message as bytes; worlds answer with bytes already (no second encoding)."""
    return response if isinstance(response, bytes) else response.SerializeToString()


def add_service(server: grpc.Server, service: ServiceDescriptor, servicer: object) -> None:
    """Serve every method of ``service`` (e.g. :data:`A2V_SERVICE`) with the same-named method
    of ``servicer``, whose answers may be messages or bytes already serialised."""
    handlers = {
        method.name: grpc.unary_unary_rpc_method_handler(
            getattr(servicer, method.name),
            request_deserializer=message_factory.GetMessageClass(method.input_type).FromString,
            response_serializer=_serialise,
        )
        for method in service.methods
    }
    generic = grpc.method_handlers_generic_handler(service.full_name, handlers)
    server.add_generic_rpc_handlers((generic,))
