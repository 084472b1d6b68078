"""Pure parts of the client: errors, retry policy, endpoint rules, request checks, side data."""

from __future__ import annotations

import asyncio
import random

import grpc
import numpy as np
import pytest

from oasis_torchrl.client import ground_truth, wire
from oasis_torchrl.client.channel import parse_endpoint
from oasis_torchrl.client.errors import (
    A2VError,
    DecartRoboticsError,
    ErrorCode,
    PermanentA2VError,
    SequenceError,
    SessionLostError,
    TransportError,
    a2v_error_from_proto,
)
from oasis_torchrl.client.retry import RetryBudget, RetryPolicy, acall_with_retry, call_with_retry
from oasis_torchrl.client.session import SessionState
from oasis_torchrl.client.types import FrameFormat
from oasis_torchrl.proto import a2v_pb2, common_pb2, sim_pb2
from oasis_torchrl.protocol import TRUTH_METADATA

# ------------------------------------------------------------------------ errors


def test_enums_mirror_the_protocol() -> None:
    assert {f"ERROR_CODE_{c.name}": c.value for c in ErrorCode} == dict(
        common_pb2.ErrorCode.items()
    )
    ours = {f"FRAME_FORMAT_{f.name}": f.value for f in FrameFormat if f != FrameFormat.RAW_RGB24}
    assert ours == dict(common_pb2.FrameFormat.items())
    assert FrameFormat.RAW_RGB24 not in common_pb2.FrameFormat.values()  # our extension


@pytest.mark.parametrize(
    ("code", "message", "kind"),
    [
        (common_pb2.ERROR_CODE_INVALID_SESSION, "unknown session", SessionLostError),
        (common_pb2.ERROR_CODE_ALREADY_FINISHED, "finished", SessionLostError),
        (
            common_pb2.ERROR_CODE_INVALID_REQUEST,
            "unexpected sequence_num: expected 1",
            SequenceError,
        ),
        (common_pb2.ERROR_CODE_INVALID_REQUEST, "prompt is empty", PermanentA2VError),
        (common_pb2.ERROR_CODE_INVALID_API_KEY, "API key rejected", PermanentA2VError),
        (common_pb2.ERROR_CODE_UNSUPPORTED_SDK_VERSION, "bad version", PermanentA2VError),
        (common_pb2.ERROR_CODE_INVALID_FORMAT, "no format", PermanentA2VError),
        (common_pb2.ERROR_CODE_PROMPT_SET, "call Prompt first", PermanentA2VError),
    ],
)
def test_in_band_errors_map_to_their_kind(code: int, message: str, kind: type) -> None:
    error = a2v_error_from_proto(common_pb2.Error(code=code, message=message, details={"a": "b"}))
    assert type(error) is kind
    assert isinstance(error, A2VError) and isinstance(error, DecartRoboticsError)
    assert (error.code, error.message, error.details) == (code, message, {"a": "b"})
    assert str(error).startswith(f"A2V error {code} ({ErrorCode(code).name}): {message}")


def test_secret_is_masked_and_row_is_named() -> None:
    proto = common_pb2.Error(code=9, message="key sk-live-1 rejected", details={"key": "sk-live-1"})
    error = a2v_error_from_proto(proto, secret="sk-live-1")
    assert "sk-live-1" not in str(error) + repr(error) + repr(error.args)
    error.row = 3
    assert str(error).startswith("session row 3: A2V error 9")


def test_transport_error_is_a_grpc_rpc_error() -> None:
    error = TransportError(
        grpc.StatusCode.UNAVAILABLE,
        "refused",
        method="Infer",
        target="h:1",
        attempts=3,
        elapsed=0.5,
    )
    assert isinstance(error, grpc.RpcError) and isinstance(error, DecartRoboticsError)
    assert error.code() == grpc.StatusCode.UNAVAILABLE and error.details() == "refused"
    assert str(error) == "Infer to h:1 failed after 3 attempts in 0.50 s: UNAVAILABLE: refused"


# ------------------------------------------------------------------------- retry


