"""What an endpoint sends beyond frames: found at its first Infer, not configured.

The embedded server sends its simulator's ground truth with every Infer (and, on request, its
expert's next chunk; its ``SimService`` answers depth and scenes). The hosted service, and the
embedded server in its hosted-like mode (``env.server.hosted=true``), send frames alone. The
features that need ground truth (the ground-truth reward, the privileged critic and auxiliary
head, distance and collision metrics, the autopilot and its labels) have automatic defaults
resolved here: on where the endpoint sends ground truth, the frames-only defaults elsewhere, and
one log line per endpoint says which. Asking for one of them explicitly on a frames-only
endpoint is a one-line error naming the endpoint and the alternative (:meth:`Capabilities.require`).

An ``endpoint: local`` env is known without asking (its ``server.hosted`` says); any other
endpoint is probed once per process: one session, one Prompt, one Infer standing still.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

from omegaconf import DictConfig

from oasis_torchrl.client import A2VClient, DecartRoboticsError
from oasis_torchrl.config.env import LOCAL, EnvConfig
from oasis_torchrl.protocol import CHUNK

logger = logging.getLogger(__name__)

Settings = EnvConfig | DictConfig
PROBE_PROMPT = "urban"
PROBE_FRAME_SIZE = (32, 48)
"""Frames of the probe's single Infer are decoded this small: only its metadata matters."""

_probed: dict[tuple[str, bool], Capabilities] = {}
"""The capabilities of each endpoint (its address, and whether it is the hosted-like embedded
server), probed once per process."""
_lock = threading.Lock()


@dataclass(frozen=True)
class Capabilities:
    """What an endpoint sends: frames always, ground truth (and what comes with it) or not.

    Example:
        >>> frames = Capabilities("http://127.0.0.1:1", ground_truth=False)
        >>> frames.summary()  # doctest: +ELLIPSIS
        'http://127.0.0.1:1 sends frames only: the motion reward, ...'
        >>> frames.require("the autopilot", "pass a person or a policy")
        Traceback (most recent call last):
        ...
        ValueError: the autopilot needs ground truth, which http://127.0.0.1:1 does not send \
(frames only): pass a person or a policy
    """

    endpoint: str
    ground_truth: bool

    @property
    def frames_only(self) -> bool:
        """Whether the endpoint sends frames and nothing else (the hosted service does)."""
        return not self.ground_truth

    def require(self, feature: str, alternative: str) -> None:
        """Raise a one-line ValueError if ``feature`` needs what this endpoint does not send."""
        if self.frames_only:
            raise ValueError(
                f"{feature} needs ground truth, which {self.endpoint} does not send (frames "
                f"only): {alternative}"
            )

    def summary(self) -> str:
        """One line: what the endpoint sends and the defaults that follow."""
        if self.ground_truth:
            return (
                f"{self.endpoint} sends ground truth: the ground-truth reward, the privileged "
                "critic and auxiliary head, distance and collision metrics and the autopilot are on"
            )
        return (
            f"{self.endpoint} sends frames only: the motion reward, a camera-only "
            "critic, metrics from frames, demonstrations from a person, recordings or a policy"
        )


def endpoint_name(cfg: Settings) -> str:
    """How logs and errors name the endpoint of an ``env`` section.

    Example:
        >>> endpoint_name(EnvConfig(server=EnvConfig().server.__class__(hosted=True)))
        'the hosted-like embedded server'
    """
    if cfg.endpoint != LOCAL:
        return str(cfg.endpoint)
    return "the hosted-like embedded server" if cfg.server.hosted else "the embedded server"


def env_capabilities(cfg: Settings) -> Capabilities:
    """The capabilities of an ``env`` section's endpoint (probed once per process), logged once.

    Example:
        >>> env_capabilities(EnvConfig()).ground_truth
        True
    """
    local = cfg.endpoint == LOCAL
    key = (str(cfg.endpoint), bool(cfg.server.hosted) if local else False)
    with _lock:
        if key not in _probed:
            name = endpoint_name(cfg)
            capabilities = (
                Capabilities(name, ground_truth=not key[1]) if local else probe(str(cfg.endpoint))
            )
            logger.info(capabilities.summary())
            _probed[key] = capabilities
        return _probed[key]


def probe(endpoint: str, *, api_key: str | None = None, timeout: float = 60.0) -> Capabilities:
    """Ask ``endpoint`` what it sends: one session, Prompt, one Infer standing still, Finish.

    ``api_key`` defaults to ``DECART_API_KEY``, as every client of the endpoint does; an
    endpoint that cannot be asked is a one-line ValueError.
    """
    try:
        with A2VClient(
            endpoint, api_key=api_key, timeout=timeout, resize=PROBE_FRAME_SIZE
        ) as client:
            client.prompt(PROBE_PROMPT)
            client.infer([[0.0, 0.0]] * CHUNK)
            return Capabilities(endpoint, ground_truth=client.last_truth is not None)
    except DecartRoboticsError as error:
        raise ValueError(f"cannot ask {endpoint} what it sends: {error}") from error


FRAMES_ONLY_REWARD = "motion"
"""The reward ``env.reward.kind=auto`` picks where the endpoint sends frames alone."""


def resolve_reward_kind(kind: str, capabilities: Capabilities) -> str:
    """``env.reward.kind`` resolved: ``auto`` becomes ground_truth where the endpoint sends it,
    else motion (the frames-only reward); ground_truth on a frames-only endpoint is an error.

    Example:
        >>> resolve_reward_kind("auto", Capabilities("x", ground_truth=False))
        'motion'
    """
    if kind == "auto":
        return "ground_truth" if capabilities.ground_truth else FRAMES_ONLY_REWARD
    if kind == "ground_truth":
        capabilities.require(
            "env.reward.kind=ground_truth",
            "use env.reward.kind=motion (the frames-only reward) or auto",
        )
    return kind
