"""A2V clients: a drop-in replacement for ``decart_oasis`` and a concurrent session pool.

- :class:`A2VClient`: one blocking session, same API as ``decart_oasis.A2VClient`` (plus
  retries, JPEG, decode-time resize, seeds, ping, ground truth and depth).
- :class:`SessionPool`: N sessions stepped concurrently over one channel, with per-row
  recovery; what the TorchRL env stands on.
- :class:`SceneSource`: scene layouts by prompt and seed (``SimService/GetScene``), for
  top-down views.

>>> from oasis_torchrl.client import A2VClient, SessionPool, RetryPolicy
>>> RetryPolicy().max_attempts
5
"""

from oasis_torchrl.client.channel import parse_endpoint
from oasis_torchrl.client.decoding import FrameDecoder, JpegDecoder, Vp9Decoder, make_decoder
from oasis_torchrl.client.errors import (
    A2VError,
    DecartRoboticsError,
    DecodeError,
    ErrorCode,
    PermanentA2VError,
    SequenceError,
    SessionLostError,
    TransportError,
    UnsupportedFeatureError,
)
from oasis_torchrl.client.ground_truth import TRUTH_FIELDS
from oasis_torchrl.client.pool import SessionPool
from oasis_torchrl.client.retry import RetryPolicy
from oasis_torchrl.client.scenes import SceneLookup, SceneSource
from oasis_torchrl.client.sync_client import DEFAULT_SDK_VERSION, A2VClient
from oasis_torchrl.client.types import (
    JPEG,
    VP9,
    A2VResult,
    FrameConsumer,
    PoolStep,
    SessionStatus,
    StreamInfo,
)
from oasis_torchrl.protocol import API_KEY_ENV_VAR as DEFAULT_API_KEY_ENV_VAR
from oasis_torchrl.protocol import CAMERAS as DEFAULT_REQUIRED_STREAMS
from oasis_torchrl.protocol import DEFAULT_ENDPOINT, FrameFormat
from oasis_torchrl.protocol import ENDPOINT_ENV_VAR as DEFAULT_ENDPOINT_ENV_VAR

__all__ = [
    "DEFAULT_API_KEY_ENV_VAR",
    "DEFAULT_ENDPOINT",
    "DEFAULT_ENDPOINT_ENV_VAR",
    "DEFAULT_REQUIRED_STREAMS",
    "DEFAULT_SDK_VERSION",
    "JPEG",
    "TRUTH_FIELDS",
    "VP9",
    "A2VClient",
    "A2VError",
    "A2VResult",
    "DecartRoboticsError",
    "DecodeError",
    "ErrorCode",
    "FrameConsumer",
    "FrameDecoder",
    "FrameFormat",
    "JpegDecoder",
    "PermanentA2VError",
    "PoolStep",
    "RetryPolicy",
    "SceneLookup",
    "SceneSource",
    "SequenceError",
    "SessionLostError",
    "SessionPool",
    "SessionStatus",
    "StreamInfo",
    "TransportError",
    "UnsupportedFeatureError",
    "Vp9Decoder",
    "make_decoder",
    "parse_endpoint",
]
