"""Where a depth reward gets its per-pixel nearness: ground truth, a monocular model, or a callable.

Every source maps the step's TensorDict to float32 ``[N, H, W]`` *nearness* for one camera:
relative inverse depth, larger = nearer, like Depth-Anything's output. Only the order matters to
the depth-collision reward, which min-max normalises each image.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import torch
import torch.nn.functional as F
from tensordict import TensorDictBase

from oasis_torchrl.protocol import CAMERAS, CHUNK
from oasis_torchrl.rewards.base import get_entry

if TYPE_CHECKING:
    from transformers import BaseImageProcessor, PreTrainedModel

logger = logging.getLogger(__name__)

DEFAULT_DEPTH_MODEL = "depth-anything/Depth-Anything-V2-Small-hf"
OFFLINE_ALTERNATIVE = "env.reward.depth_model=small"
"""The setting that needs no download: the small depth network shipped with the package."""
DepthFn = Callable[[torch.Tensor], torch.Tensor]
InputSize = int | tuple[int, int]


class DepthModelError(ValueError):
    """A depth model cannot be loaded; the message names the model, the cause and the
    alternative.

    >>> raise DepthModelError("depth model 'x' cannot be loaded: ...")
    Traceback (most recent call last):
    ...
    oasis_torchrl.rewards.depth_sources.DepthModelError: depth model 'x' cannot be loaded: ...
    """


@runtime_checkable
class DepthSource(Protocol):
    """Maps a step's TensorDict to float32 nearness ``[N, H, W]`` (larger = nearer).

    >>> isinstance(GroundTruthDepth(), DepthSource)
    True
    """

    camera: str

    def __call__(self, td: TensorDictBase) -> torch.Tensor:
        """Nearness of the configured camera's last frame, one map per row."""
        ...


def check_camera(camera: str) -> str:
    """Return ``camera`` if it is one of :data:`CAMERAS`, else raise ValueError.

    >>> check_camera("front")
    'front'
    """
    if camera not in CAMERAS:
        raise ValueError(f"camera must be one of {CAMERAS}, got {camera!r}")
    return camera


def read_pixels(td: TensorDictBase, camera: str, owner: str) -> torch.Tensor:
    """The uint8 RGB frames ``[N, H, W, 3]`` of ``camera``, validated; of an env that returns
    every frame of a chunk (``[N, 4, H, W, 3]``), the chunk's last, as the reference scores.

    >>> from tensordict import TensorDict
    >>> td = TensorDict({("pixels", "front"): torch.zeros(2, 8, 8, 3, dtype=torch.uint8)}, [2])
    >>> read_pixels(td, "front", "doc").shape
    torch.Size([2, 8, 8, 3])
    >>> chunks = TensorDict({("pixels", "front"): torch.zeros(2, 4, 8, 8, 3).byte()}, [2])
    >>> read_pixels(chunks, "front", "doc").shape
    torch.Size([2, 8, 8, 3])
    """
    rgb = get_entry(td, ("pixels", camera), owner)
    if rgb.ndim == 5 and rgb.shape[1] == CHUNK:
        rgb = rgb[:, -1]
    if rgb.dtype != torch.uint8 or rgb.ndim != 4 or rgb.shape[-1] != 3:
        raise ValueError(
            f"{owner} needs td[('pixels', {camera!r})] as uint8 [N, H, W, 3], "
            f"got {rgb.dtype} {list(rgb.shape)}"
        )
    return rgb


class GroundTruthDepth:
    """Nearness ``1 / depth`` from the embedded server's metric depth (sky, +inf, becomes 0).

    >>> from tensordict import TensorDict
    >>> depth = torch.tensor([[[2.0, float("inf")]]])
    >>> GroundTruthDepth()(TensorDict({("depth", "front"): depth}, [1])).tolist()
    [[[0.5, 0.0]]]
    """

    def __init__(self, camera: str = "front") -> None:
        self.camera = check_camera(camera)

    def __call__(self, td: TensorDictBase) -> torch.Tensor:
        """Reciprocal of ``td[("depth", camera)]`` float ``[N, H, W]``."""
        depth = get_entry(td, ("depth", self.camera), type(self).__name__)
        if not depth.is_floating_point() or depth.ndim != 3:
            raise ValueError(
                f"GroundTruthDepth needs td[('depth', {self.camera!r})] as float [N, H, W], "
                f"got {depth.dtype} {list(depth.shape)}"
            )
        return torch.reciprocal(depth.float())


