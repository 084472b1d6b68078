"""Depth sources: ground-truth inversion, the callable wrapper, and the monocular model path.

The monocular tests use a tiny randomly initialised Depth-Anything saved to a temporary folder,
loaded through the real ``from_pretrained`` path with the hub offline.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import torch
from tensordict import TensorDict

from oasis_torchrl.rewards import CallableDepth, DepthPreprocess, GroundTruthDepth, MonocularDepth

N, HEIGHT, WIDTH = 3, 64, 96
INPUT_SIZE = 56  # tiny model input: 56 x 84 for 64 x 96 frames


def frames_td(batch: int = N, camera: str = "front") -> TensorDict:
    """Smooth synthetic RGB frames (a different gradient per row)."""
    rows = torch.linspace(0, 1, HEIGHT).view(1, HEIGHT, 1, 1)
    cols = torch.linspace(0, 1, WIDTH).view(1, 1, WIDTH, 1)
    tint = torch.arange(1, batch + 1, dtype=torch.float32).view(batch, 1, 1, 1) / batch
    channels = [rows * tint, cols * tint, (rows + cols) / 2]
    rgb = torch.cat([c.expand(batch, HEIGHT, WIDTH, 1) for c in channels], dim=-1)
    pixels = (rgb * 255).to(torch.uint8)
    return TensorDict({("pixels", camera): pixels}, batch_size=[batch])


def tiny_depth_anything() -> torch.nn.Module:
    """The smallest valid Depth-Anything: a 3-layer, 8-wide Dinov2 and 4-channel neck."""
    from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config

    torch.manual_seed(0)
    backbone = Dinov2Config(
        hidden_size=8,
        num_hidden_layers=3,
        num_attention_heads=1,
        mlp_ratio=1,
        image_size=14,
        patch_size=14,
        out_indices=[0, 1, 2, 3],
        reshape_hidden_states=False,
        apply_layernorm=True,
    )
    config = DepthAnythingConfig(
        backbone_config=backbone,
        reassemble_hidden_size=8,
        neck_hidden_sizes=[4, 4, 4, 4],
        fusion_hidden_size=4,
        head_hidden_size=4,
    )
    return DepthAnythingForDepthEstimation(config).eval()


def depth_anything_processor(size: int):
    """Depth-Anything-V2's processor settings at a small target size."""
    from transformers import DPTImageProcessor

    return DPTImageProcessor(
        size={"height": size, "width": size},
        keep_aspect_ratio=True,
        ensure_multiple_of=14,
        image_mean=[0.485, 0.456, 0.406],
        image_std=[0.229, 0.224, 0.225],
    )


@pytest.fixture(scope="module")
def tiny_model_dir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("HF_HUB_OFFLINE", "1")
        folder = tmp_path_factory.mktemp("tiny-depth-anything")
        tiny_depth_anything().save_pretrained(folder)
        depth_anything_processor(INPUT_SIZE).save_pretrained(folder)
        yield folder


def test_ground_truth_inverts_metric_depth_and_sky_is_zero() -> None:
    depth = torch.tensor([[[2.0, float("inf")], [0.5, 4.0]]])
    td = TensorDict({("depth", "front"): depth}, batch_size=[1])
    assert GroundTruthDepth()(td).tolist() == [[[0.5, 0.0], [2.0, 0.25]]]


def test_ground_truth_reads_the_configured_camera_and_names_missing_keys() -> None:
    td = TensorDict({("depth", "left_forward"): torch.full((1, 2, 2), 4.0)}, batch_size=[1])
    assert GroundTruthDepth("left_forward")(td).unique().tolist() == [0.25]
    with pytest.raises(KeyError, match=r"\('depth', 'front'\)"):
        GroundTruthDepth()(td)
    with pytest.raises(ValueError, match="camera must be one of"):
        GroundTruthDepth("rear")


def test_ground_truth_rejects_non_float_maps() -> None:
    td = TensorDict({("depth", "front"): torch.ones(1, 2, 2, dtype=torch.int32)}, [1])
    with pytest.raises(ValueError, match=r"float \[N, H, W\]"):
        GroundTruthDepth()(td)


def test_callable_depth_passes_the_camera_frames_and_checks_the_result() -> None:
    seen: list[torch.Tensor] = []

    def brightness(rgb: torch.Tensor) -> torch.Tensor:
        seen.append(rgb)
        return rgb.float().mean(-1)

    td = frames_td(camera="right_forward")
    nearness = CallableDepth(brightness, camera="right_forward")(td)
    assert nearness.shape == (N, HEIGHT, WIDTH) and nearness.dtype == torch.float32
    assert seen[0] is td["pixels", "right_forward"]


