"""The usual transformed ``OasisEnv`` for training, built with one call."""

from __future__ import annotations

from typing import Any

from torchrl.envs import Compose, Resize, RewardSum, StepCounter, ToTensorImage, TransformedEnv

from oasis_torchrl.envs.oasis_env import OasisEnv
from oasis_torchrl.models.config import POLICY_IMAGE_SIZE


def make_training_env(
    env: OasisEnv | None = None,
    *,
    image_size: tuple[int, int] = POLICY_IMAGE_SIZE,
    **env_kwargs: Any,
) -> TransformedEnv:
    """Wrap an :class:`OasisEnv` with float images at policy size, a reward sum and a step count.

    Adds ``("images", <camera>)``: float32 ``[N, 3, H, W]`` in ``[0, 1]`` beside the raw uint8
    ``("pixels", <camera>)`` (kept for datasets and viewers), ``"episode_reward"`` and
    ``"step_count"``. When the env is built here, frames are resized while decoding, so no
    per-step resize runs; an existing env of another size gets a ``Resize`` transform.

    Args:
        env: an existing env; if ``None`` one is built from ``env_kwargs`` with
            ``frame_size=image_size``.
        image_size: ``(height, width)`` of the policy images.
        **env_kwargs: arguments of :class:`OasisEnv` when ``env`` is ``None``.

    Example:
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = make_training_env(num_envs=2, image_size=(32, 48),
        ...                         server=ServerConfig(width=96, height=64))
        >>> env.reset()["images", "front"].shape
        torch.Size([2, 3, 32, 48])
        >>> env.close()
    """
    if env is None:
        env = OasisEnv(frame_size=image_size, **env_kwargs)
    cameras = env.layout.cameras
    in_keys = [("pixels", camera) for camera in cameras]
    out_keys = [("images", camera) for camera in cameras]
    transforms = [ToTensorImage(in_keys=in_keys, out_keys=out_keys)]
    if tuple(env.layout.frame_size) != tuple(image_size):
        transforms.append(Resize(image_size[1], image_size[0], in_keys=out_keys))
    transforms += [RewardSum(), StepCounter()]
    return TransformedEnv(env, Compose(*transforms))
