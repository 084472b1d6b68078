"""Multi-camera image encoder: one small CNN per camera (or one shared), in a single pass.

Both weight modes run the cameras in one convolution call: shared weights fold the cameras into
the batch; separate weights stack them along the channels and use grouped convolutions (one
group per camera), which is a single kernel launch instead of one per camera.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from oasis_torchrl.models.config import DrivingNetConfig

_IMAGE_MEAN = 0.5
_IMAGE_STD = 0.25
# (kernel, stride, padding) of the three convolutions: a 4x4 patch stem, then two 3x3 layers.
_LAYOUT = ((4, 4, 0), (3, 2, 1), (3, 1, 1))


class MultiCameraEncoder(nn.Module):
    """Encode ``C`` cameras' frames ``[..., T, 3, H, W]`` (float in [0, 1]) into ``[..., C * F]``.

    Per camera, the ``T = config.frames`` frames stacked along the channels: conv 4x4/4 -> ReLU
    -> conv 3x3/2 -> ReLU -> conv 3x3/1 -> ReLU -> average pool to ``pool_grid`` -> linear to
    ``F = camera_features`` -> ReLU.

    Example:
        >>> config = DrivingNetConfig(image_size=(32, 48), frames=2, camera_features=16)
        >>> encoder = MultiCameraEncoder(config)
        >>> images = [torch.rand(5, 2, 3, 32, 48) for _ in config.cameras]
        >>> encoder(images).shape
        torch.Size([5, 48])
    """

    def __init__(self, config: DrivingNetConfig) -> None:
        super().__init__()
        self.num_cameras = len(config.cameras)
        self.frames = config.frames
        self.groups = 1 if config.shared_encoder else self.num_cameras
        layers: list[nn.Module] = []
        in_channels = 3 * config.frames
        for out_channels, (kernel, stride, padding) in zip(
            config.encoder_channels, _LAYOUT, strict=True
        ):
            layers += [
                nn.Conv2d(
                    in_channels * self.groups,
                    out_channels * self.groups,
                    kernel,
                    stride,
                    padding,
                    groups=self.groups,
                ),
                nn.ReLU(inplace=True),
            ]
            in_channels = out_channels
        layers.append(nn.AdaptiveAvgPool2d(config.pool_grid))
        self.convs = nn.Sequential(*layers)
        pooled = in_channels * config.pool_grid[0] * config.pool_grid[1]
        self.project_weight = nn.Parameter(torch.empty(self.groups, pooled, config.camera_features))
        self.project_bias = nn.Parameter(torch.zeros(self.groups, config.camera_features))
        bound = pooled**-0.5  # nn.Linear's default initialisation, per camera
        nn.init.uniform_(self.project_weight, -bound, bound)
        self.out_features = self.num_cameras * config.camera_features

    def forward(self, images: Sequence[torch.Tensor]) -> torch.Tensor:
        """Features ``[..., C * F]`` of the frames ``[..., T, 3, H, W]`` of each camera."""
        if len(images) != self.num_cameras:
            raise ValueError(f"expected {self.num_cameras} camera images, got {len(images)}")
        first = images[0]
        if first.dim() < 5 or first.shape[-4:-2] != (self.frames, 3):
            raise ValueError(
                f"camera frames must be [..., {self.frames}, 3, H, W], got {list(first.shape)}"
            )
        leading, (height, width) = first.shape[:-4], first.shape[-2:]
        stacked = torch.stack(list(images), dim=-5)  # [..., C, T, 3, H, W]
        # Shared weights fold the cameras into the batch; separate ones stack them as groups.
        channels = 3 * self.frames * self.groups
        x = (stacked.reshape(-1, channels, height, width) - _IMAGE_MEAN) / _IMAGE_STD
        pooled = self.convs(x).reshape(-1, self.groups, self.project_weight.shape[1])
        features = torch.relu(
            torch.einsum("bgk,gkf->bgf", pooled, self.project_weight) + self.project_bias
        )
        return features.reshape(*leading, self.out_features)
