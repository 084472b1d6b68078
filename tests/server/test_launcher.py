"""Launchers (in-process and subprocess), the serve command's flags, and config validation."""

from __future__ import annotations

import dataclasses
import pickle
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import grpc
import pytest
from grpc_health.v1 import health_pb2

from oasis_torchrl.cli import build_parser, main, parse_arguments
from oasis_torchrl.config import to_object
from oasis_torchrl.config.arguments import load_from_args
from oasis_torchrl.config.serving import ServeConfig
from oasis_torchrl.proto import common_pb2
from oasis_torchrl.protocol import SERVER_API_KEYS_ENV_VAR as API_KEYS_ENV_VAR
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer, ServerProcess

if TYPE_CHECKING:
    from conftest import RawStubs

StubFactory = Callable[[str], "RawStubs"]


def test_server_process_serves_then_dies_on_kill(stub_factory: StubFactory) -> None:
    with ServerProcess(width=96, height=64, latency_ms=1.0) as server:
        stubs = stub_factory(server.address)
        reply = stubs.health.Check(health_pb2.HealthCheckRequest(service=""), timeout=5)
        assert reply.status == health_pb2.HealthCheckResponse.SERVING
        session = stubs.open_session(server.api_key)
        assert not stubs.infer(session, 0)[0].HasField("error")
        command_line = Path(f"/proc/{server.pid}/cmdline").read_bytes().replace(b"\0", b" ")
        assert b"--port-file" in command_line and server.api_key.encode() not in command_line
        assert server.kill() == -9
        assert not server.is_running()
        with pytest.raises(grpc.RpcError) as raised:
            stubs.infer(session, 1)
        assert raised.value.code() == grpc.StatusCode.UNAVAILABLE


def test_server_process_stops_cleanly_on_sigterm() -> None:
    server = ServerProcess(width=96, height=64).start()
    log_path = server.log_path
    assert server.stop() == 0
    assert log_path is not None and not log_path.exists()  # its work folder is removed
    assert server.stop() is None  # idempotent


def test_server_process_reports_a_failed_start() -> None:
    server = ServerProcess(tls_cert="/nonexistent/cert.pem", tls_key="/nonexistent/key.pem")
    with pytest.raises(RuntimeError, match=r"exited with code 2[\s\S]*nonexistent"):
        server.start()
    assert not server.is_running()


def test_local_server_generates_a_key_and_frees_its_port(
    monkeypatch: pytest.MonkeyPatch, stub_factory: StubFactory
) -> None:
    monkeypatch.delenv(API_KEYS_ENV_VAR, raising=False)
    server = LocalServer(width=96, height=64).start()
    stubs = stub_factory(server.address)
    assert len(server.api_key) >= 24
    assert not stubs.initialize(server.api_key)[0].HasField("error")
    refused, _ = stubs.initialize("some-other-key")
    assert refused.error.code == common_pb2.ERROR_CODE_INVALID_API_KEY
    port = server.port
    server.stop()
    server.stop()  # idempotent
    with LocalServer(width=96, height=64, port=port) as successor:  # the port is free again
        assert successor.port == port


def _served(argv: list[str]) -> ServeConfig:
    return to_object(load_from_args(parse_arguments(build_parser(), ["serve", *argv]), ServeConfig))


def test_serve_has_a_flag_for_every_setting_and_configs_travel_as_json() -> None:
    config = ServerConfig(
        host="0.0.0.0", port=1234, width=128, height=96, fps=10.0, api_keys=("k",),
        allow_any_key=True, latency_ms=2.5, failure_rate=0.1, failure_seed=7, idle_timeout_s=9.0,
        max_sessions=5, max_sessions_per_key=3, max_prompt_chars=50, max_message_bytes=4096,
        tls_cert="cert.pem", tls_key="key.pem", workers=4, processes=3, encode_workers=2,
        formats=(common_pb2.FRAME_FORMAT_VP9,), vp9_cpu_used=5, vp9_bit_rate=500_000,
        vp9_threads=2, jpeg_quality=70, hosted=True,
    )  # fmt: skip
    defaults = ServerConfig(api_keys=("other",))
    changed = [
        f.name
        for f in dataclasses.fields(config)
        if getattr(config, f.name) == getattr(defaults, f.name)
    ]
    assert not changed, f"set every field to a non-default value: {changed}"
    argv = shlex.split(
        "--host 0.0.0.0 --port 1234 --width 128 --height 96 --fps 10 --api-key k --allow-any-key "
        "--latency-ms 2.5 --failure-rate 0.1 --failure-seed 7 --idle-timeout 9 --max-sessions 5 "
        "--max-sessions-per-key 3 --max-prompt-chars 50 --max-message-bytes 4096 "
        "--tls-cert cert.pem --tls-key key.pem --workers 4 --processes 3 --encode-workers 2 "
        "--formats vp9 --hosted "
        "--vp9-cpu-used 5 --vp9-bit-rate 500000 --vp9-threads 2 --jpeg-quality 70"
    )
    assert _served(argv).server_config() == config
    assert _served([*argv, "width=256"]).width == 256  # key=value overrides come last
    assert ServerConfig.from_json(config.to_json()) == config
    assert pickle.loads(pickle.dumps(config)) == config


def test_cli_rejects_bad_settings(caplog: pytest.LogCaptureFixture) -> None:
    assert main(["serve", "--width", "7", "--api-key", "k"]) == 2
    assert main(["serve", "--formats", "h264"]) == 2
    assert "formats must be a comma-separated list" in caplog.text


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"height": 63}, "height must be an even integer"),
        ({"fps": float("nan")}, "fps must be a number"),
        ({"failure_rate": 1.5}, "failure_rate must be a number in"),
        ({"port": 70000}, "port must be an integer in"),
        ({"tls_cert": "cert.pem"}, "tls_cert and tls_key must be given together"),
        ({"formats": (common_pb2.FRAME_FORMAT_H264,)}, "formats contains FRAME_FORMAT_H264"),
        ({"api_keys": ("has space",)}, r"api_keys\[0\] must be"),
        ({"vp9_cpu_used": 9}, "vp9_cpu_used must be an integer in"),
    ],
)
def test_config_validation_names_the_field(overrides: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ServerConfig(**{"api_keys": ("k",), **overrides})  # type: ignore[arg-type]


def test_a_server_process_stops_when_its_launcher_dies(tmp_path: Path) -> None:
    # The launching process is killed without stopping its server: the server must not linger.
    script = (
        "import sys\n"
        "from oasis_torchrl.sim.launcher import ServerProcess\n"
        "server = ServerProcess(width=96, height=64, processes=1).start()\n"
        "print(server.pid, flush=True)\n"
        "sys.stdin.read()\n"
    )
    launcher = subprocess.Popen(
        [sys.executable, "-c", script], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    server_pid = int(launcher.stdout.readline())
    launcher.kill()
    launcher.wait()
    deadline = time.monotonic() + 30
    while not _ended(server_pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _ended(server_pid), "the server outlived its launcher"


def _ended(pid: int) -> bool:
    """Whether process ``pid`` has exited (gone, or a zombie its new parent has not reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True
