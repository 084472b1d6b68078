"""The policy server on the wire (raw stubs): keys, limits, sizes, bad observations and the
policy's state, each answered with a clear status while the server keeps serving."""

from __future__ import annotations

import threading
from collections.abc import Callable

import grpc
import pytest
import torch

from oasis_torchrl.proto import policy_pb2, policy_pb2_grpc
from oasis_torchrl.remote.features import Feature, sample_observation
from oasis_torchrl.remote.tensors import encode, encode_map
from oasis_torchrl.serving.served import load_served_policy
from oasis_torchrl.serving.server import PolicyServer

from .conftest import KEYS

Stub = policy_pb2_grpc.PolicyServiceStub
AUTH = (("x-api-key", KEYS[0]),)


def _request(observation: dict[str, torch.Tensor]) -> policy_pb2.PredictChunkRequest:
    request = policy_pb2.PredictChunkRequest()
    encode_map(observation, request.observation)
    return request


def _sample(stub: Stub, rows: int = 2) -> dict[str, torch.Tensor]:
    described = stub.Describe(policy_pb2.DescribeRequest(), metadata=AUTH, timeout=10)
    return sample_observation([Feature.from_proto(f) for f in described.inputs], rows, seed=3)


def _fails(call: Callable[[], object], status: grpc.StatusCode, *fragments: str) -> str:
    with pytest.raises(grpc.RpcError) as caught:
        call()
    error = caught.value
    assert error.code() == status, error.details()
    for fragment in fragments:
        assert fragment in error.details()
    return error.details()


def test_describe_status_and_ping_of_a_policy_folder(
    policy_server: PolicyServer, stub_factory: Callable[[PolicyServer], Stub]
) -> None:
    stub = stub_factory(policy_server)
    described = stub.Describe(policy_pb2.DescribeRequest(), metadata=AUTH, timeout=10)
    inputs = {f.name: Feature.from_proto(f) for f in described.inputs}
    assert inputs["frame_stack.front"].describe() == "frame_stack.front: uint8 [2, 64, 96, 3]"
    assert (inputs["frame_stack.front"].low, inputs["frame_stack.front"].high) == (0.0, 255.0)
    assert inputs["state"].describe() == "state: float32 [2]"
    cameras = ["left_forward", "front", "right_forward"]
    assert list(inputs) == [*(f"frame_stack.{camera}" for camera in cameras), "state"]
    action = Feature.from_proto(described.action)
    assert (action.shape, action.names, described.chunk_size) == ((2,), ("throttle", "steering"), 4)
    assert described.policy == "policy"
    status = stub.Status(policy_pb2.StatusRequest(), metadata=AUTH, timeout=10)
    assert (status.state, status.reason) == (policy_pb2.STATE_READY, "")
    assert stub.Ping(policy_pb2.PingRequest(), metadata=AUTH, timeout=10).server_version


def test_keys_are_checked_on_every_call(
    policy_server: PolicyServer, stub_factory: Callable[[PolicyServer], Stub]
) -> None:
    stub = stub_factory(policy_server)
    ping = policy_pb2.PingRequest()
    _fails(lambda: stub.Ping(ping, timeout=10), grpc.StatusCode.UNAUTHENTICATED, "missing API key")
    wrong = (("x-api-key", "guess"),)
    _fails(lambda: stub.Ping(ping, metadata=wrong, timeout=10), grpc.StatusCode.UNAUTHENTICATED)
    request = _request(_sample(stub))
    _fails(
        lambda: stub.PredictChunk(request, metadata=wrong, timeout=10),
        grpc.StatusCode.UNAUTHENTICATED,
        "API key rejected",
    )
    assert stub.PredictChunk(request, metadata=AUTH, timeout=30).actions.shape == [2, 4, 2]


def test_bad_observations_name_the_feature_shape_and_dtype(
    policy_server: PolicyServer, stub_factory: Callable[[PolicyServer], Stub]
) -> None:
    stub = stub_factory(policy_server)
    good = _sample(stub)

    def predict(observation: dict[str, torch.Tensor]) -> object:
        return stub.PredictChunk(_request(observation), metadata=AUTH, timeout=30)

    invalid = grpc.StatusCode.INVALID_ARGUMENT
    _fails(
        lambda: predict({**good, "state": good["state"].double()}), invalid, "'state'", "float32"
    )
    _fails(
        lambda: predict({**good, "frame_stack.front": good["frame_stack.front"][:, :1]}),
        invalid,
        "'frame_stack.front'",
        "[rows, 2, 64, 96, 3] = [2, 2, 64, 96, 3], got [2, 1, 64, 96, 3]",
    )
    nan_state = good["state"].clone()
    nan_state[1, 0] = float("nan")
    _fails(lambda: predict({**good, "state": nan_state}), invalid, "'state' holds nan", "row 1")
    _fails(lambda: predict({k: v for k, v in good.items() if k != "state"}), invalid, "missing")
    _fails(lambda: predict({**good, "reward": good["state"]}), invalid, "'reward' is not an input")
    _fails(lambda: predict({**good, "state": good["state"][:1]}), invalid, "1 rows")
    malformed = _request(good)
    malformed.observation["state"].data = b"\x00" * 7
    _fails(
        lambda: stub.PredictChunk(malformed, metadata=AUTH, timeout=30),
        invalid,
        "state: 7 bytes do not hold a float32 tensor of shape [2, 2] (16 bytes)",
    )
    unknown_dtype = _request(good)
    unknown_dtype.observation["state"].dtype = 99
    _fails(
        lambda: stub.PredictChunk(unknown_dtype, metadata=AUTH, timeout=30),
        invalid,
        "unknown dtype",
    )
    assert predict(good).actions.shape == [2, 4, 2]  # still serving


