"""Stock LeRobot policy folders built in-process (no training, no downloads) for tests."""

from __future__ import annotations

from pathlib import Path

import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.policies.act.configuration_act import ACTConfig
from lerobot.policies.act.modeling_act import ACTPolicy
from lerobot.policies.factory import make_pre_post_processors

from oasis_torchrl.protocol import CAMERAS

IMAGE_SIZE = (64, 96)


def act_folder(folder: Path, *, n_action_steps: int = 4, seed: int = 0) -> Path:
    """A tiny randomly initialised ACT policy with its processors, saved as LeRobot does."""
    inputs = {
        f"observation.images.{camera}": PolicyFeature(FeatureType.VISUAL, (3, *IMAGE_SIZE))
        for camera in CAMERAS
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
