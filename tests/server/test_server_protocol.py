"""The embedded server's A2V protocol behaviour, exercised with raw generated stubs on loopback."""

from __future__ import annotations

import re
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import grpc
import numpy as np
import pytest
from grpc_health.v1 import health_pb2

from oasis_torchrl.proto import a2v_pb2, common_pb2, sim_pb2
from oasis_torchrl.protocol import CAMERAS as CAMERA_NAMES
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.encoding import Vp9Encoder
from oasis_torchrl.sim.launcher import LocalServer
from oasis_torchrl.sim.simulator import Simulator

from ._vp9 import sdk_decode

if TYPE_CHECKING:
    from conftest import RawStubs, SessionHandle

StubFactory = Callable[[str], "RawStubs"]
ServerFactory = Callable[..., LocalServer]
STRAIGHT = ((0.5, 0.0),) * 4


def packets(response: a2v_pb2.InferResponse) -> list[bytes]:
    return [frame for stream in response.streams for frame in stream.frames]


def error_code(response: object) -> int:
    assert response.HasField("error"), "expected an in-band error"  # type: ignore[attr-defined]
    return response.error.code  # type: ignore[attr-defined]


# --- Initialize -------------------------------------------------------------------------------


def test_initialize_advertises_three_rgb_streams_and_pins_the_session(stubs: RawStubs) -> None:
    response, call = stubs.initialize()
    assert not response.HasField("error")
    assert [s.name for s in response.streams] == list(CAMERA_NAMES)
    assert {(s.type, s.width, s.height) for s in response.streams} == {
        (a2v_pb2.SENSOR_TYPE_RGB, 96, 64)
    }
    assert response.output_format == common_pb2.FRAME_FORMAT_VP9
    assert dict(call.initial_metadata())["x-session-target"]
    other, _ = stubs.initialize()
    assert len(response.session_id) >= 32 and other.session_id != response.session_id


@pytest.mark.parametrize(
    ("metadata_key", "body_key"),
    [(None, ""), ("wrong-key", "wrong-key"), ("test-key-alpha", "test-key-beta")],
    ids=["missing", "wrong", "conflicting"],
)
def test_initialize_rejects_bad_api_keys(
    stubs: RawStubs, metadata_key: str | None, body_key: str
) -> None:
    response, _ = stubs.initialize(metadata_key, body_key=body_key)
    assert error_code(response) == common_pb2.ERROR_CODE_INVALID_API_KEY
    assert not response.session_id


def test_initialize_accepts_the_key_in_metadata_or_body_alone(stubs: RawStubs) -> None:
    by_metadata, _ = stubs.initialize("test-key-beta", body_key="")
    by_body = stubs.a2v.Initialize(
        a2v_pb2.InitializeRequest(
            client_sdk_version="0.0.2",
            api_key="test-key-beta",
            accepted_output_formats=[common_pb2.FRAME_FORMAT_VP9],
        )
    )
    assert not by_metadata.HasField("error") and not by_body.HasField("error")


@pytest.mark.parametrize(
    ("version", "accepted"),
    [
        ("0.0.2", True),
        ("oasis-torchrl/0.1.0", True),
        ("0.0.0+unknown", True),
        ("", False),
        ("latest", False),
        ("../../etc/passwd", False),
    ],
)
def test_sdk_version_must_be_a_version(stubs: RawStubs, version: str, accepted: bool) -> None:
    response, _ = stubs.initialize(sdk_version=version)
    if accepted:
        assert not response.HasField("error")
    else:
        assert error_code(response) == common_pb2.ERROR_CODE_UNSUPPORTED_SDK_VERSION