def test_backoff_is_capped_exponential_with_full_jitter() -> None:
    policy = RetryPolicy(base_delay=0.1, max_delay=0.5)
    rng = random.Random(0)
    for attempt, ceiling in [(1, 0.1), (2, 0.2), (3, 0.4), (4, 0.5), (9, 0.5)]:
        delays = [policy.backoff(attempt, rng) for _ in range(200)]
        assert min(delays) >= 0.0 and max(delays) <= ceiling
        assert max(delays) > 0.7 * ceiling  # spread over the whole range
    assert RetryPolicy(jitter=False, base_delay=0.1, max_delay=0.5).backoff(9) == 0.5


def test_which_failures_are_retried() -> None:
    policy = RetryPolicy()
    assert policy.is_retryable(grpc.StatusCode.UNAVAILABLE, "Initialize")
    assert policy.is_retryable(grpc.StatusCode.RESOURCE_EXHAUSTED, "Prompt")
    assert policy.is_retryable(grpc.StatusCode.DEADLINE_EXCEEDED, "Infer")
    assert not policy.is_retryable(grpc.StatusCode.DEADLINE_EXCEEDED, "Initialize")
    assert not policy.is_retryable(grpc.StatusCode.UNAUTHENTICATED, "Infer")
    assert not policy.is_retryable(grpc.StatusCode.INVALID_ARGUMENT, "Infer")


def test_policy_rejects_bad_settings() -> None:
    for bad in ({"max_attempts": 0}, {"base_delay": -1}, {"max_delay": 0.01}, {"deadline": 0}):
        with pytest.raises(ValueError):
            RetryPolicy(**bad)


class Flaky:
    """Fails ``failures`` times with ``status``, then answers; records the timeouts it got."""

    def __init__(self, failures: int, status: grpc.StatusCode = grpc.StatusCode.UNAVAILABLE):
        self.failures = failures
        self.status = status
        self.timeouts: list[float | None] = []

    def __call__(self, timeout: float | None) -> str:
        self.timeouts.append(timeout)
        if len(self.timeouts) <= self.failures:
            raise TransportError(self.status, "key sk-9 flaked", method="raw")
        return "answer"


def test_call_with_retry_recovers_then_gives_up_with_a_clear_error() -> None:
    fast = RetryPolicy(max_attempts=4, base_delay=0.001, max_delay=0.002)
    flaky = Flaky(3)
    assert call_with_retry(flaky, policy=fast, method="Infer", timeout=2.0) == "answer"
    assert flaky.timeouts == [2.0] * 4
    with pytest.raises(TransportError) as raised:
        call_with_retry(Flaky(9), policy=fast, method="Infer", timeout=2.0, secret="sk-9")
    assert raised.value.attempts == 4 and "sk-9" not in str(raised.value)
    with pytest.raises(TransportError) as raised:  # not transient: one attempt only
        call_with_retry(
            Flaky(9, grpc.StatusCode.UNAUTHENTICATED), policy=fast, method="Infer", timeout=2.0
        )
    assert raised.value.attempts == 1


def test_deadline_bounds_attempt_timeouts_and_retries() -> None:
    budget = RetryBudget(RetryPolicy(deadline=0.05, base_delay=0.04, jitter=False), "Infer", 10.0)
    assert budget.attempt_timeout() <= 0.05
    assert budget.next_delay(grpc.StatusCode.UNAVAILABLE) == 0.04
    assert budget.next_delay(grpc.StatusCode.UNAVAILABLE) is None  # 0.08 s would pass 0.05


def test_async_retry_matches_sync() -> None:
    fast = RetryPolicy(max_attempts=3, base_delay=0.001, max_delay=0.002)
    flaky = Flaky(2)

    async def call(timeout: float | None) -> str:
        return flaky(timeout)

    assert (
        asyncio.run(acall_with_retry(call, policy=fast, method="Prompt", timeout=1.0)) == "answer"
    )
    assert len(flaky.timeouts) == 3


# --------------------------------------------------------------------- endpoints


