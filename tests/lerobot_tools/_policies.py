"""LeRobot policy folders built in-process (no training, no downloads) for tests: a stock ACT
and the project's own policy."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.policies.act.configuration_act import ACTConfig
from lerobot.policies.act.modeling_act import ACTPolicy
from lerobot.policies.factory import make_pre_post_processors

from oasis_torchrl.drivers.folders import export_lerobot
from oasis_torchrl.models import DrivingNet, DrivingNetConfig
from oasis_torchrl.protocol import CAMERAS

IMAGE_SIZE = (64, 96)


def act_folder(
    folder: Path,
    *,
    n_action_steps: int = 4,
    seed: int = 0,
    cameras: Sequence[str] = CAMERAS,
) -> Path:
    """A tiny randomly initialised ACT policy reading ``cameras``, with its processors, saved
    as LeRobot does."""
    inputs = {
        f"observation.images.{camera}": PolicyFeature(FeatureType.VISUAL, (3, *IMAGE_SIZE))
        for camera in cameras
    }
    inputs["observation.state"] = PolicyFeature(FeatureType.STATE, (2,))
    config = ACTConfig(
        device="cpu",
        push_to_hub=False,
        input_features=inputs,
        output_features={"action": PolicyFeature(FeatureType.ACTION, (2,))},
        chunk_size=8,
        n_action_steps=n_action_steps,
        dim_model=32,
        n_heads=2,
        dim_feedforward=64,
        n_encoder_layers=1,
        use_vae=False,
        pretrained_backbone_weights=None,
    )
    torch.manual_seed(seed)
    policy = ACTPolicy(config)
    stats = {
        key: {"mean": torch.full((3, 1, 1), 0.4), "std": torch.full((3, 1, 1), 0.2)}
        for key in inputs
        if "images" in key
    }
    stats["observation.state"] = {"mean": torch.zeros(2), "std": torch.full((2,), 0.5)}
    stats["action"] = {"mean": torch.tensor([0.5, 0.0]), "std": torch.tensor([0.3, 0.1])}
    preprocessor, postprocessor = make_pre_post_processors(config, dataset_stats=stats)
    policy.save_pretrained(folder)
    preprocessor.save_pretrained(folder)
    postprocessor.save_pretrained(folder)
    return folder


def oasis_folder(folder: Path, *, seed: int = 0) -> Path:
    """The project's policy around 0.6 throttle, with its actor's last layer far above a fresh
    one's (which starts near one chunk for every input), so that its actions swing with the
    frames it sees: the same policy fed other frames drives other distances. A unimodal head,
    so its chunk is continuous in them."""
    torch.manual_seed(seed)
    config = DrivingNetConfig(image_size=IMAGE_SIZE, head="tanh_normal", init_action=(0.6, 0.0))
    net = DrivingNet(config)
    last = net.actor[-1]
    torch.nn.init.normal_(last.weight, std=30.0 / last.in_features**0.5)
    return export_lerobot(net, folder)