def test_callable_depth_errors_are_clear() -> None:
    td = frames_td()
    with pytest.raises(ValueError, match=r"must return shape \[3, 64, 96\].*got \[3, 64\]"):
        CallableDepth(lambda rgb: rgb[..., 0, 0].float())(td)
    with pytest.raises(TypeError, match=r"must return a torch\.Tensor, got list"):
        CallableDepth(lambda rgb: [0.0])(td)
    with pytest.raises(TypeError, match="fn must be callable"):
        CallableDepth("not a function")  # type: ignore[arg-type]
    with pytest.raises(KeyError, match=r"\('pixels', 'left_forward'\)"):
        CallableDepth(lambda rgb: rgb, camera="left_forward")(td)
    td["pixels", "front"] = td["pixels", "front"].float()
    with pytest.raises(ValueError, match=r"uint8 \[N, H, W, 3\]"):
        CallableDepth(lambda rgb: rgb)(td)


def test_monocular_loads_lazily_from_a_local_folder(tiny_model_dir: Path) -> None:
    source = MonocularDepth(str(tiny_model_dir))
    assert not source.is_loaded and source.model is None
    nearness = source(frames_td())
    assert source.is_loaded
    assert nearness.shape == (N, HEIGHT, WIDTH) and nearness.dtype == torch.float32
    assert torch.isfinite(nearness).all()
    assert source.model is not None and not source.model.training


def test_monocular_defers_errors_of_a_missing_model_to_the_first_call(tmp_path: Path) -> None:
    source = MonocularDepth(tmp_path)  # an empty folder: constructing reads nothing
    with pytest.raises((OSError, ValueError)):  # transformers' own error for a model-less folder
        source(frames_td())


def test_monocular_runs_one_batched_forward_at_the_processor_size(tiny_model_dir: Path) -> None:
    source = MonocularDepth(str(tiny_model_dir))
    source(frames_td(batch=1))
    inputs: list[torch.Tensor] = []
    hook = source.model.register_forward_hook(
        lambda module, args, kwargs, output: inputs.append(kwargs["pixel_values"]),
        with_kwargs=True,
    )
    try:
        nearness = source(frames_td())
    finally:
        hook.remove()
    assert len(inputs) == 1
    assert inputs[0].shape == (N, 3, 56, 84)
    assert nearness.shape == (N, HEIGHT, WIDTH)


def test_monocular_accepts_a_built_model_and_input_size() -> None:
    model = tiny_depth_anything()
    calls: list[torch.Size] = []
    model.register_forward_hook(
        lambda module, args, kwargs, output: calls.append(kwargs["pixel_values"].shape),
        with_kwargs=True,
    )
    source = MonocularDepth(model, input_size=(28, 42))
    assert source.is_loaded
    first = source(frames_td())
    again = source(frames_td())
    assert calls == [torch.Size([N, 3, 28, 42])] * 2
    assert torch.equal(first, again)
    with pytest.raises(TypeError, match="model must be a hub id"):
        MonocularDepth(3)  # type: ignore[arg-type]


def test_monocular_places_the_model_on_the_requested_device() -> None:
    source = MonocularDepth(tiny_depth_anything(), device="cpu", input_size=INPUT_SIZE)
    nearness = source(frames_td())
    assert next(source.model.parameters()).device == torch.device("cpu")
    assert nearness.device == frames_td()["pixels", "front"].device


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_monocular_runs_on_cuda_and_returns_on_the_frames_device() -> None:
    source = MonocularDepth(tiny_depth_anything(), device="cuda", input_size=INPUT_SIZE)
    nearness = source(frames_td())
    assert next(source.model.parameters()).device.type == "cuda"
    assert nearness.device.type == "cpu"


def test_torch_preprocessing_matches_the_transformers_processor() -> None:
    processor = depth_anything_processor(INPUT_SIZE)
    pixels = frames_td()["pixels", "front"]
    expected = processor(images=list(pixels.numpy()), return_tensors="pt")["pixel_values"]
    actual = DepthPreprocess.from_processor(processor)(pixels, torch.float32)
    assert actual.shape == expected.shape
    assert torch.allclose(actual, expected, atol=0.05)
