"""Shared fixtures: embedded A2V servers on loopback and raw gRPC stubs to talk to them.

- ``server_keys``: the two API keys every fixture server accepts.
- ``local_server``: one in-process server for the whole run (96x64, the keys above, limits of
  1024 sessions / 512 per key); do not change it, start your own with ``server_factory``.
- ``server_factory(**overrides)``: a fresh in-process :class:`LocalServer` (96x64 and the keys
  above unless overridden), stopped at the end of the test.
- ``stub_factory(address)``: :class:`RawStubs` on a plain-text channel; after the test the
  sessions it opened are finished and the channel closed.
- ``stubs``: :class:`RawStubs` connected to ``local_server``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import grpc
import pytest
from grpc_health.v1 import health_pb2_grpc

from oasis_torchrl.proto import a2v_pb2, a2v_pb2_grpc, common_pb2, sim_pb2_grpc
from oasis_torchrl.sim.launcher import LocalServer

# Scripts run in subprocesses by interop tests; importing them here would load the official
# SDK's protos into this process, where they clash with ours.
collect_ignore_glob = ["interop/official_*.py"]

TEST_KEYS = ("test-key-alpha", "test-key-beta")
SMALL_SERVER = {"width": 96, "height": 64}
Metadata = tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class SessionHandle:
    """An open session: its id and the metadata every later call of it must carry."""

    session_id: str
    metadata: Metadata

    def with_metadata(self, *extra: tuple[str, str]) -> Metadata:
        """The session metadata plus ``extra`` pairs (e.g. a seed)."""
        return self.metadata + tuple(extra)


@dataclass
class RawStubs:
    """Generated stubs on one channel, plus helpers that open sessions the protocol way."""

    channel: grpc.Channel
    a2v: a2v_pb2_grpc.A2VServiceStub
    sim: sim_pb2_grpc.SimServiceStub
    health: health_pb2_grpc.HealthStub
    opened: list[SessionHandle] = field(default_factory=list)

    def initialize(
        self,
        api_key: str | None = TEST_KEYS[0],
        *,
        formats: Sequence[int] = (common_pb2.FRAME_FORMAT_VP9,),
        sdk_version: str = "0.0.2",
        body_key: str | None = None,
    ) -> tuple[a2v_pb2.InitializeResponse, Any]:
        """Initialize with ``api_key`` as metadata and (unless ``body_key``) in the body."""
        metadata = (("x-api-key", api_key),) if api_key else ()
        request = a2v_pb2.InitializeRequest(
            client_sdk_version=sdk_version,
            api_key=api_key if body_key is None else body_key,
            accepted_output_formats=list(formats),
        )
        return self.a2v.Initialize.with_call(request, metadata=metadata, timeout=10)

    def open_session(
        self,
        api_key: str = TEST_KEYS[0],
        *,
        prompt: str | None = "a sunny two-lane road",
        seed: int | None = None,
        formats: Sequence[int] = (common_pb2.FRAME_FORMAT_VP9,),
    ) -> SessionHandle:
        """Initialize (and Prompt, unless ``prompt`` is None); fails the test on any error."""
        response, call = self.initialize(api_key, formats=formats)
        assert not response.HasField("error"), response.error
        target = dict(call.initial_metadata())["x-session-target"]
        session = SessionHandle(
            response.session_id, (("x-api-key", api_key), ("x-session-target", target))
        )
        self.opened.append(session)
        if prompt is not None:
            self.prompt(session, prompt, seed=seed)
        return session

    def finish_opened(self) -> None:
        """Finish every session :meth:`open_session` opened (errors ignored: some are gone)."""
        for session in self.opened:
            with contextlib.suppress(grpc.RpcError):
                self.a2v.Finish(
                    a2v_pb2.FinishRequest(session_id=session.session_id),
                    metadata=session.metadata,
                    timeout=5,
                )
        self.opened.clear()

    def prompt(self, session: SessionHandle, prompt: str, *, seed: int | None = None) -> None:
        """Prompt ``session``; fails the test on an in-band error."""
        extra = (("x-oasis-seed", str(seed)),) if seed is not None else ()
        response = self.a2v.Prompt(
            a2v_pb2.PromptRequest(session_id=session.session_id, prompt=prompt),
            metadata=session.with_metadata(*extra),
            timeout=10,
        )
        assert not response.HasField("error"), response.error

    def infer(
        self,
        session: SessionHandle,
        sequence_num: int,
        actions: Sequence[tuple[float, float]] = ((0.5, 0.0),) * 4,
    ) -> tuple[a2v_pb2.InferResponse, Any]:
        """One Infer; returns the response and the call (for trailing metadata)."""
        request = a2v_pb2.InferRequest(
            session_id=session.session_id,
            sequence_num=sequence_num,
            actions=[a2v_pb2.Action(throttle=t, steering=s) for t, s in actions],
        )
        return self.a2v.Infer.with_call(request, metadata=session.metadata, timeout=30)


@pytest.fixture(scope="session")
def server_keys() -> tuple[str, str]:
    """The API keys every fixture server accepts."""
    return TEST_KEYS


@pytest.fixture(scope="session")
def local_server(server_keys: tuple[str, str]) -> Iterator[LocalServer]:
    """One shared in-process server (96x64) for the whole test run."""
    # Generous limits: many test files share this server and some leave sessions open.
    with LocalServer(
        api_keys=server_keys, max_sessions=1024, max_sessions_per_key=512, **SMALL_SERVER
    ) as server:
        yield server


@pytest.fixture
def server_factory(server_keys: tuple[str, str]) -> Iterator[Callable[..., LocalServer]]:
    """Start in-process servers with config overrides; all are stopped after the test."""
    servers: list[LocalServer] = []

    def start(**overrides: Any) -> LocalServer:
        settings = {"api_keys": server_keys, **SMALL_SERVER, **overrides}
        server = LocalServer(**settings).start()
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.stop(grace=0)


@pytest.fixture
def stub_factory() -> Iterator[Callable[[str], RawStubs]]:
    """Make :class:`RawStubs` on a plain-text channel to an address.

    After the test, the sessions they opened are finished and the channels closed.
    """
    connected: list[RawStubs] = []

    def connect(address: str) -> RawStubs:
        channel = grpc.insecure_channel(address)
        stubs = RawStubs(
            channel,
            a2v_pb2_grpc.A2VServiceStub(channel),
            sim_pb2_grpc.SimServiceStub(channel),
            health_pb2_grpc.HealthStub(channel),
        )
        connected.append(stubs)
        return stubs

    yield connect
    for stubs in connected:
        stubs.finish_opened()
        stubs.channel.close()


@pytest.fixture
def stubs(local_server: LocalServer, stub_factory: Callable[[str], RawStubs]) -> RawStubs:
    """Raw stubs connected to the shared ``local_server``."""
    return stub_factory(local_server.address)