@pytest.mark.parametrize(
    ("offered", "chosen"),
    [
        ((common_pb2.FRAME_FORMAT_VP9,), common_pb2.FRAME_FORMAT_VP9),
        ((common_pb2.FRAME_FORMAT_JPEG, common_pb2.FRAME_FORMAT_VP9), common_pb2.FRAME_FORMAT_JPEG),
        (
            (common_pb2.FRAME_FORMAT_H264, 77, common_pb2.FRAME_FORMAT_VP9),
            common_pb2.FRAME_FORMAT_VP9,
        ),
        ((common_pb2.FRAME_FORMAT_H264, common_pb2.FRAME_FORMAT_VP8), None),
        ((), None),
    ],
)
def test_format_negotiation_follows_the_client_order(
    stubs: RawStubs, offered: tuple[int, ...], chosen: int | None
) -> None:
    response, _ = stubs.initialize(formats=offered)
    if chosen is None:
        assert error_code(response) == common_pb2.ERROR_CODE_INVALID_FORMAT
        assert "FRAME_FORMAT_VP9" in response.error.message
    else:
        assert response.output_format == chosen


def test_jpeg_session_returns_jpeg_frames(stubs: RawStubs) -> None:
    session = stubs.open_session(formats=(common_pb2.FRAME_FORMAT_JPEG,))
    response, _ = stubs.infer(session, 0)
    assert all(frame[:2] == b"\xff\xd8" for frame in packets(response))


# --- Session access -------------------------------------------------------------------------


def test_session_target_is_required_and_checked(stubs: RawStubs) -> None:
    session = stubs.open_session(prompt=None)
    key_only = session.metadata[:1]
    for metadata in (key_only, (*key_only, ("x-session-target", "oasis-sim-elsewhere"))):
        response = stubs.a2v.Prompt(
            a2v_pb2.PromptRequest(session_id=session.session_id, prompt="road"), metadata=metadata
        )
        assert error_code(response) == common_pb2.ERROR_CODE_INVALID_SESSION
        assert "x-session-target" in response.error.message


def test_a_session_belongs_to_the_key_that_opened_it(stubs: RawStubs) -> None:
    session = stubs.open_session("test-key-alpha")
    intruder = (("x-api-key", "test-key-beta"), session.metadata[1])
    response = stubs.a2v.Infer(
        a2v_pb2.InferRequest(session_id=session.session_id, sequence_num=0), metadata=intruder
    )
    assert error_code(response) == common_pb2.ERROR_CODE_INVALID_SESSION
    wrong_key = (("x-api-key", "not-a-key"), session.metadata[1])
    response = stubs.a2v.Finish(
        a2v_pb2.FinishRequest(session_id=session.session_id), metadata=wrong_key
    )
    assert error_code(response) == common_pb2.ERROR_CODE_INVALID_API_KEY
    stubs.infer(session, 0)  # the owner is unaffected


def test_unknown_session_id(stubs: RawStubs) -> None:
    session = stubs.open_session(prompt=None)
    response = stubs.a2v.Prompt(
        a2v_pb2.PromptRequest(session_id="no-such-session", prompt="road"),
        metadata=session.metadata,
    )
    assert error_code(response) == common_pb2.ERROR_CODE_INVALID_SESSION


def test_finish_ends_the_session(stubs: RawStubs) -> None:
    session = stubs.open_session()
    finish = a2v_pb2.FinishRequest(session_id=session.session_id)
    assert not stubs.a2v.Finish(finish, metadata=session.metadata).HasField("error")
    assert error_code(stubs.a2v.Finish(finish, metadata=session.metadata)) == (
        common_pb2.ERROR_CODE_ALREADY_FINISHED
    )
    response, _ = stubs.infer(session, 0)
    assert error_code(response) == common_pb2.ERROR_CODE_ALREADY_FINISHED
    intruder = (("x-api-key", "test-key-beta"), session.metadata[1])
    assert (
        error_code(stubs.a2v.Finish(finish, metadata=intruder))
        == common_pb2.ERROR_CODE_INVALID_SESSION
    )


# --- Prompt -----------------------------------------------------------------------------------


@pytest.mark.parametrize("prompt", ["", "   \n", "x" * 2001])
def test_prompt_must_be_non_blank_and_short_enough(stubs: RawStubs, prompt: str) -> None:
    session = stubs.open_session(prompt=None)
    response = stubs.a2v.Prompt(
        a2v_pb2.PromptRequest(session_id=session.session_id, prompt=prompt),
        metadata=session.metadata,
    )
    assert error_code(response) == common_pb2.ERROR_CODE_INVALID_REQUEST
    assert "prompt" in response.error.message