@pytest.mark.parametrize(
    ("endpoint", "tls", "address", "secure"),
    [
        ("https://oasis-grpc.decart.ai", None, "oasis-grpc.decart.ai", True),
        ("https://oasis-grpc.decart.ai/", None, "oasis-grpc.decart.ai", True),
        ("http://127.0.0.1:50051", None, "127.0.0.1:50051", False),
        ("http://127.0.0.1:50051", True, "127.0.0.1:50051", True),
        ("https://host:443", False, "host:443", False),
        ("localhost:50051", None, "localhost:50051", True),
        ("localhost:50051", False, "localhost:50051", False),
        ("dns:///svc:50051", False, "dns:///svc:50051", False),
    ],
)
def test_endpoint_rules_follow_the_official_sdk(
    endpoint: str, tls: bool | None, address: str, secure: bool
) -> None:
    target = parse_endpoint(endpoint, tls)
    assert (target.address, target.secure) == (address, secure)


def test_bad_endpoints_and_tls_are_rejected() -> None:
    with pytest.raises(ValueError, match="Invalid endpoint"):
        parse_endpoint("http://")
    with pytest.raises(TypeError, match="tls"):
        parse_endpoint("h:1", tls="yes")  # type: ignore[arg-type]
    custom = grpc.ssl_channel_credentials()
    assert parse_endpoint("http://h:1", tls=custom).credentials is custom


