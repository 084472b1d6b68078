"""The policy server: ``oasis_torchrl.policy.v1.PolicyService`` over a loaded policy.

Every call is checked in this order: the API key (``x-api-key`` metadata, the A2V server's
authority: UNAUTHENTICATED), the key's limits (RESOURCE_EXHAUSTED), the policy's state
(UNAVAILABLE while loading, FAILED_PRECONDITION after a failed load), the request (an
observation must match Describe: INVALID_ARGUMENT naming the feature, shape and dtype). gRPC
itself refuses a request larger than ``max_message_bytes`` (RESOURCE_EXHAUSTED). A policy that
raises fails only the requests it raised on (INTERNAL, naming the exception); any other fault
is logged and answered INTERNAL. Nothing a client sends is ever unpickled.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from tensordict import TensorDictBase

from oasis_torchrl import __version__
from oasis_torchrl.config.policy_serving import PolicyServerConfig
from oasis_torchrl.proto import policy_pb2, policy_pb2_grpc
from oasis_torchrl.protocol import API_KEY_METADATA, POLICY_SERVICE
from oasis_torchrl.remote.features import as_tensordict, check_observation, sample_observation
from oasis_torchrl.remote.tensors import decode_map, encode, encode_map
from oasis_torchrl.serving.batching import PolicyRaised
from oasis_torchrl.serving.host import Loader, PolicyHost
from oasis_torchrl.serving.limits import KeyLimits
from oasis_torchrl.serving.sessions import ActionQueues
from oasis_torchrl.sim.auth import ApiKeyAuthority
from oasis_torchrl.sim.errors import RequestError, StatusError

logger = logging.getLogger(__name__)

_Response = TypeVar("_Response")
_MAX_ERROR_CHARS = 1000
MAX_ACTIONS_PER_CALL = 1024
"""``SelectActionRequest.count`` at most."""


def _api_key(context: grpc.ServicerContext) -> str | None:
    for item in context.invocation_metadata() or ():
        if item.key == API_KEY_METADATA:
            return item.value if isinstance(item.value, str) else item.value.decode("utf-8")
    return None


class PolicyServicer(policy_pb2_grpc.PolicyServiceServicer):
    """``PolicyService`` answered from a :class:`PolicyHost`.

    Example:
        >>> config = PolicyServerConfig(api_keys=("k",))
        >>> host = PolicyHost(lambda: None, "none", max_rows=1, max_wait=0)
        >>> callable(PolicyServicer(config, host).PredictChunk)
        True
    """

    def __init__(self, config: PolicyServerConfig, host: PolicyHost) -> None:
        self._config = config
        self._host = host
        self._authority = ApiKeyAuthority(config.api_keys, allow_any_key=config.allow_any_key)
        self._limits = KeyLimits(
            config.rate_per_key, config.burst_per_key, config.max_in_flight_per_key
        )
        self._queues = ActionQueues(
            max_sessions=config.max_sessions,
            max_sessions_per_key=config.max_sessions_per_key,
            idle_timeout=config.session_idle_s,
        )

    def Ping(
        self, request: policy_pb2.PingRequest, context: grpc.ServicerContext
    ) -> policy_pb2.PingResponse:
        """The server's version: it is up and the key is valid."""
        return self._serve(context, lambda key: policy_pb2.PingResponse(server_version=__version__))

    def Status(
        self, request: policy_pb2.StatusRequest, context: grpc.ServicerContext
    ) -> policy_pb2.StatusResponse:
        """Loading, ready, or failed with the reason."""
        host = self._host
        return self._serve(
            context,
            lambda key: policy_pb2.StatusResponse(
                state=host.state, reason=host.reason, policy=host.name
            ),
        )

    def Describe(
        self, request: policy_pb2.DescribeRequest, context: grpc.ServicerContext
    ) -> policy_pb2.DescribeResponse:
        """The policy's inputs and action, chunk size and the request limits."""
        return self._serve(context, lambda key: self._describe())

    def PredictChunk(
        self, request: policy_pb2.PredictChunkRequest, context: grpc.ServicerContext
    ) -> policy_pb2.PredictChunkResponse:
        """A chunk per row, from a forward pass shared with concurrent requests."""

        def answer(key: bytes) -> policy_pb2.PredictChunkResponse:
            chunks = self._host.predict_chunk(self._observation(request.observation))
            return policy_pb2.PredictChunkResponse(actions=encode(chunks))

        return self._serve(context, answer)

    def SelectAction(
        self, request: policy_pb2.SelectActionRequest, context: grpc.ServicerContext
    ) -> policy_pb2.SelectActionResponse:
        """The next actions of each row from the session's queues."""

        def answer(key: bytes) -> policy_pb2.SelectActionResponse:
            if request.count > MAX_ACTIONS_PER_CALL:
                raise StatusError(
                    grpc.StatusCode.INVALID_ARGUMENT,
                    f"count {request.count} is over {MAX_ACTIONS_PER_CALL} actions per call",
                )
            observation = self._observation(request.observation)
            steps = self._host.policy.n_action_steps
            actions = self._queues.select(
                key,
                request.session_id,
                observation,
                lambda rows: self._host.predict_chunk(rows)[:, :steps],
                count=max(request.count, 1),
            )
            return policy_pb2.SelectActionResponse(actions=encode(actions))

        return self._serve(context, answer)

    def Reset(
        self, request: policy_pb2.ResetRequest, context: grpc.ServicerContext
    ) -> policy_pb2.ResetResponse:
        """Drop queued actions of a session's rows."""

        def answer(key: bytes) -> policy_pb2.ResetResponse:
            self._queues.reset(key, request.session_id, list(request.rows))
            return policy_pb2.ResetResponse()

        return self._serve(context, answer)

    def SampleInput(
        self, request: policy_pb2.SampleInputRequest, context: grpc.ServicerContext
    ) -> policy_pb2.SampleInputResponse:
        """A valid random observation of ``batch_size`` rows."""

        def answer(key: bytes) -> policy_pb2.SampleInputResponse:
            rows = request.batch_size or 1
            if rows > self._config.max_rows:
                raise StatusError(
                    grpc.StatusCode.INVALID_ARGUMENT,
                    f"batch_size {rows} is over the server's max_rows {self._config.max_rows}",
                )
            response = policy_pb2.SampleInputResponse()
            observation = sample_observation(self._host.policy.inputs, rows, request.seed)
            encode_map(observation, response.observation)
            return response

        return self._serve(context, answer)

    def _describe(self) -> policy_pb2.DescribeResponse:
        policy = self._host.policy
        return policy_pb2.DescribeResponse(
            inputs=[feature.to_proto() for feature in policy.inputs],
            action=policy.action.to_proto(),
            chunk_size=policy.chunk_size,
            n_action_steps=policy.n_action_steps,
            policy=policy.name,
            max_batch_rows=self._config.max_rows,
            max_request_bytes=self._config.max_message_bytes,
        )

    def _observation(self, messages: Mapping[str, policy_pb2.Tensor]) -> TensorDictBase:
        """The request's observation as a TensorDict, checked against the policy's inputs."""
        policy = self._host.policy
        try:
            observation = decode_map(messages)
            rows = check_observation(observation, policy.inputs, self._config.max_rows)
        except ValueError as error:
            raise StatusError(grpc.StatusCode.INVALID_ARGUMENT, str(error)) from None
        return as_tensordict(observation, rows)

    def _serve(
        self, context: grpc.ServicerContext, answer: Callable[[bytes], _Response]
    ) -> _Response:
        """Authenticate, admit under the key's limits, answer; failures become statuses."""
        try:
            key = self._authority.authenticate(_api_key(context))
            with self._limits.admit(key):
                return answer(key)
        except RequestError as error:  # the only one the authority raises: a bad key
            status, message = grpc.StatusCode.UNAUTHENTICATED, error.message
        except StatusError as error:
            status, message = error.status, error.message
        except PolicyRaised as error:
            status, message = grpc.StatusCode.INTERNAL, str(error)[:_MAX_ERROR_CHARS]
        except Exception:
            logger.exception("internal error in a policy server handler")
            status, message = grpc.StatusCode.INTERNAL, "internal server error"
        context.abort(status, message)
        raise AssertionError("context.abort returned")  # pragma: no cover