@pytest.mark.parametrize("seed", ["abc", "-1", "1.5", "", " 7", "18446744073709551616"])
def test_invalid_seed_metadata_is_rejected(stubs: RawStubs, seed: str) -> None:
    session = stubs.open_session(prompt=None)
    response = stubs.a2v.Prompt(
        a2v_pb2.PromptRequest(session_id=session.session_id, prompt="road"),
        metadata=session.with_metadata(("x-oasis-seed", seed)),
    )
    assert error_code(response) == common_pb2.ERROR_CODE_INVALID_REQUEST
    assert "x-oasis-seed" in response.error.message


# --- Infer ------------------------------------------------------------------------------------


def test_infer_before_prompt(stubs: RawStubs) -> None:
    session = stubs.open_session(prompt=None)
    response, _ = stubs.infer(session, 0)
    assert error_code(response) == common_pb2.ERROR_CODE_PROMPT_SET


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        (((0.0, 0.0),) * 3, "exactly 4 actions, got 3"),
        (((0.0, 0.0),) * 5, "exactly 4 actions, got 5"),
        (((0.0, 0.0),) * 3 + ((float("nan"), 0.0),), r"actions\[3\].throttle"),
        (((0.0, float("-inf")),) * 4, r"actions\[0\].steering"),
        (((1.5, 0.0),) * 4, r"in \[-1, 1\], got 1.5"),
    ],
)
def test_infer_validates_actions(
    stubs: RawStubs, actions: tuple[tuple[float, float], ...], message: str
) -> None:
    session = stubs.open_session()
    response, _ = stubs.infer(session, 0, actions)
    assert error_code(response) == common_pb2.ERROR_CODE_INVALID_REQUEST
    assert re.search(message, response.error.message)
    stubs.infer(session, 0)  # a rejected call consumed no sequence number


def test_infer_returns_decodable_frames_and_ground_truth(stubs: RawStubs) -> None:
    session = stubs.open_session(seed=11)
    decoders: dict[str, list[np.ndarray]] = {name: [] for name in CAMERA_NAMES}
    first_key_frames: list[bool] = []
    for sequence_num in range(3):
        response, call = stubs.infer(session, sequence_num)
        first_key_frames = first_key_frames or [
            Vp9Encoder.is_key_frame(p) for p in response.streams[1].frames
        ]
        assert response.sequence_num == sequence_num and not response.HasField("error")
        assert [s.name for s in response.streams] == list(CAMERA_NAMES)
        for stream in response.streams:
            assert len(stream.frames) == 4
            decoders[stream.name].extend(stream.frames)
        truth = sim_pb2.InferTruth.FromString(dict(call.trailing_metadata())["x-oasis-truth-bin"])
        assert (truth.sequence_num, truth.seed, len(truth.frames)) == (sequence_num, 11, 4)
    assert first_key_frames == [True] + [False] * 3
    for stream_packets in decoders.values():
        frames = sdk_decode(stream_packets)
        assert len(frames) == 12 and frames[0].shape == (64, 96, 3)


def test_ground_truth_carries_the_experts_next_chunk(stubs: RawStubs) -> None:
    # The server's expert is the simulator's autopilot, one per session, restarted at a Prompt.
    def expert_of(call: object) -> np.ndarray:
        truth = sim_pb2.InferTruth.FromString(dict(call.trailing_metadata())["x-oasis-truth-bin"])
        return np.array(truth.expert_actions, np.float32).reshape(4, 2)

    for prompt, seed in (("urban street", 5), ("highway", 2)):
        session = stubs.open_session(prompt=prompt, seed=seed)
        simulator = Simulator(96, 64)
        simulator.reset(prompt, seed)
        chunk, pilot = np.zeros((4, 2), np.float32), None
        for sequence_num in range(6):
            _, call = stubs.infer(session, sequence_num, [tuple(action) for action in chunk])
            simulator.step(chunk, render=False)
            pilot = pilot or Autopilot(simulator)
            chunk = pilot.act()
            np.testing.assert_array_equal(expert_of(call), chunk)
        assert chunk[:, 0].mean() > 0.1  # it drives


