"""Pre- and post-processing pipelines of the oasis policy (LeRobot's processor convention).

Preprocessor: rename (none by default), add a batch dimension, move to the policy's device,
resize every camera's frames to ``config.image_size`` (:class:`ResizeFramesProcessorStep`),
normalise (``config.normalization_mapping``). Postprocessor: unnormalise the actions, move them
to the CPU.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from lerobot.configs.types import PipelineFeatureType, PolicyFeature
from lerobot.processor import (
    AddBatchDimensionProcessorStep,
    DeviceProcessorStep,
    NormalizerProcessorStep,
    ObservationProcessorStep,
    PolicyAction,
    PolicyProcessorPipeline,
    ProcessorStepRegistry,
    RenameObservationsProcessorStep,
    UnnormalizerProcessorStep,
)
from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
from lerobot.utils.constants import (
    OBS_IMAGES,
    POLICY_POSTPROCESSOR_DEFAULT_NAME,
    POLICY_PREPROCESSOR_DEFAULT_NAME,
)

from lerobot_policy_oasis.configuration_oasis import OasisConfig

Stats = dict[str, dict[str, torch.Tensor]]
PAD_SUFFIX = "_is_pad"


def _is_camera(key: str) -> bool:
    return key.startswith(f"{OBS_IMAGES}.") and not key.endswith(PAD_SUFFIX)


@ProcessorStepRegistry.register("oasis_resize_frames")
@dataclass
class ResizeFramesProcessorStep(ObservationProcessorStep):
    """Resize camera frames ``[..., 3, H, W]`` (any leading dims, e.g. a time axis) to ``size``.

    Only ``observation.images.<camera>`` tensors are touched (LeRobot's own crop-resize step
    also grabs the ``..._is_pad`` masks of multi-frame observations); frames already at
    ``size`` pass through untouched.

    Example:
        >>> step = ResizeFramesProcessorStep(size=(8, 12))
        >>> out = step.observation({"observation.images.front": torch.rand(2, 2, 3, 16, 24)})
        >>> out["observation.images.front"].shape
        torch.Size([2, 2, 3, 8, 12])
    """

    size: tuple[int, int] = (64, 96)

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The observation with every camera's frames at ``size``."""
        resized = dict(observation)
        size = tuple(self.size)
        for key, frames in observation.items():
            if not _is_camera(key) or tuple(frames.shape[-2:]) == size:
                continue
            flat = frames.reshape(-1, *frames.shape[-3:])
            out = F.interpolate(flat, size=size, mode="bilinear", antialias=True)
            resized[key] = out.clamp_(0.0, 1.0).reshape(*frames.shape[:-2], *size)
        return resized

    def get_config(self) -> dict[str, Any]:
        """What :meth:`PolicyProcessorPipeline.save_pretrained` stores."""
        return {"size": list(self.size)}

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        """Camera features take the new size."""
        observed = features.get(PipelineFeatureType.OBSERVATION, {})
        for key, feature in observed.items():
            if _is_camera(key):
                observed[key] = PolicyFeature(feature.type, (feature.shape[0], *self.size))
        return features


def make_oasis_pre_post_processors(
    config: OasisConfig, dataset_stats: Stats | None = None
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    """The ``(preprocessor, postprocessor)`` pair LeRobot's factory asks a policy plugin for.

    Example:
        >>> from lerobot_policy_oasis import OasisConfig
        >>> pre, post = make_oasis_pre_post_processors(OasisConfig(device="cpu"))
        >>> [type(step).__name__ for step in pre.steps][-2:]
        ['ResizeFramesProcessorStep', 'NormalizerProcessorStep']
    """
    features = {**config.input_features, **config.output_features}
    input_steps = [
        RenameObservationsProcessorStep(rename_map={}),
        AddBatchDimensionProcessorStep(),
        DeviceProcessorStep(device=config.device),
        ResizeFramesProcessorStep(size=tuple(config.image_size)),
        NormalizerProcessorStep(
            features=features,
            norm_map=config.normalization_mapping,
            stats=dataset_stats,
            device=config.device,
        ),
    ]
    output_steps = [
        UnnormalizerProcessorStep(
            features=config.output_features,
            norm_map=config.normalization_mapping,
            stats=dataset_stats,
        ),
        DeviceProcessorStep(device="cpu"),
    ]
    return (
        PolicyProcessorPipeline[dict[str, Any], dict[str, Any]](
            steps=input_steps, name=POLICY_PREPROCESSOR_DEFAULT_NAME
        ),
        PolicyProcessorPipeline[PolicyAction, PolicyAction](
            steps=output_steps,
            name=POLICY_POSTPROCESSOR_DEFAULT_NAME,
            to_transition=policy_action_to_transition,
            to_output=transition_to_policy_action,
        ),
    )
