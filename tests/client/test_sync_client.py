"""The drop-in sync client against the real embedded server on loopback (96x64)."""

from __future__ import annotations

import logging
import shutil
import socket
import subprocess
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import grpc
import numpy as np
import pytest

from oasis_torchrl.client import (
    JPEG,
    VP9,
    A2VClient,
    A2VError,
    DecartRoboticsError,
    ErrorCode,
    PermanentA2VError,
    RetryPolicy,
    SequenceError,
    SessionLostError,
    SessionPool,
    TransportError,
    UnsupportedFeatureError,
)
from oasis_torchrl.proto import a2v_pb2
from oasis_torchrl.sim.auth import ApiKeyAuthority
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer
from oasis_torchrl.sim.server import A2V_SERVICE, A2VServicer, add_service
from oasis_torchrl.sim.session_world import LocalWorlds
from oasis_torchrl.sim.sessions import SessionRegistry

from ._helpers import PROMPT, action_chunks, sync_rollout

STREAMS = ["left_forward", "front", "right_forward"]
ZERO_CHUNK = [[0.0, 0.0]] * 4


def dead_endpoint() -> str:
    """An endpoint nobody listens on (a port that was free a moment ago)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return f"http://127.0.0.1:{sock.getsockname()[1]}"


@pytest.fixture
def a2v_only_endpoint(server_keys: tuple[str, str]) -> Iterator[str]:
    """A real gRPC server with the A2V service alone: no health service, no SimService."""
    config = ServerConfig(width=96, height=64, api_keys=server_keys)
    worlds = LocalWorlds(config)
    server = grpc.server(ThreadPoolExecutor(4))
    servicer = A2VServicer(config, SessionRegistry(config, worlds), ApiKeyAuthority(server_keys))
    add_service(server, A2V_SERVICE, servicer)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    yield f"http://127.0.0.1:{port}"
    server.stop(0).wait()
    worlds.close()


def area_downscale(image: np.ndarray, factor: int) -> np.ndarray:
    height, width = image.shape[0] // factor, image.shape[1] // factor
    return image.reshape(height, factor, width, factor, 3).astype(np.float32).mean(axis=(1, 3))


def expect_a2v_error(action: Callable[[], object], kind: type, code: ErrorCode) -> A2VError:
    with pytest.raises(kind) as raised:
        action()
    assert raised.value.code == code, raised.value
    return raised.value


@pytest.mark.parametrize("frame_format", [VP9, JPEG])
def test_lifecycle_with_each_format(local_server: LocalServer, frame_format: int) -> None:
    client = A2VClient(
        local_server.endpoint, api_key=local_server.api_key, accepted_formats=(frame_format,)
    )
    streams = client.initialize()
    assert [(s.name, s.height, s.width) for s in streams] == [(n, 64, 96) for n in STREAMS]
    assert client.session_id and client.session_target
    client.prompt(PROMPT, seed=11)
    for expected_sequence in (0, 1):
        result = client.infer([[0.8, 0.1]] * 4)
        assert result.sequence_num == expected_sequence and result.streams == streams
        assert sorted(result.frames) == sorted(STREAMS)
        for frames in result.frames.values():
            assert [f.shape for f in frames] == [(64, 96, 3)] * 4
            assert frames[0].dtype == np.uint8 and frames[-1].std() > 0
        truth = client.last_truth
        assert (truth.sequence_num, truth.seed, len(truth.frames)) == (expected_sequence, 11, 4)
        assert truth.frames[-1].distance > 0
    client.prompt(PROMPT, seed=11)  # a new clip restarts at sequence 0
    assert client.infer(ZERO_CHUNK).sequence_num == 0
    client.close()
    assert client.session_id is None
    with pytest.raises(DecartRoboticsError, match="not initialized"):
        client.infer(ZERO_CHUNK)


def test_same_seed_and_actions_give_identical_frames(local_server: LocalServer) -> None:
    chunks = action_chunks(2, 1)[:, 0]
    first, second = (sync_rollout(local_server, 5, chunks) for _ in range(2))
    other_seed = sync_rollout(local_server, 6, chunks)
    for a, b in zip(first, second, strict=True):
        for name in STREAMS:
            np.testing.assert_array_equal(a[name], b[name])
    assert not np.array_equal(first[0]["front"], other_seed[0]["front"])


@pytest.mark.parametrize("frame_format", [VP9, JPEG])
def test_resize_matches_a_downscaled_full_decode(
    local_server: LocalServer, frame_format: int
) -> None:
    chunks = action_chunks(2, 1, seed=3)[:, 0]
    full = sync_rollout(local_server, 2, chunks, accepted_formats=(frame_format,))
    small = sync_rollout(local_server, 2, chunks, accepted_formats=(frame_format,), resize=(32, 48))
    for full_chunk, small_chunk in zip(full, small, strict=True):
        for name in STREAMS:
            assert small_chunk[name].shape == (4, 32, 48, 3)
            for big, little in zip(full_chunk[name], small_chunk[name], strict=True):
                error = np.abs(little.astype(np.float32) - area_downscale(big, 2)).mean()
                assert error < 6.0, (name, error)


def test_frame_consumer_gets_every_chunk_and_clip(local_server: LocalServer) -> None:
    events: list[object] = []

    class Recorder:
        def submit(self, frames: dict[str, list[np.ndarray]]) -> None:
            events.append({name: len(chunk) for name, chunk in frames.items()})

        def new_clip(self) -> None:
            events.append("new_clip")

    with A2VClient(
        local_server.endpoint, api_key=local_server.api_key, frame_consumer=Recorder()
    ) as client:
        client.prompt(PROMPT)
        client.infer(ZERO_CHUNK)
        client.infer(ZERO_CHUNK)
        client.prompt(PROMPT)
        client.infer(ZERO_CHUNK)
    chunk = dict.fromkeys(STREAMS, 4)
    assert events == ["new_clip", chunk, chunk, "new_clip", chunk]


def initialize_error(endpoint: str, kind: type, **client_kwargs: object) -> Exception:
    """The error ``with A2VClient(...)`` raises on entry (its channel is released)."""
    with pytest.raises(kind) as raised, A2VClient(endpoint, **client_kwargs):
        pass
    return raised.value


def test_initialize_errors(
    local_server: LocalServer, server_factory: Callable[..., LocalServer]
) -> None:
    endpoint, key = local_server.endpoint, local_server.api_key
    error = initialize_error(endpoint, DecartRoboticsError, api_key="")
    assert "API key is required" in str(error)
    error = initialize_error(endpoint, PermanentA2VError, api_key="wrong-key")
    assert error.code == ErrorCode.INVALID_API_KEY
    error = initialize_error(endpoint, PermanentA2VError, api_key=key, client_sdk_version="latest")
    assert error.code == ErrorCode.UNSUPPORTED_SDK_VERSION
    jpeg_only = server_factory(formats=(JPEG,))
    error = initialize_error(
        jpeg_only.endpoint, PermanentA2VError, api_key=key, accepted_formats=(VP9,)
    )
    assert error.code == ErrorCode.INVALID_FORMAT
    error = initialize_error(
        endpoint, DecartRoboticsError, api_key=key, required_streams=("front", "rear")
    )
    assert "required streams: rear" in str(error)


def test_session_errors(local_server: LocalServer, stub_factory: Callable) -> None:
    key = local_server.api_key
    with A2VClient(local_server.endpoint, api_key=key) as client:
        expect_a2v_error(lambda: client.infer(ZERO_CHUNK), PermanentA2VError, ErrorCode.PROMPT_SET)
        expect_a2v_error(lambda: client.prompt(" "), PermanentA2VError, ErrorCode.INVALID_REQUEST)
        client.prompt(PROMPT)
        client.infer(ZERO_CHUNK)
        # Another holder of the same session advances it: the client's sequence number is stale.
        raw = stub_factory(local_server.address).a2v
        metadata = (("x-api-key", key), ("x-session-target", client.session_target))
        for sequence_num in (1, 2):
            request = a2v_pb2.InferRequest(
                session_id=client.session_id,
                sequence_num=sequence_num,
                actions=[a2v_pb2.Action()] * 4,
            )
            raw.Infer(request, metadata=metadata, timeout=10)
        error = expect_a2v_error(
            lambda: client.infer(ZERO_CHUNK), SequenceError, ErrorCode.INVALID_REQUEST
        )
        assert error.details == {"expected": "3", "got": "1"}
        # ...then finishes it behind the client's back.
        raw.Finish(a2v_pb2.FinishRequest(session_id=client.session_id), metadata=metadata)
        expect_a2v_error(
            lambda: client.infer(ZERO_CHUNK), SessionLostError, ErrorCode.ALREADY_FINISHED
        )
        with pytest.raises(SessionLostError):  # close() reports the failed Finish...
            client.close()
        with pytest.raises(DecartRoboticsError, match="closed"):  # ...yet released the channel
            client.ping()


def test_idle_expiry_is_a_lost_session(server_factory: Callable[..., LocalServer]) -> None:
    server = server_factory(idle_timeout_s=0.2)
    with A2VClient(server.endpoint, api_key=server.api_key) as client:
        client.prompt(PROMPT)
        time.sleep(0.5)
        expect_a2v_error(
            lambda: client.infer(ZERO_CHUNK), SessionLostError, ErrorCode.INVALID_SESSION
        )
        with pytest.raises(SessionLostError):
            client.close()


def test_failing_close_never_hides_the_with_block_error(
    local_server: LocalServer, stub_factory: Callable, caplog: pytest.LogCaptureFixture
) -> None:
    key = local_server.api_key
    raw = stub_factory(local_server.address).a2v
    with (
        pytest.raises(KeyError, match="the real problem"),
        A2VClient(local_server.endpoint, api_key=key) as client,
    ):
        metadata = (("x-api-key", key), ("x-session-target", client.session_target))
        raw.Finish(a2v_pb2.FinishRequest(session_id=client.session_id), metadata=metadata)
        raise KeyError("the real problem")
    assert "closing the A2V client failed" in caplog.text


def test_transport_errors_after_retries(server_factory: Callable[..., LocalServer]) -> None:
    server = server_factory(max_sessions=1)
    policy = RetryPolicy(max_attempts=3, base_delay=0.001, max_delay=0.002)
    with A2VClient(server.endpoint, api_key=server.api_key):
        error = initialize_error(
            server.endpoint, TransportError, api_key=server.api_key, retry=policy
        )
        assert error.code() == grpc.StatusCode.RESOURCE_EXHAUSTED and error.attempts == 3
    # What official-SDK callers catch: a grpc.RpcError with a status code.
    error = initialize_error(dead_endpoint(), grpc.RpcError, api_key="k", retry=policy)
    assert error.code() == grpc.StatusCode.UNAVAILABLE and "after 3 attempts" in str(error)


def test_api_key_never_appears_in_logs_reprs_or_errors(
    local_server: LocalServer, caplog: pytest.LogCaptureFixture
) -> None:
    key = local_server.api_key
    caplog.set_level(logging.DEBUG)
    messages = []
    with A2VClient(local_server.endpoint, api_key=key) as client:
        messages.append(repr(client))
        client.prompt(PROMPT)
        client.infer(ZERO_CHUNK)
        for action in (lambda: client.infer([[0.0, 0.0]] * 3), lambda: client.prompt("")):
            try:
                action()
            except (ValueError, DecartRoboticsError) as error:
                messages.append(f"{error!s} {error!r}")
    failing = [
        (local_server.endpoint, {"api_key": f"wrong-{key}"}),
        (dead_endpoint(), {"api_key": key, "retry": RetryPolicy.never()}),
    ]
    for endpoint, client_kwargs in failing:
        error = initialize_error(endpoint, DecartRoboticsError, **client_kwargs)
        messages.append(f"{error!s} {error!r}")
    assert len(messages) == 5 and "***" in messages[0]
    for text in [*messages, caplog.text]:
        assert key not in text


def test_ping(local_server: LocalServer, a2v_only_endpoint: str) -> None:
    def ping(endpoint: str) -> bool:
        client = A2VClient(endpoint, api_key="k")
        try:
            return client.ping()
        finally:
            client.close()

    assert ping(local_server.endpoint) is True
    assert ping(dead_endpoint()) is False
    with pytest.raises(UnsupportedFeatureError, match=r"grpc\.health\.v1\.Health"):
        ping(a2v_only_endpoint)


def test_depth(local_server: LocalServer, a2v_only_endpoint: str) -> None:
    with A2VClient(local_server.endpoint, api_key=local_server.api_key) as client:
        client.prompt(PROMPT, seed=1)
        client.infer([[1.0, 0.0]] * 4)
        depth = client.depth()
    assert sorted(depth) == sorted(STREAMS)
    for depth_map in depth.values():
        assert depth_map.shape == (64, 96) and depth_map.dtype == np.float32
        assert (depth_map > 0).all() and np.isfinite(depth_map).any()
    with (
        A2VClient(a2v_only_endpoint, api_key=local_server.api_key) as client,
        pytest.raises(UnsupportedFeatureError, match="SimService"),
    ):
        client.depth()


def test_from_env(monkeypatch: pytest.MonkeyPatch, local_server: LocalServer) -> None:
    monkeypatch.setenv("DECART_ROBOTICS_ENDPOINT", local_server.endpoint)
    monkeypatch.setenv("DECART_API_KEY", local_server.api_key)
    with A2VClient.from_env() as client:
        assert client.endpoint == local_server.endpoint and client.session_id
    monkeypatch.delenv("DECART_ROBOTICS_ENDPOINT")
    with pytest.raises(DecartRoboticsError, match="DECART_ROBOTICS_ENDPOINT is not set"):
        A2VClient.from_env(default_endpoint=None)


@pytest.fixture(scope="module")
def certificate(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A self-signed certificate and key for 127.0.0.1 (needs the openssl command)."""
    openssl = shutil.which("openssl")
    if openssl is None:
        pytest.skip("the openssl command is not installed")
    folder = tmp_path_factory.mktemp("client-tls")
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(
        [openssl, "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
         "-keyout", str(key), "-out", str(cert), "-subj", "/CN=localhost",
         "-addext", "subjectAltName=IP:127.0.0.1"],
        check=True, capture_output=True,
    )  # fmt: skip
    return cert, key


def test_tls_endpoints(
    server_factory: Callable[..., LocalServer], certificate: tuple[Path, Path]
) -> None:
    cert, key = certificate
    server = server_factory(tls_cert=str(cert), tls_key=str(key))
    assert server.endpoint.startswith("https://")
    trusted = grpc.ssl_channel_credentials(root_certificates=cert.read_bytes())
    with A2VClient(server.endpoint, api_key=server.api_key, tls=trusted) as client:
        client.prompt(PROMPT)
        assert client.infer(ZERO_CHUNK).sequence_num == 0
    with SessionPool(server.endpoint, 2, api_key=server.api_key, tls=trusted) as pool:
        assert pool.reset(None, [PROMPT] * 2).status.tolist() == [0, 0]
    plaintext = server.endpoint.replace("https://", "http://")  # wrong: the server wants TLS
    error = initialize_error(
        plaintext, TransportError, api_key=server.api_key, retry=RetryPolicy.never()
    )
    assert error.code() == grpc.StatusCode.UNAVAILABLE