def test_sequence_numbers_replay_and_restart_after_prompt(stubs: RawStubs) -> None:
    session = stubs.open_session(seed=3)
    skipped, _ = stubs.infer(session, 1)
    assert error_code(skipped) == common_pb2.ERROR_CODE_INVALID_REQUEST
    assert dict(skipped.error.details) == {"expected": "0", "got": "1"}
    original, call = stubs.infer(session, 0)
    replayed, replay_call = stubs.infer(session, 0)
    assert replayed.SerializeToString() == original.SerializeToString()
    assert dict(replay_call.trailing_metadata()) == dict(call.trailing_metadata())
    altered, _ = stubs.infer(session, 0, ((0.0, 1.0),) * 4)
    assert error_code(altered) == common_pb2.ERROR_CODE_INVALID_REQUEST
    assert not stubs.infer(session, 1)[0].HasField("error")
    stale, _ = stubs.infer(session, 0)
    assert error_code(stale) == common_pb2.ERROR_CODE_INVALID_REQUEST
    stubs.prompt(session, "a rainy city street", seed=3)
    restarted, _ = stubs.infer(session, 0)
    assert all(Vp9Encoder.is_key_frame(s.frames[0]) for s in restarted.streams)


def test_same_prompt_and_seed_give_identical_packets(stubs: RawStubs) -> None:
    chunks = [((0.8, 0.0),) * 4, ((0.3, -0.6),) * 4, ((-0.5, 0.4),) * 4]

    def rollout(seed: int) -> list[bytes]:
        session = stubs.open_session(prompt="a winding mountain road", seed=seed)
        return [
            p for k, chunk in enumerate(chunks) for p in packets(stubs.infer(session, k, chunk)[0])
        ]

    assert rollout(5) == rollout(5)
    assert rollout(5) != rollout(6)


def test_steering_left_and_right_give_different_frames(stubs: RawStubs) -> None:
    def last_front_frame(steering: float) -> np.ndarray:
        session = stubs.open_session(seed=1)
        stream = []
        for k in range(3):
            response, _ = stubs.infer(session, k, ((0.8, steering),) * 4)
            stream += list(response.streams[1].frames)
        return sdk_decode(stream)[-1]

    assert np.abs(last_front_frame(-1.0).astype(int) - last_front_frame(1.0)).mean() > 2


# --- Depth, scene, health ---------------------------------------------------------------------


def test_depth_and_scene_of_a_session(stubs: RawStubs) -> None:
    session = stubs.open_session(prompt="a foggy highway", seed=9)
    stubs.infer(session, 0)
    depth = stubs.sim.GetDepth(
        sim_pb2.DepthRequest(session_id=session.session_id), metadata=session.metadata
    )
    assert [m.name for m in depth.maps] == list(CAMERA_NAMES)
    for depth_map in depth.maps:
        values = np.frombuffer(depth_map.depth_f16, "<f2").reshape(depth_map.height, -1)
        assert values.shape == (64, 96)
        assert np.isfinite(values).any() and (values > 0).all()
    scene = stubs.sim.GetScene(
        sim_pb2.SceneRequest(session_id=session.session_id), metadata=session.metadata
    )
    assert (scene.prompt, scene.seed) == ("a foggy highway", 9)


@pytest.mark.parametrize(
    ("case", "status"),
    [
        ("no_prompt", grpc.StatusCode.FAILED_PRECONDITION),
        ("wrong_key", grpc.StatusCode.UNAUTHENTICATED),
        ("unknown_id", grpc.StatusCode.NOT_FOUND),
    ],
)
def test_sim_service_errors_are_statuses(
    stubs: RawStubs, case: str, status: grpc.StatusCode
) -> None:
    session = stubs.open_session(prompt=None)
    metadata = session.metadata
    session_id = "unknown" if case == "unknown_id" else session.session_id
    if case == "wrong_key":
        metadata = (("x-api-key", "nope"), metadata[1])
    with pytest.raises(grpc.RpcError) as raised:
        stubs.sim.GetDepth(sim_pb2.DepthRequest(session_id=session_id), metadata=metadata)
    assert raised.value.code() == status