class CallableDepth:
    """Nearness from a user callable ``fn(rgb uint8 [N, H, W, 3]) -> Tensor [N, H, W]``.

    >>> from tensordict import TensorDict
    >>> source = CallableDepth(lambda rgb: rgb[..., 0].float())
    >>> td = TensorDict({("pixels", "front"): torch.ones(2, 4, 6, 3, dtype=torch.uint8)}, [2])
    >>> source(td).shape
    torch.Size([2, 4, 6])
    """

    def __init__(self, fn: DepthFn, camera: str = "front") -> None:
        if not callable(fn):
            raise TypeError(f"fn must be callable as fn(rgb) -> Tensor, got {type(fn).__name__}")
        self.fn = fn
        self.camera = check_camera(camera)

    def __call__(self, td: TensorDictBase) -> torch.Tensor:
        """Call ``fn`` on the camera's frames and check it returned float-able ``[N, H, W]``."""
        rgb = read_pixels(td, self.camera, type(self).__name__)
        nearness = self.fn(rgb)
        if not isinstance(nearness, torch.Tensor):
            raise TypeError(f"depth fn must return a torch.Tensor, got {type(nearness).__name__}")
        if nearness.shape != rgb.shape[:3]:
            raise ValueError(
                f"depth fn must return shape {list(rgb.shape[:3])} (N, H, W of the frames), "
                f"got {list(nearness.shape)}"
            )
        return nearness.float()