def test_requests_over_the_row_and_size_limits_are_refused(
    server_factory: Callable[..., PolicyServer], stub_factory: Callable[[PolicyServer], Stub]
) -> None:
    server = server_factory(max_rows=3, max_message_bytes=512 * 1024)
    assert server.wait_until_loaded(120)
    stub = stub_factory(server)
    described = stub.Describe(policy_pb2.DescribeRequest(), metadata=AUTH, timeout=10)
    assert (described.max_batch_rows, described.max_request_bytes) == (3, 512 * 1024)
    rows_4 = _request(_sample(stub, rows=4))  # 4 rows x 3 cameras x 2 frames: 295 kB
    _fails(
        lambda: stub.PredictChunk(rows_4, metadata=AUTH, timeout=30),
        grpc.StatusCode.INVALID_ARGUMENT,
        "has 4 rows; a request holds 1 to 3",
    )
    huge = _request({"state": torch.zeros(200_000, 2)})  # 1.6 MB
    _fails(
        lambda: stub.PredictChunk(huge, metadata=AUTH, timeout=30),
        grpc.StatusCode.RESOURCE_EXHAUSTED,
        "larger than max",
    )
    _fails(
        lambda: stub.SampleInput(policy_pb2.SampleInputRequest(batch_size=4), metadata=AUTH),
        grpc.StatusCode.INVALID_ARGUMENT,
        "max_rows 3",
    )
    assert stub.PredictChunk(_request(_sample(stub, 3)), metadata=AUTH, timeout=30).actions


def test_per_key_rate_limit(
    server_factory: Callable[..., PolicyServer], stub_factory: Callable[[PolicyServer], Stub]
) -> None:
    server = server_factory(rate_per_key=0.5, burst_per_key=3)
    stub = stub_factory(server)
    ping = policy_pb2.PingRequest()
    for _ in range(3):
        stub.Ping(ping, metadata=AUTH, timeout=10)
    _fails(
        lambda: stub.Ping(ping, metadata=AUTH, timeout=10),
        grpc.StatusCode.RESOURCE_EXHAUSTED,
        "rate limit of 0.5 requests/s (burst 3)",
    )
    stub.Ping(ping, metadata=(("x-api-key", KEYS[1]),), timeout=10)  # another key's own budget


def test_sessions_per_key_are_limited(
    server_factory: Callable[..., PolicyServer], stub_factory: Callable[[PolicyServer], Stub]
) -> None:
    server = server_factory(max_sessions_per_key=2)
    assert server.wait_until_loaded(120)
    stub = stub_factory(server)
    observation = _sample(stub, rows=1)

    def select(session: str, key: str = KEYS[0]) -> object:
        request = policy_pb2.SelectActionRequest(session_id=session)
        encode_map(observation, request.observation)
        return stub.SelectAction(request, metadata=(("x-api-key", key),), timeout=30)

    select("a"), select("b"), select("a")
    _fails(lambda: select("c"), grpc.StatusCode.RESOURCE_EXHAUSTED, "holds 2 sessions")
    select("c", KEYS[1])
    _fails(lambda: select("has space"), grpc.StatusCode.INVALID_ARGUMENT, "session_id")


def test_status_while_loading_then_ready_and_after_a_failed_load(
    server_factory: Callable[..., PolicyServer],
    stub_factory: Callable[[PolicyServer], Stub],
    policy_folder: object,
) -> None:
    release = threading.Event()

    def slow_load() -> object:
        release.wait(60)
        return load_served_policy(str(policy_folder))

    server = server_factory(slow_load)
    stub = stub_factory(server)
    status = stub.Status(policy_pb2.StatusRequest(), metadata=AUTH, timeout=10)
    assert status.state == policy_pb2.STATE_LOADING
    _fails(
        lambda: stub.Describe(policy_pb2.DescribeRequest(), metadata=AUTH, timeout=10),
        grpc.StatusCode.UNAVAILABLE,
        "still loading",
    )
    release.set()
    assert server.wait_until_loaded(120)
    assert stub.Status(policy_pb2.StatusRequest(), metadata=AUTH).state == policy_pb2.STATE_READY

    broken = server_factory(lambda: load_served_policy("/no/such/policy.pt"))
    assert broken.wait_until_loaded(60)
    stub = stub_factory(broken)
    status = stub.Status(policy_pb2.StatusRequest(), metadata=AUTH, timeout=10)
    assert status.state == policy_pb2.STATE_FAILED
    assert "ValueError" in status.reason and "/no/such/policy.pt" in status.reason
    _fails(
        lambda: stub.Describe(policy_pb2.DescribeRequest(), metadata=AUTH, timeout=10),
        grpc.StatusCode.FAILED_PRECONDITION,
        "failed to load",
    )


def test_tensors_travel_as_raw_bytes() -> None:
    message = encode(torch.tensor([[1.5, -2.0]], dtype=torch.float32))
    assert (message.dtype, list(message.shape)) == (policy_pb2.DTYPE_FLOAT32, [1, 2])
    assert message.data == torch.tensor([1.5, -2.0]).numpy().tobytes()
    assert b"torch" not in message.SerializeToString()  # no pickle, no class names
