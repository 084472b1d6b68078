"""A small monocular depth network: uint8 RGB frames to per-pixel nearness (a small U-Net).

It stands in for Depth-Anything where no model can be fetched: trained on the embedded world's
frames with the simulator's metric depth as the target (``oasis-torchrl train depth``), it maps
``[N, H, W, 3]`` uint8 frames to float32 nearness ``[N, H, W]`` (relative inverse depth, larger
= nearer). Its scale and offset are arbitrary: :func:`scale_shift_invariant_loss` compares maps
after normalising both, which is all the depth-collision reward needs (it min-max normalises
each image).
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

IMAGE_MEAN = (0.485, 0.456, 0.406)
IMAGE_STD = (0.229, 0.224, 0.225)


@dataclasses.dataclass(frozen=True)
class DepthNetConfig:
    """The network's shape: the widths of its levels, the first at half the frames' resolution,
    each next one at half the previous one's.

    Frames must have height and width divisible by :attr:`divisor`.

    >>> DepthNetConfig().divisor
    16
    """

    channels: tuple[int, ...] = (12, 24, 48, 96)

    def __post_init__(self) -> None:
        if len(self.channels) < 2 or not all(int(c) > 0 for c in self.channels):
            raise ValueError(
                f"DepthNetConfig.channels needs at least two positive widths, got {self.channels}"
            )
        object.__setattr__(self, "channels", tuple(int(c) for c in self.channels))

    @property
    def divisor(self) -> int:
        """What frame heights and widths must be multiples of."""
        return 2 ** len(self.channels)


def _conv(inputs: int, outputs: int, stride: int = 1) -> list[nn.Module]:
    """A 3x3 convolution with batch norm and ReLU."""
    return [
        nn.Conv2d(inputs, outputs, 3, stride=stride, padding=1, bias=False),
        nn.BatchNorm2d(outputs),
        nn.ReLU(inplace=True),
    ]


class DepthNet(nn.Module):
    """A U-Net at half resolution: a strided stem, an encoder halving the resolution per level,
    a decoder doubling it back with skip connections, a 1x1 head, and a bilinear upsampling to
    the frames' size; nearness float32 ``[N, H, W]`` from uint8 ``[N, H, W, 3]``.

    The half-resolution maps keep it cheap on a CPU; the reward reads fractions of the image,
    not edges.

    >>> net = DepthNet(DepthNetConfig(channels=(4, 8))).eval()
    >>> net(torch.zeros(2, 8, 12, 3, dtype=torch.uint8)).shape
    torch.Size([2, 8, 12])
    """

    def __init__(self, config: DepthNetConfig | None = None) -> None:
        super().__init__()
        self.config = config if config is not None else DepthNetConfig()
        widths = self.config.channels
        self.stem = nn.Sequential(*_conv(3, widths[0], stride=2), *_conv(widths[0], widths[0]))
        self.encoder = nn.ModuleList(
            nn.Sequential(*_conv(inputs, outputs), *_conv(outputs, outputs))
            for inputs, outputs in itertools.pairwise(widths)
        )
        self.decoder = nn.ModuleList(
            nn.Sequential(*_conv(deep + skip, skip))
            for deep, skip in zip(widths[:0:-1], widths[-2::-1], strict=True)
        )
        self.head = nn.Conv2d(widths[0], 1, 1)
        self.register_buffer("mean", torch.tensor(IMAGE_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGE_STD).view(1, 3, 1, 1), persistent=False)

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        """Nearness ``[N, H, W]`` of uint8 frames ``[N, H, W, 3]``."""
        check_frames(rgb, self.config.divisor)
        x = self.stem((rgb.permute(0, 3, 1, 2).float().div(255) - self.mean) / self.std)
        skips = [x]
        for block in self.encoder:
            x = block(F.max_pool2d(x, 2))
            skips.append(x)
        for block, skip in zip(self.decoder, reversed(skips[:-1]), strict=True):
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = block(torch.cat([x, skip], dim=1))
        nearness = F.interpolate(
            self.head(x), size=rgb.shape[1:3], mode="bilinear", align_corners=False
        )
        return nearness.squeeze(1)


def check_frames(rgb: torch.Tensor, divisor: int) -> None:
    """Refuse anything but uint8 ``[N, H, W, 3]`` with H and W multiples of ``divisor``.

    >>> check_frames(torch.zeros(1, 6, 8, 3, dtype=torch.uint8), 4)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: DepthNet needs uint8 [N, H, W, 3] frames ... got torch.uint8 [1, 6, 8, 3]
    """
    if (
        rgb.dtype != torch.uint8
        or rgb.ndim != 4
        or rgb.shape[-1] != 3
        or rgb.shape[1] % divisor
        or rgb.shape[2] % divisor
    ):
        raise ValueError(
            f"DepthNet needs uint8 [N, H, W, 3] frames with H and W multiples of {divisor}, "
            f"got {rgb.dtype} {list(rgb.shape)}"
        )


def normalize_robustly(maps: torch.Tensor, eps: float = 1e-6) -> torch.Tensor:
    """Each ``[H, W]`` map of ``[N, H, W]`` minus its median, over its mean absolute deviation
    from it: invariant to a positive scale and a shift, and it keeps the order.

    >>> normalize_robustly(torch.tensor([[[0.0, 1.0, 3.0]]])).tolist()
    [[[-1.0, 0.0, 2.0]]]
    """
    flat = maps.flatten(1)
    median = flat.median(dim=1, keepdim=True).values
    spread = (flat - median).abs().mean(dim=1, keepdim=True).clamp_min(eps)
    return ((flat - median) / spread).view_as(maps)


def scale_shift_invariant_loss(
    predicted: torch.Tensor, target: torch.Tensor, near_weight: float = 0.0
) -> torch.Tensor:
    """Mean absolute difference of the robustly normalised maps (:func:`normalize_robustly`),
    the MiDaS loss on inverse depth: any positive scale and shift of a map costs nothing.

    ``near_weight`` weighs each pixel by ``1 + near_weight * t``, where ``t`` is the target's
    nearness min-max normalised per image (sky 0, the nearest pixel 1): the pixels that decide
    the depth-collision reward count more.

    >>> target = torch.rand(2, 4, 6)
    >>> scale_shift_invariant_loss(3 * target + 1, target, near_weight=4.0).item() < 1e-5
    True
    """
    error = (normalize_robustly(predicted) - normalize_robustly(target)).abs()
    if not near_weight:
        return error.mean()
    flat = target.flatten(1)
    low, high = flat.amin(1, keepdim=True), flat.amax(1, keepdim=True)
    nearness = ((flat - low) / (high - low).clamp_min(1e-6)).view_as(target)
    weight = 1.0 + near_weight * nearness
    return (error * weight).sum() / weight.sum()


def nearness_target(depth: torch.Tensor, factor: int = 1) -> torch.Tensor:
    """Nearness ``1 / depth`` (sky, +inf, is 0) of metric depth ``[N, H, W]``, averaged over
    ``factor`` x ``factor`` blocks (depth rendered at ``factor`` times the frames' size).

    >>> nearness_target(torch.tensor([[[1.0, 2.0], [4.0, float("inf")]]]), factor=2).tolist()
    [[[0.4375]]]
    """
    nearness = torch.reciprocal(depth.float())
    if factor == 1:
        return nearness
    return F.avg_pool2d(nearness.unsqueeze(1), factor).squeeze(1)


def parameter_count(module: nn.Module) -> int:
    """Number of parameters of ``module``.

    >>> parameter_count(nn.Linear(3, 2))
    8
    """
    return sum(p.numel() for p in module.parameters())


def config_from_dict(values: dict[str, Sequence[int]]) -> DepthNetConfig:
    """The :class:`DepthNetConfig` saved with a weights file (``dataclasses.asdict`` of it).

    >>> config_from_dict({"channels": [8, 16]})
    DepthNetConfig(channels=(8, 16))
    """
    return DepthNetConfig(**{key: tuple(value) for key, value in values.items()})