@dataclasses.dataclass(frozen=True)
class DepthPreprocess:
    """Batched torch version of the DPT image processor Depth-Anything uses.

    Defaults are Depth-Anything-V2's processor settings. Resize (bicubic) to ``size`` with the
    processor's aspect-ratio rule and rounding to ``multiple_of``, scale to [0, 1], normalise.

    >>> DepthPreprocess().output_size(512, 768)
    (518, 784)
    >>> DepthPreprocess()(torch.zeros(2, 64, 96, 3, dtype=torch.uint8), torch.float32).shape
    torch.Size([2, 3, 350, 518])
    """

    size: tuple[int, int] = (518, 518)
    keep_aspect_ratio: bool = True
    multiple_of: int = 14
    mean: tuple[float, float, float] = (0.485, 0.456, 0.406)
    std: tuple[float, float, float] = (0.229, 0.224, 0.225)

    @classmethod
    def from_processor(
        cls, processor: BaseImageProcessor, input_size: InputSize | None = None
    ) -> DepthPreprocess:
        """Read a DPT processor's settings (either backend); ``input_size`` overrides its size."""
        size = processor.size
        target = input_size if input_size is not None else (size["height"], size["width"])
        return cls(
            size=_size_pair(target),
            keep_aspect_ratio=bool(processor.keep_aspect_ratio),
            multiple_of=int(processor.ensure_multiple_of),
            mean=tuple(processor.image_mean),
            std=tuple(processor.image_std),
        )

    def output_size(self, height: int, width: int) -> tuple[int, int]:
        """Model input size for ``height x width`` frames (the DPT processor's rule)."""
        scale_height = self.size[0] / height
        scale_width = self.size[1] / width
        if self.keep_aspect_ratio:
            # Scale as little as possible, as the DPT processor does.
            if abs(1 - scale_width) < abs(1 - scale_height):
                scale_height = scale_width
            else:
                scale_width = scale_height
        return self._to_multiple(scale_height * height), self._to_multiple(scale_width * width)

    def _to_multiple(self, value: float) -> int:
        return max(self.multiple_of, round(value / self.multiple_of) * self.multiple_of)

    def __call__(self, rgb: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
        """``pixel_values`` ``[N, 3, h, w]`` in ``dtype`` from uint8 frames ``[N, H, W, 3]``."""
        images = rgb.permute(0, 3, 1, 2).float().div_(255)
        images = F.interpolate(
            images,
            size=self.output_size(rgb.shape[1], rgb.shape[2]),
            mode="bicubic",
            align_corners=False,
            antialias=True,
        ).clamp_(0, 1)
        mean = torch.tensor(self.mean, device=images.device).view(1, 3, 1, 1)
        std = torch.tensor(self.std, device=images.device).view(1, 3, 1, 1)
        return images.sub_(mean).div_(std).to(dtype)


def _size_pair(size: InputSize) -> tuple[int, int]:
    pair = (size, size) if isinstance(size, int) else tuple(size)
    if len(pair) != 2 or not all(isinstance(v, int) and v > 0 for v in pair):
        raise ValueError(f"input_size must be a positive int or (height, width), got {size!r}")
    return pair


class MonocularDepth:
    """Nearness from a transformers depth model (Depth-Anything-V2-Small by default).

    ``model`` is a hub id or local directory (loaded lazily on the first call with
    ``AutoModelForDepthEstimation`` and ``AutoImageProcessor``) or an already built model (then
    preprocessed with :class:`DepthPreprocess` defaults). All N frames go through one batched
    forward on ``device`` (default: the frames' device); the result, resized bilinearly back to
    the frames' H x W, is returned on the frames' device. ``input_size`` (int or (height, width))
    replaces the processor's target size, e.g. to trade accuracy for speed.

    >>> source = MonocularDepth()
    >>> source.is_loaded
    False
    """

    def __init__(
        self,
        model: str | os.PathLike[str] | PreTrainedModel = DEFAULT_DEPTH_MODEL,
        *,
        camera: str = "front",
        device: torch.device | str | None = None,
        input_size: InputSize | None = None,
    ) -> None:
        self.camera = check_camera(camera)
        self.device = torch.device(device) if device is not None else None
        self.input_size = _size_pair(input_size) if input_size is not None else None
        self._model: torch.nn.Module | None = None
        self._preprocess: DepthPreprocess | None = None
        if isinstance(model, torch.nn.Module):
            self._model = model.eval()
            self._preprocess = (
                DepthPreprocess() if self.input_size is None else DepthPreprocess(self.input_size)
            )
        elif not isinstance(model, str | os.PathLike):
            raise TypeError(
                f"model must be a hub id, a local path or a torch.nn.Module, "
                f"got {type(model).__name__}"
            )
        self.source = model

    @property
    def is_loaded(self) -> bool:
        """Whether the model is in memory (False until the first call for a hub id or path)."""
        return self._model is not None

    @property
    def model(self) -> torch.nn.Module | None:
        """The depth model, or None before it is loaded."""
        return self._model

    def _load(self) -> tuple[torch.nn.Module, DepthPreprocess]:
        if self._model is None or self._preprocess is None:
            from transformers import AutoImageProcessor, AutoModelForDepthEstimation

            logger.info("loading depth model %s", self.source)
            try:
                model = AutoModelForDepthEstimation.from_pretrained(self.source).eval()
                processor = AutoImageProcessor.from_pretrained(self.source)
            except (OSError, ValueError) as error:  # not cached offline, no such model, bad files
                raise DepthModelError(
                    f"depth model {str(self.source)!r} cannot be loaded: "
                    f"{_why_not_loaded(self.source, error)}; "
                    f"offline, use the small network shipped with the package: "
                    f"{OFFLINE_ALTERNATIVE}"
                ) from None
            self._model = model
            self._preprocess = DepthPreprocess.from_processor(processor, self.input_size)
        return self._model, self._preprocess

    def __call__(self, td: TensorDictBase) -> torch.Tensor:
        """One batched forward over the camera's N frames; nearness float32 ``[N, H, W]``."""
        rgb = read_pixels(td, self.camera, type(self).__name__)
        model, preprocess = self._load()
        device = self.device if self.device is not None else rgb.device
        parameter = next(model.parameters())
        if parameter.device != device:
            model.to(device)
        with torch.inference_mode():
            pixel_values = preprocess(rgb.to(device), parameter.dtype)
            predicted = model(pixel_values=pixel_values).predicted_depth
        # Resizing outside inference mode returns an ordinary tensor callers may modify in place.
        nearness = F.interpolate(
            predicted.unsqueeze(1).float(),
            size=rgb.shape[1:3],
            mode="bilinear",
            align_corners=False,
        ).squeeze(1)
        return nearness.to(rgb.device)


def error_cause(error: BaseException) -> str:
    """An error's type and the first line of its message, for one-line reports (web addresses
    replaced by "the hub").

    >>> error_cause(OSError("cannot reach 'https://example.org/x'\\nlong advice"))
    'OSError: cannot reach the hub'
    """
    lines = str(error).strip().splitlines()
    first = re.sub(r"'?https?://[^\s']+'?", "the hub", lines[0]) if lines else "no message"
    return f"{type(error).__name__}: {first}"


def _why_not_loaded(source: str | os.PathLike[str], error: BaseException) -> str:
    """Why ``from_pretrained(source)`` failed, in words a user can act on."""
    from huggingface_hub import constants

    text = str(source)
    if Path(text).expanduser().is_dir():
        return f"the folder holds no depth model ({error_cause(error)})"
    if isinstance(source, os.PathLike) or text.startswith(("/", ".", "~")):
        return "no such folder"
    if constants.HF_HUB_OFFLINE:
        return "it is not in the local cache, and downloads are off (HF_HUB_OFFLINE)"
    return error_cause(error)