class PolicyServer:
    """A gRPC server answering ``PolicyService`` (and gRPC health) for one policy.

    The policy loads in the background once the server starts: Status says loading, then
    ready or failed (with the reason); health turns SERVING when it is ready.

    Args:
        config: where to listen, keys, limits, batching.
        load: builds the policy (e.g. ``lambda: load_served_policy(path)``).
        name: what the policy is called while it loads.

    Example:
        >>> from oasis_torchrl.drivers import PolicyDriver
        >>> from oasis_torchrl.models import DrivingNet
        >>> from oasis_torchrl.serving.served import ServedPolicy
        >>> load = lambda: ServedPolicy.of_driver(PolicyDriver.of_network(DrivingNet()), "net")
        >>> with PolicyServer(PolicyServerConfig(api_keys=("k",)), load) as server:
        ...     server.wait_until_loaded(60), server.endpoint.startswith("grpc://127.0.0.1:")
        (True, True)
    """

    def __init__(self, config: PolicyServerConfig, load: Loader, name: str = "policy") -> None:
        self.config = config
        self._health = health.HealthServicer()
        self.host = PolicyHost(
            load,
            name,
            max_rows=config.batch_rows,
            max_wait=config.batch_wait_ms / 1000.0,
            on_ready=self._report_serving,
        )
        self._handler_pool = ThreadPoolExecutor(config.workers, thread_name_prefix="policy-grpc")
        self._server = grpc.server(
            self._handler_pool,
            options=[
                ("grpc.max_receive_message_length", config.max_message_bytes),
                ("grpc.max_send_message_length", -1),
                ("grpc.so_reuseport", 0),
            ],
        )
        policy_pb2_grpc.add_PolicyServiceServicer_to_server(
            PolicyServicer(config, self.host), self._server
        )
        health_pb2_grpc.add_HealthServicer_to_server(self._health, self._server)
        self.port: int | None = None

    @property
    def endpoint(self) -> str:
        """``grpc://host:port`` (``grpcs://`` with TLS): what a client is given."""
        if self.port is None:
            raise RuntimeError("the server is not started; call start() first")
        return self.config.endpoint(self.port)

    def start(self) -> int:
        """Bind, serve, start loading the policy; returns the bound port."""
        self.port = self.config.bind(self._server)
        for service in ("", POLICY_SERVICE):
            self._health.set(service, health_pb2.HealthCheckResponse.NOT_SERVING)
        self._server.start()
        self.host.start()
        logger.info("policy server listening on %s", self.endpoint)
        return self.port

    def wait_until_loaded(self, timeout: float | None = None) -> bool:
        """Block until the policy has loaded or failed; True unless ``timeout`` passed."""
        return self.host.wait(timeout)

    def stop(self, grace: float | None = 1.0) -> None:
        """Report NOT_SERVING, let in-flight calls finish within ``grace`` s, release all."""
        self._health.enter_graceful_shutdown()
        self._server.stop(grace).wait()
        self.host.close()
        self._handler_pool.shutdown(wait=False)
        logger.info("policy server on port %s stopped", self.port)

    def __enter__(self) -> PolicyServer:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop(grace=0)

    def _report_serving(self) -> None:
        for service in ("", POLICY_SERVICE):
            self._health.set(service, health_pb2.HealthCheckResponse.SERVING)
