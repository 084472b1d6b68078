"""What the embedded simulator tells beyond A2V: ground truth, its expert's actions, depth.

The hosted service sends none of it; every helper degrades clearly: ground truth is None when
the server sends none, and a missing ``SimService`` raises :class:`UnsupportedFeatureError`.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NoReturn

import grpc
import numpy as np

from oasis_torchrl.client.errors import TransportError, UnsupportedFeatureError
from oasis_torchrl.proto import sim_pb2
from oasis_torchrl.protocol import ACTION_DIM, CHUNK, SIM_SERVICE, TRUTH_METADATA

TRUTH_FIELDS: tuple[str, ...] = tuple(
    field.name for field in sorted(sim_pb2.FrameTruth.DESCRIPTOR.fields, key=lambda f: f.number)
)
"""FrameTruth field names, in the order of the last axis of ``PoolStep.truth``."""


def parse_truth(
    trailing_metadata: Iterable[tuple[str, str | bytes]] | None,
) -> sim_pb2.InferTruth | None:
    """The InferTruth in an Infer's trailing metadata, or None if the server sent none.

    >>> truth = sim_pb2.InferTruth(sequence_num=3)
    >>> parse_truth([(TRUTH_METADATA, truth.SerializeToString())]).sequence_num
    3
    >>> parse_truth([]) is None
    True
    """
    for key, value in trailing_metadata or ():
        if key == TRUTH_METADATA:
            return sim_pb2.InferTruth.FromString(value)
    return None


def truth_array(truth: sim_pb2.InferTruth) -> np.ndarray:
    """float64 ``[frames, len(TRUTH_FIELDS)]`` of one InferTruth (booleans as 0/1).

    >>> truth = sim_pb2.InferTruth(frames=[sim_pb2.FrameTruth(x=1.5, collided=True)])
    >>> row = truth_array(truth)[0]
    >>> row[[TRUTH_FIELDS.index("x"), TRUTH_FIELDS.index("collided")]].tolist()
    [1.5, 1.0]
    """
    return np.array(
        [[getattr(frame, name) for name in TRUTH_FIELDS] for frame in truth.frames],
        dtype=np.float64,
    ).reshape(len(truth.frames), len(TRUTH_FIELDS))


def expert_chunk(truth: sim_pb2.InferTruth | None) -> np.ndarray:
    """The expert's next chunk in an InferTruth, float32 ``[4, 2]``; NaN when it has none.

    >>> truth = sim_pb2.InferTruth(expert_actions=[0.5, -0.1] * 4)
    >>> expert_chunk(truth)[0].tolist(), bool(np.isnan(expert_chunk(None)).all())
    ([0.5, -0.10000000149011612], True)
    """
    actions = () if truth is None else truth.expert_actions
    if len(actions) != CHUNK * ACTION_DIM:
        return np.full((CHUNK, ACTION_DIM), np.nan, np.float32)
    return np.array(actions, np.float32).reshape(CHUNK, ACTION_DIM)


def depth_maps(response: sim_pb2.DepthResponse) -> dict[str, np.ndarray]:
    """Stream name -> float32 ``[H, W]`` metric depth from a DepthResponse (sky is +inf).

    >>> import numpy as np
    >>> raw = np.full((2, 3), 4.0, "<f2").tobytes()
    >>> response = sim_pb2.DepthResponse(maps=[sim_pb2.DepthMap(
    ...     name="front", height=2, width=3, depth_f16=raw)])
    >>> depth_maps(response)["front"].dtype.name
    'float32'
    """
    return {
        depth.name: np.frombuffer(depth.depth_f16, dtype="<f2")
        .reshape(depth.height, depth.width)
        .astype(np.float32)
        for depth in response.maps
    }


def raise_sim_error(error: TransportError, feature: str) -> NoReturn:
    """Re-raise a failed ``SimService`` call (``feature`` names what it was for), as
    UnsupportedFeatureError if the server has no SimService.

    >>> error = TransportError(grpc.StatusCode.UNIMPLEMENTED, "", method="GetDepth")
    >>> raise_sim_error(error, "depth")
    Traceback (most recent call last):
    ...
    oasis_torchrl.client.errors.UnsupportedFeatureError: depth needs oasis_torchrl.sim.v1...
    """
    if error.code() == grpc.StatusCode.UNIMPLEMENTED:
        raise UnsupportedFeatureError(
            f"{feature} needs {SIM_SERVICE}, which only the embedded oasis-torchrl simulator "
            "implements; this server does not"
        ) from error
    raise error