# ------------------------------------------------------------------ wire checks


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        ([[0.0, 0.0]] * 3, r"shape \(4, 2\)"),
        ([[0.0, 0.0, 0.0]] * 4, r"shape \(4, 2\)"),
        ([[float("nan"), 0.0]] * 4, "finite"),
        ([[0.0, float("inf")]] * 4, "finite"),
        ([[0.0, -1.01]] * 4, r"in \[-1, 1\]"),
    ],
)
def test_action_chunks_are_checked_locally(actions: list, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        wire.validate_action_chunk(actions)


def test_action_batches_name_the_bad_row() -> None:
    batch = np.zeros((3, 4, 2), np.float32)
    assert wire.validate_action_batch(batch, [0, 1, 2]).dtype == np.float32
    batch[2, 1, 1] = 1.5
    with pytest.raises(ValueError, match="actions for row 7 must be in"):
        wire.validate_action_batch(batch, [4, 5, 7])
    with pytest.raises(ValueError, match=r"shape \(2, 4, 2\)"):
        wire.validate_action_batch(batch, [0, 1])


def test_seeds_metadata_and_formats() -> None:
    assert wire.prompt_metadata((("x-api-key", "k"),), 2**64 - 1)[-1] == (
        "x-oasis-seed",
        str(2**64 - 1),
    )
    assert wire.prompt_metadata((), None) == ()
    for bad in (-1, 2**64, 1.5, True, "3"):
        with pytest.raises(ValueError, match="seed"):
            wire.validate_seed(bad)  # type: ignore[arg-type]
    assert wire.call_metadata(None) == ()
    for bad in ((), (FrameFormat.H264,), (FrameFormat.VP9, FrameFormat.VP9)):
        with pytest.raises(ValueError, match="accepted_formats"):
            wire.accepted_format_list(bad, "http://127.0.0.1:1")
    # Raw RGB (our extension) is offered first to a server on this machine, never to another.
    local, remote = "http://127.0.0.1:1", "https://oasis-grpc.decart.ai"
    assert wire.accepted_format_list(None, local) == (
        FrameFormat.RAW_RGB24,
        FrameFormat.VP9,
        FrameFormat.JPEG,
    )
    assert wire.accepted_format_list(None, remote) == (FrameFormat.VP9, FrameFormat.JPEG)


def test_session_parsing_and_checks() -> None:
    response = a2v_pb2.InitializeResponse(
        session_id="s",
        output_format=common_pb2.FRAME_FORMAT_JPEG,
        streams=[a2v_pb2.StreamInfo(name="front", type=1, height=64, width=96)],
    )
    info = wire.parse_session(response, [("x-session-target", b"n1")])
    assert (info.session_target, info.streams[0].width, info.output_format) == ("n1", 96, 1)
    wire.check_session(info, accepted_formats=[FrameFormat.JPEG], required_streams=["front"])
    with pytest.raises(DecartRoboticsError, match="required streams: left_forward"):
        wire.check_session(
            info, accepted_formats=[FrameFormat.JPEG], required_streams=["front", "left_forward"]
        )
    with pytest.raises(DecartRoboticsError, match="negotiated output format JPEG"):
        wire.check_session(info, accepted_formats=[FrameFormat.VP9], required_streams=[])


# ---------------------------------------------------------------- side channel


def test_truth_and_depth_parsing() -> None:
    truth = sim_pb2.InferTruth(
        sequence_num=2,
        frames=[sim_pb2.FrameTruth(speed=float(k), off_road=k == 3) for k in range(4)],
    )
    parsed = ground_truth.parse_truth([("other", "x"), (TRUTH_METADATA, truth.SerializeToString())])
    table = ground_truth.truth_array(parsed)
    assert table.shape == (4, len(ground_truth.TRUTH_FIELDS))
    assert table[:, ground_truth.TRUTH_FIELDS.index("speed")].tolist() == [0.0, 1.0, 2.0, 3.0]
    assert table[:, ground_truth.TRUTH_FIELDS.index("off_road")].tolist() == [0.0, 0.0, 0.0, 1.0]
    assert ground_truth.parse_truth(None) is None
    depth = np.array([[1.5, np.inf], [2.0, 100.0]], "<f2")
    response = sim_pb2.DepthResponse(
        maps=[sim_pb2.DepthMap(name="front", height=2, width=2, depth_f16=depth.tobytes())]
    )
    np.testing.assert_array_equal(
        ground_truth.depth_maps(response)["front"], depth.astype(np.float32)
    )


# --------------------------------------------------------------- session state machine


def _state() -> SessionState:
    return SessionState(
        "key", sdk_version="0.0.2", accepted_formats=[FrameFormat.VP9], required_streams=["front"]
    )


def _initialized(output_format: int = FrameFormat.VP9) -> SessionState:
    state = _state()
    streams = [a2v_pb2.StreamInfo(name="front", type=1, height=64, width=96)]
    response = a2v_pb2.InitializeResponse(
        session_id="s1", output_format=output_format, streams=streams
    )
    state.on_initialize(response, [("x-session-target", b"node-1")])
    return state


def test_session_state_counts_sequences_and_replays_its_prompt() -> None:
    state = _initialized()
    assert state.session_id == "s1" and ("x-session-target", "node-1") in state.metadata
    with pytest.raises(DecartRoboticsError, match="never prompted"):
        state.replay_prompt()
    prompt = state.prompt("a road", 7)
    assert prompt.metadata[-1] == ("x-oasis-seed", "7")
    state.on_prompt(a2v_pb2.PromptResponse())
    chunk = np.zeros((4, 2), np.float32)
    for expected in (0, 1):
        call = state.infer(chunk)
        assert call.request.sequence_num == expected
        state.on_infer(a2v_pb2.InferResponse(sequence_num=expected), None)
    replay = state.replay_prompt()
    assert (replay.request.prompt, replay.metadata[-1]) == ("a road", ("x-oasis-seed", "7"))
    state.on_prompt(a2v_pb2.PromptResponse())
    assert state.infer(chunk).request.sequence_num == 0  # a Prompt restarts the rollout
    error = common_pb2.Error(code=common_pb2.ERROR_CODE_INVALID_SESSION, message="gone")
    with pytest.raises(SessionLostError):
        state.on_infer(a2v_pb2.InferResponse(error=error), None)


def test_session_state_refuses_a_format_it_did_not_offer_but_can_finish_it() -> None:
    with pytest.raises(DecartRoboticsError, match="negotiated output format JPEG"):
        _initialized(FrameFormat.JPEG)
    state = _state()
    assert state.finish() is None  # nothing open
    with pytest.raises(DecartRoboticsError):
        state.on_initialize(
            a2v_pb2.InitializeResponse(session_id="s2", output_format=FrameFormat.JPEG), ()
        )
    finish = state.finish()
    assert finish is not None and finish.request.session_id == "s2"
    assert state.finish() is None  # forgotten at once: a failing Finish is not sent twice
