"""Pre- and post-processing pipelines of the oasis policy (LeRobot's processor convention).

Preprocessor: rename (none by default), add a batch dimension, move to the policy's device,
resize every camera image to ``config.image_size``, normalise (``config.normalization_mapping``).
Postprocessor: unnormalise the actions, move them to the CPU.
"""

from __future__ import annotations

from typing import Any

import torch
from lerobot.processor import (
    AddBatchDimensionProcessorStep,
    DeviceProcessorStep,
    ImageCropResizeProcessorStep,
    NormalizerProcessorStep,
    PolicyAction,
    PolicyProcessorPipeline,
    RenameObservationsProcessorStep,
    UnnormalizerProcessorStep,
)
from lerobot.processor.converters import policy_action_to_transition, transition_to_policy_action
from lerobot.utils.constants import (
    POLICY_POSTPROCESSOR_DEFAULT_NAME,
    POLICY_PREPROCESSOR_DEFAULT_NAME,
)

from lerobot_policy_oasis.configuration_oasis import OasisConfig

Stats = dict[str, dict[str, torch.Tensor]]


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
        ['ImageCropResizeProcessorStep', 'NormalizerProcessorStep']
    """
    features = {**config.input_features, **config.output_features}
    input_steps = [
        RenameObservationsProcessorStep(rename_map={}),
        AddBatchDimensionProcessorStep(),
        DeviceProcessorStep(device=config.device),
        ImageCropResizeProcessorStep(resize_size=tuple(config.image_size)),
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