def test_health_is_serving_then_not_serving_during_shutdown(
    server_factory: ServerFactory, stub_factory: StubFactory
) -> None:
    server = server_factory()
    stubs = stub_factory(server.address)
    for service in ("", "decart.inference.a2v.A2VService"):
        reply = stubs.health.Check(health_pb2.HealthCheckRequest(service=service), timeout=5)
        assert reply.status == health_pb2.HealthCheckResponse.SERVING
    watch = stubs.health.Watch(health_pb2.HealthCheckRequest(service=""), timeout=10)
    assert next(watch).status == health_pb2.HealthCheckResponse.SERVING
    threading.Timer(0.1, server.stop, kwargs={"grace": 1.0}).start()
    assert next(watch).status == health_pb2.HealthCheckResponse.NOT_SERVING


# --- Limits, expiry, injected failures --------------------------------------------------------


def test_idle_sessions_expire(server_factory: ServerFactory, stub_factory: StubFactory) -> None:
    server = server_factory(idle_timeout_s=0.3, max_sessions=1)
    stubs = stub_factory(server.address)
    session = stubs.open_session(prompt=None)
    time.sleep(0.8)
    # The reaper freed the only slot (opening does not expire sessions itself)...
    stubs.open_session(prompt=None)
    # ...and the expired session is unknown from now on.
    response = stubs.a2v.Prompt(
        a2v_pb2.PromptRequest(session_id=session.session_id, prompt="road"),
        metadata=session.metadata,
    )
    assert error_code(response) == common_pb2.ERROR_CODE_INVALID_SESSION


def test_session_limits_total_and_per_key(
    server_factory: ServerFactory, stub_factory: StubFactory
) -> None:
    server = server_factory(max_sessions=2, max_sessions_per_key=1)
    stubs = stub_factory(server.address)

    def refused(api_key: str) -> str:
        with pytest.raises(grpc.RpcError) as raised:
            stubs.initialize(api_key)
        assert raised.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
        return raised.value.details()

    alpha = stubs.open_session("test-key-alpha", prompt=None)
    assert "this API key holds its limit of 1" in refused("test-key-alpha")
    stubs.open_session("test-key-beta", prompt=None)
    assert "the server holds its limit of 2" in refused("test-key-beta")
    stubs.a2v.Finish(a2v_pb2.FinishRequest(session_id=alpha.session_id), metadata=alpha.metadata)
    stubs.open_session("test-key-alpha", prompt=None)


def test_injected_failures_follow_the_configured_rate(
    server_factory: ServerFactory, stub_factory: StubFactory
) -> None:
    flaky = stub_factory(server_factory(failure_rate=0.3, failure_seed=1).address)
    outcomes = []
    for _ in range(100):
        try:
            response, _ = flaky.initialize("not-a-key")
            outcomes.append(error_code(response))
        except grpc.RpcError as error:
            outcomes.append(error.code())
    failed = outcomes.count(grpc.StatusCode.UNAVAILABLE)
    assert 15 <= failed <= 45, f"{failed} of 100 calls failed at rate 0.3"
    assert outcomes.count(common_pb2.ERROR_CODE_INVALID_API_KEY) == 100 - failed


def test_injected_failures_are_transient_and_retries_are_exact(
    server_factory: ServerFactory, stub_factory: StubFactory, stubs: RawStubs
) -> None:
    flaky = stub_factory(server_factory(failure_rate=0.3, failure_seed=4).address)
    failures = 0

    def retried(call: Callable[[], object]) -> object:
        nonlocal failures
        for _ in range(50):
            try:
                return call()
            except grpc.RpcError as error:
                assert error.code() == grpc.StatusCode.UNAVAILABLE
                failures += 1
        raise AssertionError("50 failures in a row")

    session: SessionHandle = retried(lambda: flaky.open_session(seed=2))  # type: ignore[assignment]
    flaky_packets = [
        p for k in range(8) for p in packets(retried(lambda k=k: flaky.infer(session, k))[0])
    ]
    reference = stubs.open_session(seed=2)
    assert flaky_packets == [p for k in range(8) for p in packets(stubs.infer(reference, k)[0])]
    assert failures > 0, "no call failed: the retry path was not exercised"
