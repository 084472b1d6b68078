"""Multi-camera image encoder: one small CNN per camera (or one shared), in a single pass.

Both weight modes run the cameras in one convolution call: shared weights fold the cameras into
the batch; separate weights stack them along the channels and use grouped convolutions (one
group per camera), which is a single kernel launch instead of one per camera.

Frames come as the env's uint8 ``[..., T, H, W, 3]`` or as float ``[..., T, 3, H, W]`` in
``[0, 1]``. The cameras are stacked before the conversion to float (a byte copy, not a float
one) into one batch in channels-last memory (the faster layout for these convolutions on CPU),
instead of converting each camera to float, stacking and normalising in separate passes.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from oasis_torchrl.models.config import DrivingNetConfig

_IMAGE_MEAN = 0.5
_IMAGE_STD = 0.25


def convolution_layout(stride: int) -> tuple[int, int, int]:
    """``(kernel, stride, padding)`` of an encoder convolution of that stride: a 4x4 patch
    convolution for 4, a 3x3 one (padded to keep the grid at stride 1) for 1 and 2.

    Example:
        >>> [convolution_layout(stride) for stride in (4, 2, 1)]
        [(4, 4, 0), (3, 2, 1), (3, 1, 1)]
    """
    return (4, 4, 0) if stride == 4 else (3, stride, 1)


class MultiCameraEncoder(nn.Module):
    """Encode ``C`` cameras' frames into ``[..., C * F]``: uint8 ``[..., T, H, W, 3]`` or float
    ``[..., T, 3, H, W]`` in ``[0, 1]`` (the same layout and type for every camera).

    Per camera, the ``T = config.frames`` frames stacked along the channels: three convolutions
    of ``encoder_strides`` (by default conv 4x4/4 -> ReLU -> conv 3x3/2 -> ReLU -> conv 3x3/1 ->
    ReLU) -> average pool to ``pool_grid`` -> linear to ``F = camera_features`` -> ReLU.

    Example:
        >>> config = DrivingNetConfig(image_size=(32, 48), frames=2, camera_features=16)
        >>> encoder = MultiCameraEncoder(config)
        >>> images = [torch.rand(5, 2, 3, 32, 48) for _ in config.cameras]
        >>> encoder(images).shape
        torch.Size([5, 48])
        >>> env_frames = [torch.randint(0, 256, (5, 2, 32, 48, 3), dtype=torch.uint8)] * 3
        >>> as_float = [x.movedim(-1, -3) / 255 for x in env_frames]
        >>> torch.allclose(encoder(env_frames), encoder(as_float), atol=1e-6)
        True
    """

    def __init__(self, config: DrivingNetConfig) -> None:
        super().__init__()
        self.num_cameras = len(config.cameras)
        self.frames = config.frames
        self.groups = 1 if config.shared_encoder else self.num_cameras
        layers: list[nn.Module] = []
        in_channels = 3 * config.frames
        for out_channels, stride in zip(
            config.encoder_channels, config.encoder_strides, strict=True
        ):
            kernel, stride, padding = convolution_layout(stride)
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
        """Features ``[..., C * F]`` of the frames of each camera."""
        leading = images[0].shape[:-4]
        pooled = self.convs(self._network_input(images))
        pooled = pooled.reshape(-1, self.groups, self.project_weight.shape[1])
        features = torch.relu(
            torch.einsum("bgk,gkf->bgf", pooled, self.project_weight) + self.project_bias
        )
        return features.reshape(*leading, self.out_features)

    def _network_input(self, images: Sequence[torch.Tensor]) -> torch.Tensor:
        """The normalised frames ``[N, channels, H, W]`` (channels-last memory; channels ordered
        camera, frame, colour). Out-of-place operations only where they touch the inputs, so
        it also runs under ``vmap`` (TorchRL's value estimators call the critic that way); the
        stack is a copy, so the normalisation runs in place on it (one frame-sized copy less,
        a few ms of a behaviour-cloning step)."""
        first = self._check_frames(images)
        channels_first = first.dtype != torch.uint8
        rows = first.shape[:-4].numel()
        order = (0, 3, 4, 1, 2) if channels_first else (0, 2, 3, 1, 4)  # -> [N, H, W, T, 3]
        per_camera = [image.reshape(rows, *image.shape[-4:]).permute(order) for image in images]
        if self.groups == 1:  # cameras folded into the batch
            stacked = torch.stack(per_camera, dim=1).flatten(0, 1).flatten(-2)
        else:  # cameras along the channels
            stacked = torch.stack(per_camera, dim=3).flatten(-3)
        scale = (1.0 if channels_first else 1.0 / 255.0) / _IMAGE_STD
        batch = stacked.to(self.project_weight.dtype).permute(0, 3, 1, 2)
        return batch.mul_(scale).sub_(_IMAGE_MEAN / _IMAGE_STD)

    def _check_frames(self, images: Sequence[torch.Tensor]) -> torch.Tensor:
        """The first camera's frames, after checking every camera's count, layout and type."""
        if len(images) != self.num_cameras:
            raise ValueError(f"expected {self.num_cameras} camera images, got {len(images)}")
        first = images[0]
        if first.dtype == torch.uint8:
            layout_ok = first.shape[-4:-3] == (self.frames,) and first.shape[-1:] == (3,)
        else:
            layout_ok = first.dtype.is_floating_point and first.shape[-4:-2] == (self.frames, 3)
        if first.dim() < 5 or not layout_ok:
            raise ValueError(
                f"camera frames must be float [..., {self.frames}, 3, H, W] or uint8 "
                f"[..., {self.frames}, H, W, 3], got {first.dtype} {list(first.shape)}"
            )
        for image in images[1:]:
            if image.shape != first.shape or image.dtype != first.dtype:
                raise ValueError(
                    f"every camera's frames must match the first's {first.dtype} "
                    f"{list(first.shape)}, got {image.dtype} {list(image.shape)}"
                )
        return first
