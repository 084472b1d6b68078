"""The LeRobot feature schema of oasis datasets, and validation with errors that say what is wrong.

Every dataset this package writes (rollouts, expert drives, human recordings) uses LeRobot's own
key names (``lerobot.utils.constants``):

=================================  ==========  =============  =====================================
key                                dtype       shape          meaning
=================================  ==========  =============  =====================================
``observation.images.<camera>``    video       ``(H, W, 3)``  one camera frame (uint8 RGB when
                                                              written), cameras ``left_forward``,
                                                              ``front``, ``right_forward``
``observation.state``              float32     ``(2,)``       the action applied before this frame
``action``                         float32     ``(2,)`` or    the action(s) applied next:
                                               ``(8,)``       ``[throttle, steering]``, or a whole
                                                              chunk ``[t0, s0, t1, s1, ..., s3]``
                                                              when one row stands for one chunk
``next.reward``                    float32     ``(1,)``       reward of this row's action (rollouts)
``next.done``                      bool        ``(1,)``       the episode ends after this row
``episode_seed``                   int64       ``(1,)``       world seed (rollouts): with the task
                                                              it rebuilds the scene
``privileged_state``               float32     ``(10,)``      on request, the simulator's state of
                                                              this frame (``PRIVILEGED_FIELDS``:
                                                              speed, offsets, lanes, obstacle
                                                              distances in the path and in the
                                                              lanes; scaled): an auxiliary
                                                              target, no policy input
``intervention``                   bool        ``(1,)``       on request, a person drove this row
                                                              over a policy (LeRobot's DAgger
                                                              convention, ``lerobot-rollout``)
``next.crash``                     bool        ``(1,)``       on request, the car crashed by this
                                                              row (last row of its chunk): a
                                                              person's mark on the drive page, or
                                                              the world's collision where the
                                                              endpoint sends ground truth
``task``                           string                     the episode's prompt
=================================  ==========  =============  =====================================

State and action components are named ``throttle.vel`` and ``steering.vel`` (chunk rows:
``throttle_0.vel``, ``steering_0.vel``, ...): LeRobot's ``<name>.vel`` convention for velocity-like
commands (its mobile bases use ``x.vel`` / ``theta.vel``), which ``lerobot-rollout`` needs to route
a feature to a policy. The oasis robot (``lerobot_robot_oasis``) and its teleoperators use the same
names, so a person's recordings and the project's own datasets share their features.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from lerobot.utils.constants import (
    ACTION,
    DEFAULT_FEATURES,
    DONE,
    OBS_IMAGES,
    OBS_STATE,
    REWARD,
)

from oasis_torchrl.models.privileged import PRIVILEGED_FIELDS, PRIVILEGED_KEY
from oasis_torchrl.protocol import ACTION_NAMES as WIRE_NAMES
from oasis_torchrl.protocol import CHUNK

SEED_KEY = "episode_seed"
INTERVENTION_KEY = "intervention"
CRASH_KEY = "next.crash"
"""Rows by which the car crashed: named like ``next.done`` and ``next.success`` (an outcome of
the row's action); the frames-only reward's heads fine-tune on it
(:mod:`oasis_torchrl.train.motion_dataset`)."""
"""Rows a person drove while a policy was in charge: the name and type ``lerobot-rollout``'s
DAgger strategy gives its corrections."""
VELOCITY_SUFFIX = ".vel"
ACTION_NAMES = tuple(f"{name}{VELOCITY_SUFFIX}" for name in WIRE_NAMES)
"""Dataset names of ``[throttle, steering]`` (state and action)."""
IMAGE_NAMES = ("height", "width", "channels")
IMAGE_PREFIX = f"{OBS_IMAGES}."
"""What every camera's dataset key starts with."""

Feature = dict[str, Any]


def image_key(camera: str) -> str:
    """The dataset key of ``camera``'s frames.

    Example:
        >>> image_key("front")
        'observation.images.front'
    """
    return f"{IMAGE_PREFIX}{camera}"


@dataclass(frozen=True)
class DatasetLayout:
    """What fixes a dataset's features: cameras, stored frame size and actions per row.

    Args:
        cameras: camera names, in order.
        image_size: stored ``(height, width)``; both even (the video is 4:2:0).
        actions_per_row: 1 (one ``[throttle, steering]`` per row) or 4 (one row per chunk,
            the chunk flattened).
        with_reward: include ``next.reward`` (rollouts have one; human recordings do not).
        with_seed: include ``episode_seed``.
        with_privileged: include ``privileged_state`` (needs the embedded server's ground
            truth; :mod:`oasis_torchrl.models.privileged`).
        with_intervention: include ``intervention`` (a person took over from a policy).
        with_crash: include ``next.crash`` (crash marks).

    Example:
        >>> layout = DatasetLayout(("front",), (48, 64), actions_per_row=1)
        >>> sorted(build_features(layout))  # doctest: +NORMALIZE_WHITESPACE
        ['action', 'episode_seed', 'next.done', 'next.reward', 'observation.images.front',
         'observation.state']
    """

    cameras: tuple[str, ...]
    image_size: tuple[int, int]
    actions_per_row: int = 1
    with_reward: bool = True
    with_seed: bool = True
    with_privileged: bool = False
    with_intervention: bool = False
    with_crash: bool = False

    def __post_init__(self) -> None:
        if not self.cameras:
            raise ValueError("a dataset needs at least one camera")
        height, width = self.image_size
        if height <= 0 or width <= 0 or height % 2 or width % 2:
            raise ValueError(
                f"image_size must be positive and even (4:2:0 video), got {height}x{width} "
                "(height x width); pass an even image size to store reduced frames"
            )
        if self.actions_per_row not in (1, CHUNK):
            raise ValueError(f"actions_per_row must be 1 or {CHUNK}, got {self.actions_per_row}")

    @property
    def action_dim(self) -> int:
        """Length of the ``action`` vector."""
        return self.actions_per_row * len(ACTION_NAMES)


def _action_names(actions_per_row: int) -> list[str]:
    if actions_per_row == 1:
        return list(ACTION_NAMES)
    return [f"{name}_{k}{VELOCITY_SUFFIX}" for k in range(actions_per_row) for name in WIRE_NAMES]


def build_features(layout: DatasetLayout) -> dict[str, Feature]:
    """The LeRobot ``features`` dict of ``layout`` (to pass to ``LeRobotDataset.create``).

    Example:
        >>> features = build_features(DatasetLayout(("front",), (48, 64), actions_per_row=4))
        >>> features["action"]["shape"], features["action"]["names"][:3]
        ((8,), ['throttle_0.vel', 'steering_0.vel', 'throttle_1.vel'])
    """
    height, width = layout.image_size
    features: dict[str, Feature] = {
        image_key(camera): {"dtype": "video", "shape": (height, width, 3), "names": IMAGE_NAMES}
        for camera in layout.cameras
    }
    features[OBS_STATE] = {"dtype": "float32", "shape": (2,), "names": list(ACTION_NAMES)}
    features[ACTION] = {
        "dtype": "float32",
        "shape": (layout.action_dim,),
        "names": _action_names(layout.actions_per_row),
    }
    if layout.with_reward:
        features[REWARD] = {"dtype": "float32", "shape": (1,), "names": None}
    features[DONE] = {"dtype": "bool", "shape": (1,), "names": None}
    if layout.with_seed:
        features[SEED_KEY] = {"dtype": "int64", "shape": (1,), "names": None}
    if layout.with_privileged:
        features[PRIVILEGED_KEY] = {
            "dtype": "float32",
            "shape": (len(PRIVILEGED_FIELDS),),
            "names": list(PRIVILEGED_FIELDS),
        }
    if layout.with_intervention:
        features[INTERVENTION_KEY] = {"dtype": "bool", "shape": (1,), "names": None}
    if layout.with_crash:
        features[CRASH_KEY] = {"dtype": "bool", "shape": (1,), "names": None}
    return features


def numpy_dtype(feature: Feature) -> np.dtype:
    """The numpy dtype values of ``feature`` must have (uint8 for images and videos).

    Example:
        >>> numpy_dtype({"dtype": "video", "shape": (4, 4, 3)})
        dtype('uint8')
    """
    kind = feature["dtype"]
    return np.dtype(np.uint8) if kind in ("image", "video") else np.dtype(kind)


def check_column(key: str, values: np.ndarray, feature: Feature, leading: int) -> None:
    """Check that ``values`` holds rows of ``feature`` after ``leading`` batch dimensions.

    Raises:
        TypeError: wrong dtype, naming the key, the expected and the actual dtype and shape.
        ValueError: wrong shape, same details.

    Example:
        >>> check_column("action", np.zeros((5, 3), np.float32),
        ...              {"dtype": "float32", "shape": (2,)}, leading=1)
        Traceback (most recent call last):
        ...
        ValueError: action: expected float32 rows of shape (2,), got float32 of shape (5, 3)
    """
    expected_dtype = numpy_dtype(feature)
    expected_shape = tuple(feature["shape"])
    actual_shape = tuple(values.shape)
    message = (
        f"{key}: expected {expected_dtype} rows of shape {expected_shape}, "
        f"got {values.dtype} of shape {actual_shape}"
    )
    if values.dtype != expected_dtype:
        raise TypeError(message)
    if len(actual_shape) != leading + len(expected_shape) or actual_shape[leading:] != (
        expected_shape
    ):
        raise ValueError(message)


def check_columns(
    columns: Mapping[str, np.ndarray], features: Mapping[str, Feature], leading: int
) -> None:
    """Check every column of a row batch against ``features``: same keys, dtypes and shapes.

    Example:
        >>> check_columns({"x": np.zeros((3, 1), np.int64)}, {"y": {"dtype": "int64",
        ...               "shape": (1,)}}, leading=1)
        Traceback (most recent call last):
        ...
        ValueError: rows do not match the dataset features: missing ['y'], unexpected ['x']
    """
    missing = sorted(set(features) - set(columns))
    extra = sorted(set(columns) - set(features))
    if missing or extra:
        raise ValueError(
            f"rows do not match the dataset features: missing {missing}, unexpected {extra}"
        )
    for key, feature in features.items():
        check_column(key, columns[key], feature, leading)


def user_features(features: Mapping[str, Feature]) -> dict[str, Feature]:
    """``features`` without LeRobot's bookkeeping columns (index, timestamp, ...).

    Example:
        >>> sorted(user_features({"action": {}, "frame_index": {}, "timestamp": {}}))
        ['action']
    """
    return {key: value for key, value in features.items() if key not in DEFAULT_FEATURES}


def check_same_features(expected: Mapping[str, Feature], actual: Mapping[str, Feature]) -> None:
    """Check that an existing dataset's features are the ones about to be written.

    Raises:
        ValueError: naming the first differing key with both dtypes and shapes.

    Example:
        >>> check_same_features({"action": {"dtype": "float32", "shape": (2,)}},
        ...                     {"action": {"dtype": "float32", "shape": [8]}})
        Traceback (most recent call last):
        ...
        ValueError: action: the dataset stores float32 (8,), the new rows are float32 (2,)
    """
    actual = user_features(actual)
    missing = sorted(set(expected) - set(actual))
    extra = sorted(set(actual) - set(expected))
    if missing or extra:
        raise ValueError(f"the dataset's features differ: it lacks {missing} and has extra {extra}")
    for key, feature in expected.items():
        old = actual[key]
        new_spec = (feature["dtype"], tuple(feature["shape"]))
        old_spec = (old["dtype"], tuple(old["shape"]))
        if new_spec != old_spec:
            raise ValueError(
                f"{key}: the dataset stores {old_spec[0]} {old_spec[1]}, "
                f"the new rows are {new_spec[0]} {new_spec[1]}"
            )
