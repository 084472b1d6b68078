"""Hostile or careless clients: the server rejects them clearly and keeps serving everyone else."""

from __future__ import annotations

import logging
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import grpc
import numpy as np
import pytest

from oasis_torchrl.proto import a2v_pb2, a2v_pb2_grpc, common_pb2
from oasis_torchrl.protocol import SERVER_API_KEYS_ENV_VAR as API_KEYS_ENV_VAR
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer
from oasis_torchrl.sim.server import A2VServer
from oasis_torchrl.sim.simulator import Simulator

if TYPE_CHECKING:
    from conftest import RawStubs

ServerFactory = Callable[..., LocalServer]
StubFactory = Callable[[str], "RawStubs"]


def assert_still_serving(stubs: RawStubs) -> None:
    """A fresh session runs a full Prompt + Infer round."""
    session = stubs.open_session()
    response, _ = stubs.infer(session, 0)
    assert not response.HasField("error") and len(response.streams) == 3


def test_oversized_requests_are_refused_by_grpc(stubs: RawStubs) -> None:
    session = stubs.open_session()
    with pytest.raises(grpc.RpcError) as raised:
        stubs.a2v.Prompt(
            a2v_pb2.PromptRequest(session_id=session.session_id, prompt="x" * 100_000),
            metadata=session.metadata,
        )
    assert raised.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    assert not stubs.infer(session, 0)[0].HasField("error")


def test_hostile_field_values_get_in_band_errors(stubs: RawStubs) -> None:
    session = stubs.open_session()
    many_actions, _ = stubs.infer(session, 0, ((0.1, 0.1),) * 1000)
    assert many_actions.error.code == common_pb2.ERROR_CODE_INVALID_REQUEST
    huge_sequence, _ = stubs.infer(session, 2**64 - 1)
    assert huge_sequence.error.code == common_pb2.ERROR_CODE_INVALID_REQUEST
    long_id = stubs.a2v.Prompt(
        a2v_pb2.PromptRequest(session_id="\u00e9" * 20_000, prompt="road"),
        metadata=session.metadata,
    )
    assert long_id.error.code == common_pb2.ERROR_CODE_INVALID_SESSION
    assert not stubs.infer(session, 0)[0].HasField("error")


def test_undecodable_request_bytes_do_not_hurt_the_server(stubs: RawStubs) -> None:
    raw_infer = stubs.channel.unary_unary("/decart.inference.a2v.A2VService/Infer")
    for garbage in (b"\xff" * 64, b"\x0a\xff\xff\xff\xff\x0f", bytes(range(256))):
        with pytest.raises(grpc.RpcError) as raised:
            raw_infer(garbage, timeout=5)
        assert raised.value.code() in (grpc.StatusCode.INTERNAL, grpc.StatusCode.UNKNOWN)
    assert_still_serving(stubs)


class _ExplodingSimulator(Simulator):  # type: ignore[misc]
    """The real simulator, except that it fails on any prompt mentioning a volcano."""

    def reset(self, prompt: str, seed: int = 0) -> None:
        self._explodes = "volcano" in prompt
        super().reset(prompt, seed)

    def step(self, actions: np.ndarray) -> Any:
        if self._explodes:
            raise RuntimeError("simulated crash")
        return super().step(actions)


def test_a_failing_session_is_an_internal_error_for_that_call_only(
    server_factory: ServerFactory, stub_factory: StubFactory
) -> None:
    server = server_factory(simulator_factory=_ExplodingSimulator)
    stubs = stub_factory(server.address)
    healthy = stubs.open_session()
    doomed = stubs.open_session(prompt="a volcano road")
    with pytest.raises(grpc.RpcError) as raised:
        stubs.infer(doomed, 0)
    assert raised.value.code() == grpc.StatusCode.INTERNAL
    assert "simulated crash" not in raised.value.details()  # no internals leak to clients
    assert not stubs.infer(healthy, 0)[0].HasField("error")


def test_api_keys_never_reach_the_logs(
    stubs: RawStubs, server_keys: tuple[str, str], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    session = stubs.open_session(server_keys[1])
    stubs.infer(session, 0)
    stubs.initialize("a-wrong-key-that-must-not-be-logged")
    stubs.a2v.Finish(
        a2v_pb2.FinishRequest(session_id=session.session_id), metadata=session.metadata
    )
    assert caplog.records, "the server logged nothing; the check would be vacuous"
    for secret in (server_keys[1], "a-wrong-key-that-must-not-be-logged"):
        assert secret not in caplog.text


def test_any_key_mode_accepts_only_non_empty_keys(
    server_factory: ServerFactory, stub_factory: StubFactory, caplog: pytest.LogCaptureFixture
) -> None:
    stubs = stub_factory(server_factory(allow_any_key=True).address)
    assert "ANY non-empty API key" in caplog.text
    accepted, _ = stubs.initialize("whatever-key")
    assert not accepted.HasField("error")
    refused, _ = stubs.initialize(None, body_key="")
    assert refused.error.code == common_pb2.ERROR_CODE_INVALID_API_KEY


def test_a_server_without_keys_refuses_to_start(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(API_KEYS_ENV_VAR, raising=False)
    with pytest.raises(ValueError, match="no API key configured"):
        A2VServer(ServerConfig())
    monkeypatch.setenv(API_KEYS_ENV_VAR, "env-key-one,env-key-two")
    assert ServerConfig().api_keys == ("env-key-one", "env-key-two")


def test_session_ids_are_unguessable(stubs: RawStubs) -> None:
    ids = {stubs.initialize()[0].session_id for _ in range(20)}
    assert len(ids) == 20
    assert all(len(i) >= 32 and i.replace("-", "").replace("_", "").isalnum() for i in ids)


@pytest.fixture(scope="module")
def tls_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A self-signed certificate for 127.0.0.1 (needs the openssl command)."""
    openssl = shutil.which("openssl")
    if openssl is None:
        pytest.skip("the openssl command is not installed")
    folder = tmp_path_factory.mktemp("tls")
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(
        [openssl, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
         "-keyout", str(key), "-out", str(cert), "-subj", "/CN=localhost",
         "-addext", "subjectAltName=IP:127.0.0.1,DNS:localhost"],
        check=True, capture_output=True,
    )  # fmt: skip
    return cert, key


def test_tls_server(server_factory: ServerFactory, tls_files: tuple[Path, Path]) -> None:
    cert, key = tls_files
    server = server_factory(tls_cert=str(cert), tls_key=str(key))
    assert server.endpoint.startswith("https://127.0.0.1:")
    credentials = grpc.ssl_channel_credentials(root_certificates=cert.read_bytes())
    request = a2v_pb2.InitializeRequest(
        client_sdk_version="0.0.2",
        api_key=server.api_key,
        accepted_output_formats=[common_pb2.FRAME_FORMAT_VP9],
    )
    with grpc.secure_channel(server.address, credentials) as channel:
        response = a2v_pb2_grpc.A2VServiceStub(channel).Initialize(request, timeout=10)
    assert response.session_id and not response.HasField("error")
    with grpc.insecure_channel(server.address) as channel, pytest.raises(grpc.RpcError):
        a2v_pb2_grpc.A2VServiceStub(channel).Initialize(request, timeout=3)
