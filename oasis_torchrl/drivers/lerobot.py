"""Any LeRobot policy folder as a :class:`~oasis_torchrl.drivers.Driver`: ``act``, ``diffusion``,
``smolvla``, ..., plugin policies included, with the pre- and post-processors saved beside it.

The four-action bridge. A LeRobot policy acts once per frame (``select_action``, 20 times a
second); the world model takes a chunk of 4 actions per call and answers with their 4 frames.
Each env step, the driver asks the policy 4 times, exactly as LeRobot's own loop asks it on the
``oasis`` env and robot (``lerobot_env_oasis``, ``lerobot_robot_oasis``): every ask sees the
newest frames the world has produced (the last frame of the previous chunk) and, as
``observation.state``, the action decided just before (for the first ask, the previous chunk's
last action; zeros after a reset). So ``oasis-torchrl eval`` and ``lerobot-eval
--env.type=oasis`` drive a policy through the same observations and give the same numbers.

A chunking policy (ACT, diffusion, the ``oasis`` plugin) plans only when its action queue runs
out. With ``n_action_steps`` a multiple of 4 every plan starts on a chunk boundary, where the
frame and the state are exactly those of a dataset row (the frame right before the row's action,
the action before it); the asks in between only pop the queue.

LeRobot policies keep their queues for the whole batch, so when any row starts an episode the
policy is reset and every row plans afresh.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import NonTensorData, TensorDictBase

from oasis_torchrl.data.features import image_key
from oasis_torchrl.data.images import resize_frames
from oasis_torchrl.drivers.base import Driver
from oasis_torchrl.protocol import ACTION_DIM, CAMERAS, CHUNK, FRONT_CROP, POLICY_CAMERAS

logger = logging.getLogger(__name__)

CONFIG_FILE = "config.json"
STEP_COUNT = "step_count"


def policy_type(folder: str | Path) -> str:
    """The policy type a LeRobot policy folder declares in its ``config.json``.

    Raises:
        FileNotFoundError: the folder has no ``config.json``.
        ValueError: the file names no ``type``.

    Example:
        >>> import tempfile
        >>> folder = Path(tempfile.mkdtemp())
        >>> _ = (folder / "config.json").write_text('{"type": "act"}')
        >>> policy_type(folder)
        'act'
    """
    config = Path(folder) / CONFIG_FILE
    if not config.is_file():
        raise FileNotFoundError(
            f"{folder} is not a LeRobot policy folder: it has no {CONFIG_FILE} (pass the "
            "pretrained_model folder, e.g. <run>/checkpoints/last/pretrained_model)"
        )
    kind = json.loads(config.read_text()).get("type")
    if not isinstance(kind, str) or not kind:
        raise ValueError(f"{config} names no policy type")
    return kind


def _device(requested: str | None, saved: str | None) -> str:
    """The device to run on: the requested one, else the saved one if present here, else CPU."""
    if requested:
        return requested
    if saved and saved.startswith("cuda") and torch.cuda.is_available():
        return saved
    return "cpu"


def _as_list(value: Any, rows: int) -> list[str]:
    if isinstance(value, NonTensorData):
        value = value.data
    if value is None:
        return [""] * rows
    if isinstance(value, str):
        return [value] * rows
    return [str(item) for item in value.tolist()]


class LeRobotDriver(Driver):
    """Drives with a LeRobot policy, 4 ``select_action`` calls per world-model call.

    Args:
        policy: the policy (``PreTrainedPolicy``), in eval mode.
        preprocessor: its input processor pipeline (normalisation, device, ...).
        postprocessor: its output processor pipeline (unnormalisation, ...).
        chunk_actions: see :class:`~oasis_torchrl.drivers.Driver`.

    Example:
        >>> import tempfile
        >>> from oasis_torchrl.models import DrivingNet
        >>> from oasis_torchrl.drivers.folders import export_lerobot
        >>> folder = export_lerobot(DrivingNet(), Path(tempfile.mkdtemp()) / "policy")
        >>> driver = LeRobotDriver.load(folder)  # any LeRobot policy folder, e.g. an ACT one
        >>> pixels = {camera: np.zeros((2, 64, 96, 3), np.uint8) for camera in CAMERAS}
        >>> driver.image_size, driver.act(pixels, torch.zeros(2, 2), ["urban"] * 2).shape
        ((64, 96), torch.Size([2, 2]))
    """

    def __init__(
        self,
        policy: Any,
        preprocessor: Any,
        postprocessor: Any,
        *,
        chunk_actions: bool = True,
    ) -> None:
        super().__init__(chunk_actions=chunk_actions)
        self.policy = policy.eval()
        self.preprocessor = preprocessor
        self.postprocessor = postprocessor
        self.image_size = _image_size(policy.config)
        self.cameras = _cameras(policy.config)
        self.front_crop = getattr(policy.config, "front_crop", None)
        self._episodes: torch.Tensor | None = None

    @classmethod
    def load(
        cls, folder: str | Path, *, device: str | None = None, chunk_actions: bool = True
    ) -> LeRobotDriver:
        """Load the policy and its saved processors from a LeRobot policy folder.

        Plugin policy types (installed ``lerobot_policy_*`` distributions) are registered first,
        as LeRobot's command-line tools do.
        """
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors
        from lerobot.utils.import_utils import register_third_party_plugins

        folder = Path(folder)
        kind = policy_type(folder)
        register_third_party_plugins()
        config = PreTrainedConfig.from_pretrained(str(folder))
        config.device = _device(device, config.device)
        policy_class = get_policy_class(kind)
        # LeRobot prints a progress line; stdout may carry a command's JSON result.
        with contextlib.redirect_stdout(io.StringIO()):
            policy = policy_class.from_pretrained(str(folder), config=config)
        preprocessor, postprocessor = make_pre_post_processors(
            config,
            pretrained_path=str(folder),
            preprocessor_overrides={"device_processor": {"device": config.device}},
        )
        logger.info("loaded LeRobot %s policy from %s on %s", kind, folder, config.device)
        return cls(policy, preprocessor, postprocessor, chunk_actions=chunk_actions)

    def reset(self) -> None:
        """Forget queued actions and past observations (the next ask plans afresh)."""
        self.policy.reset()
        self.preprocessor.reset()
        self.postprocessor.reset()

    @torch.no_grad()
    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """Four ``select_action`` asks per row, as the per-frame LeRobot env would make them."""
        rows = td.batch_size[0]
        if self._starts_episode(td):
            self.reset()
        pixels = self._newest_frames(td)
        task = _as_list(td.get("prompt", None), rows)
        state = td.get("state").to("cpu", torch.float32)
        actions = []
        for _ in range(CHUNK):
            state = self.act(pixels, state, task)
            actions.append(state)
        return torch.stack(actions, dim=1)

    def act(
        self, pixels: dict[str, np.ndarray], state: torch.Tensor, task: list[str]
    ) -> torch.Tensor:
        """One ``select_action`` on one frame tick's observation, LeRobot's gym format
        (``pixels`` uint8 ``[N, H, W, 3]`` per camera, ``agent_pos`` ``[N, 2]``): the action
        ``[N, 2]`` in the action box, as the world applies it."""
        from lerobot.envs.utils import preprocess_observation

        observation = preprocess_observation({"pixels": pixels, "agent_pos": state.numpy()})
        observation["task"] = task
        action = self.postprocessor(self.policy.select_action(self.preprocessor(observation)))
        action = action.to("cpu", torch.float32).reshape(state.shape[0], -1)
        if action.shape[1] != ACTION_DIM:
            raise ValueError(
                f"the policy acts with {action.shape[1]} numbers per frame; the world model "
                f"takes {ACTION_DIM} (throttle, steering): train it on one-action-per-frame rows"
            )
        if torch.isnan(action).any():
            raise ValueError("the policy returned NaN actions")
        return action.clamp(-1.0, 1.0)

    def _starts_episode(self, td: TensorDictBase) -> bool:
        """Whether any row starts an episode: its step counter is 0 (the env factory's
        ``StepCounter``) or, without one, its episode seed changed; or the batch changed."""
        counter = td.get(STEP_COUNT, None)
        if counter is not None:
            return bool((counter == 0).any())
        seeds = td.get("episode_seed").reshape(-1).cpu()
        started = self._episodes is None or not torch.equal(seeds, self._episodes)
        self._episodes = seeds.clone()
        return started

    def _newest_frames(self, td: TensorDictBase) -> dict[str, np.ndarray]:
        """The last frame of every camera the policy reads, at the policy's image size.

        Raises:
            ValueError: the env lacks a camera the policy reads (the front crop, say).
        """
        keys = td.keys(True)
        missing = [camera for camera in self.cameras if ("pixels", camera) not in keys]
        if missing:
            raise ValueError(
                f"the policy reads the cameras {list(self.cameras)}, the env lacks {missing}"
                + (
                    ": build it with env.front_crop set to the fraction its data was recorded with"
                    if FRONT_CROP in missing
                    else ""
                )
            )
        frames = {}
        for camera in self.cameras:
            pixels = td.get(("pixels", camera))
            newest = pixels[:, -1] if pixels.dim() == 5 else pixels
            newest = newest.cpu()
            if self.image_size is not None:
                newest = resize_frames(newest, self.image_size)
            frames[camera] = newest.numpy()
        return frames


def _cameras(config: Any) -> tuple[str, ...]:
    """The cameras whose ``observation.images.<camera>`` the policy reads, in the conventional
    order (the three streams for a policy that reads none, as LeRobot's env gives them)."""
    read = tuple(camera for camera in POLICY_CAMERAS if image_key(camera) in config.image_features)
    return read or CAMERAS


def _image_size(config: Any) -> tuple[int, int] | None:
    """``(height, width)`` of the policy's camera inputs (None: it has none)."""
    sizes = {tuple(feature.shape[-2:]) for feature in config.image_features.values()}
    if len(sizes) > 1:
        raise ValueError(f"the policy's cameras have different sizes {sorted(sizes)}")
    return tuple(int(n) for n in sizes.pop()) if sizes else None
