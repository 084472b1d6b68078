"""The A2V protocol's constants, defined once: every other module imports them from here.

What the hosted Oasis service and the official ``decart-oasis`` SDK agree on (chunk length,
camera names, metadata keys, environment variables, the default endpoint, the frame rate the
SDK's preview assumes), plus this project's own extensions of it (the embedded server's seed and
ground-truth metadata, its API-key variable). The wire protocol itself is described in
``docs/PROTOCOL.md``; the message definitions are the generated modules in
:mod:`oasis_torchrl.proto`.

Example:
    >>> from oasis_torchrl import protocol
    >>> protocol.CHUNK, protocol.CAMERAS[1], protocol.FrameFormat.VP9.value
    (4, 'front', 3)
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

CHUNK = 4
"""Actions per Infer call, and frames per camera in its answer (frame k follows action k)."""

ACTION_DIM = 2
"""``[throttle, steering]``: throttle + is forward; steering - is left, + is right."""

ACTION_NAMES: tuple[str, ...] = ("throttle", "steering")
"""The action's components, in wire order."""

FRONT = "front"
"""The forward-facing stream."""

CAMERAS: tuple[str, ...] = ("left_forward", FRONT, "right_forward")
"""The streams the hosted model advertises, left to right."""

FRONT_CROP = "front_crop"
"""A camera the client derives, not a stream: the centre of the ``front`` stream, cut from its
full-size frame and resized to the other cameras' size (``env.front_crop``), a narrow forward
camera for what is far ahead."""

POLICY_CAMERAS: tuple[str, ...] = (*CAMERAS, FRONT_CROP)
"""Every camera an env, a dataset or a policy may carry, in their conventional order."""


def with_front_crop(streams: Sequence[str], front_crop: float | None) -> tuple[str, ...]:
    """The cameras of ``streams`` plus, when ``front_crop`` is set, the crop derived from them.

    Example:
        >>> with_front_crop(CAMERAS, 0.25)[-1], with_front_crop(CAMERAS, None) == CAMERAS
        ('front_crop', True)
    """
    return (*streams, FRONT_CROP) if front_crop is not None else tuple(streams)


HOSTED_FRAME_SIZE = (512, 768)
"""``(height, width)`` of the hosted model's frames (it advertises 768 wide, 512 high)."""

FPS = 20.0
"""Frames per second: the protocol has no field for it; the SDK's live preview treats 20 as
real speed (one Infer = 0.2 s of world time)."""

DEFAULT_ENDPOINT = "https://oasis-grpc.decart.ai"
API_KEY_ENV_VAR = "DECART_API_KEY"
ENDPOINT_ENV_VAR = "DECART_ROBOTICS_ENDPOINT"
DEFAULT_TIMEOUT_S = 120.0
"""The SDK's per-RPC deadline."""

API_KEY_METADATA = "x-api-key"
"""Sent on every call (besides ``InitializeRequest.api_key``)."""
SESSION_TARGET_METADATA = "x-session-target"
"""Initial metadata of an Initialize answer; replayed on every later call of that session."""

# -- this project's extensions (the hosted service ignores or never sends them) ----------------

SEED_METADATA = "x-oasis-seed"
"""Decimal seed of a Prompt call's scene on the embedded server (no seed means seed 0)."""
TRUTH_METADATA = "x-oasis-truth-bin"
"""Binary trailing metadata of an Infer answer: ``oasis_torchrl.sim.v1.InferTruth``."""
EXPERT_METADATA = "x-oasis-expert"
"""Prompt metadata: ``on`` runs the embedded server's expert (its privileged autopilot) beside the
rollout that Prompt starts, and every Infer's ground truth then carries the expert's next chunk
(``expert_actions``); without it the server spends nothing on the expert and sends none."""
EXPERT_ON = "on"
"""The value of :data:`EXPERT_METADATA` asking for the expert."""
FRAMES_METADATA = "x-oasis-frames"
"""Initialize metadata: ``last`` asks for only the last frame of each chunk (a client that looks
at nothing else). The embedded server grants it for raw frames, which stand alone (a codec's
stream needs every frame), by sending it back in Initialize's initial metadata; every Infer of
the session then carries one frame per stream (its ground truth still covers all 4)."""
LAST_FRAME_ONLY = "last"
"""The value of :data:`FRAMES_METADATA` asking for, and granting, the last frame alone."""
MAX_SEED = 2**64 - 1
SERVER_API_KEYS_ENV_VAR = "OASIS_SERVER_API_KEYS"
"""Comma-separated API keys the embedded server accepts."""
SIM_SERVICE = "oasis_torchrl.sim.v1.SimService"
"""The embedded server's local-only side channel (depth maps, scene layout)."""

# -- the policy service: a trained policy served over the network (oasis_torchrl.policy.v1) ----

POLICY_SERVICE = "oasis_torchrl.policy.v1.PolicyService"
POLICY_SCHEMES: dict[str, bool] = {"grpc://": False, "grpcs://": True}
"""URL prefixes naming a policy server (``grpc://host:port``), and whether each uses TLS."""
POLICY_API_KEY_ENV_VAR = "OASIS_POLICY_API_KEY"
"""The key a policy client sends when it is given none."""
POLICY_SERVER_API_KEYS_ENV_VAR = "OASIS_POLICY_SERVER_API_KEYS"
"""Comma-separated API keys the policy server accepts."""


class FrameFormat(enum.IntEnum):
    """``decart.inference.common.FrameFormat`` as a Python enum (same values), plus this
    project's ``RAW_RGB24``.

    >>> FrameFormat.VP9.value
    3
    """

    UNSPECIFIED = 0
    JPEG = 1
    H264 = 2
    VP9 = 3
    VP8 = 4
    RAW_YUV420 = 5
    RAW_RGB24 = 100
    """Uncompressed RGB frames (3 bytes a pixel, row-major): this project's extension, which
    its client offers only to a server on the same machine (frames that never leave the machine
    need no codec). A value outside decart's enum, never offered to another server."""


FORMAT_NAMES: dict[str, FrameFormat] = {
    "raw": FrameFormat.RAW_RGB24,
    "vp9": FrameFormat.VP9,
    "jpeg": FrameFormat.JPEG,
}
"""Short names of the formats this project's server and client handle (flags and options)."""
