"""The hosted-like server: what the hosted service sends (VP9 frames, error codes, the
session-pinning header) and nothing more (no truth, no SimService, seeds and expert ignored)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import grpc
import numpy as np
import pytest
from grpc_health.v1 import health_pb2

from oasis_torchrl.cli import build_parser, parse_arguments
from oasis_torchrl.config import to_object
from oasis_torchrl.config.arguments import load_from_args
from oasis_torchrl.config.serving import ServeConfig
from oasis_torchrl.proto import a2v_pb2, common_pb2, sim_pb2
from oasis_torchrl.protocol import (
    CAMERAS,
    EXPERT_METADATA,
    EXPERT_ON,
    FRAMES_METADATA,
    HOSTED_FRAME_SIZE,
    LAST_FRAME_ONLY,
    SIM_SERVICE,
    TRUTH_METADATA,
    FrameFormat,
)
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.launcher import LocalServer

from ._vp9 import sdk_decode

if TYPE_CHECKING:
    from conftest import RawStubs


@pytest.fixture
def hosted(
    server_factory: Callable[..., LocalServer], stub_factory: Callable[[str], RawStubs]
) -> RawStubs:
    """Stubs connected to a hosted-like server at 96x64 (the protocol does not depend on size)."""
    return stub_factory(server_factory(hosted=True, processes=0).address)


def test_default_hosted_server_streams_768x512_vp9_and_serve_has_the_flag(
    stub_factory: Callable[[str], RawStubs],
) -> None:
    config = to_object(
        load_from_args(parse_arguments(build_parser(), ["serve", "--hosted"]), ServeConfig)
    )
    assert config.hosted is True
    assert (config.height, config.width) == HOSTED_FRAME_SIZE
    assert ServerConfig(hosted=True, api_keys=("k",)).formats == (FrameFormat.VP9,)
    with LocalServer(hosted=True, processes=0) as server:
        stubs = stub_factory(server.address)
        raw_first = (FrameFormat.RAW_RGB24, common_pb2.FRAME_FORMAT_VP9)
        response, _ = stubs.initialize(server.api_key, formats=raw_first)
        assert response.output_format == common_pb2.FRAME_FORMAT_VP9
        assert [(s.name, s.height, s.width) for s in response.streams] == [
            (name, *HOSTED_FRAME_SIZE) for name in CAMERAS
        ]


def test_hosted_sends_frames_and_nothing_more(hosted: RawStubs) -> None:
    response, _ = hosted.initialize(formats=(FrameFormat.RAW_RGB24, common_pb2.FRAME_FORMAT_VP9))
    assert response.output_format == common_pb2.FRAME_FORMAT_VP9
    session = hosted.open_session(seed=7)
    prompt_extra = ((EXPERT_METADATA, EXPERT_ON), (FRAMES_METADATA, LAST_FRAME_ONLY))
    hosted.a2v.Prompt(
        a2v_pb2.PromptRequest(session_id=session.session_id, prompt="urban"),
        metadata=session.with_metadata(*prompt_extra),
        timeout=10,
    )
    answer, infer_call = hosted.infer(session, 0)
    assert not answer.HasField("error")
    assert [len(stream.frames) for stream in answer.streams] == [4, 4, 4]
    assert np.stack(sdk_decode(answer.streams[1].frames)).shape == (4, 64, 96, 3)
    trailing = dict(infer_call.trailing_metadata() or ())
    assert TRUTH_METADATA not in trailing
    with pytest.raises(grpc.RpcError) as error:
        hosted.sim.GetDepth(
            sim_pb2.DepthRequest(session_id=session.session_id), metadata=session.metadata
        )
    assert error.value.code() == grpc.StatusCode.UNIMPLEMENTED
    with pytest.raises(grpc.RpcError) as error:
        hosted.health.Check(health_pb2.HealthCheckRequest(service=SIM_SERVICE), timeout=5)
    assert error.value.code() == grpc.StatusCode.NOT_FOUND


def test_hosted_ignores_seeds(hosted: RawStubs) -> None:
    first, second = (hosted.open_session(seed=3) for _ in range(2))
    frames = [sdk_decode(hosted.infer(s, 0)[0].streams[1].frames)[-1] for s in (first, second)]
    assert (frames[0] != frames[1]).any()


def test_hosted_keeps_the_error_codes_and_the_pinning_header(hosted: RawStubs) -> None:
    response, _ = hosted.initialize("not-a-key")
    assert response.error.code == common_pb2.ERROR_CODE_INVALID_API_KEY
    response, _ = hosted.initialize(formats=(common_pb2.FRAME_FORMAT_H264,))
    assert response.error.code == common_pb2.ERROR_CODE_INVALID_FORMAT
    session = hosted.open_session(prompt=None)
    assert dict(session.metadata)["x-session-target"]
    answer, _ = hosted.infer(session, 0)
    assert answer.error.code == common_pb2.ERROR_CODE_PROMPT_SET
