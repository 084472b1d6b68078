"""LeRobot export throughput vs encoding the same frames straight through PyAV (the floor).

Records one rollout from the embedded server (``all_frames=True``, autopilot, every row one
episode of ``--steps`` chunks), then writes it several ways, each timed best of ``--repeats``:

- ``floor``: PyAV alone: one MP4 per episode and camera, the recorder's codec settings (LeRobot's
  ``g=2``, ``yuv420p``, libsvtav1 preset 12, at the project's ``crf`` unless ``codec:crf`` asks
  for another), one encoder thread per camera as LeRobot runs them, frames from in-memory arrays;
- ``lerobot``: ``LeRobotDataset.create`` + ``add_frame`` + ``save_episode`` + ``finalize`` on
  rows already in memory (LeRobot's own overhead on top of the floor);
- ``recorder``: :class:`~oasis_torchrl.data.LeRobotRecorder` on the rollout TensorDict (adds our
  mapping, validation and the per-episode spill of frames to disk), with the encoder threads'
  image statistics kept from level counts (:func:`oasis_torchrl.compat.count_image_statistics`);
- ``recorder_lerobot_stats``: the same with LeRobot's own running statistics (the baseline of
  ``counted_stats_speedup``; ``lerobot`` runs with them too).

Also reports what the time above the floor is made of: LeRobot's per-frame work in its encoder
threads (PIL round trip, running image statistics), its per-episode work (parquet, stats,
metadata, MP4 concatenation), and ours (mapping, spill write and read-back), plus the PSNR of
the stored video. Throughput is in dataset rows per second (a row = one frame per camera).

Usage: ``python benchmarks/export_speed.py [--steps 12 --num-envs 2 --codecs h264,libsvtav1]``
(``--codecs h264:30,h264`` compares LeRobot's quality with the project's); prints JSON.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import torch
from lerobot.configs.video import RGBEncoderConfig
from lerobot.datasets import compute_stats
from lerobot.datasets.compute_stats import auto_downsample_height_width
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from PIL import Image
from tensordict import TensorDictBase

from oasis_torchrl.compat import CountedImageStats
from oasis_torchrl.data import LeRobotRecorder, writer
from oasis_torchrl.data.chunk_rows import batch_to_rows, infer_layout
from oasis_torchrl.data.episode_buffer import EpisodeBuffer
from oasis_torchrl.data.features import build_features, check_columns
from oasis_torchrl.data.writer import camera_encoder, open_dataset, write_episode
from oasis_torchrl.drivers import Autopilot
from oasis_torchrl.envs import OasisEnv
from oasis_torchrl.sim.config import ServerConfig

FPS = 20
LEROBOT_STATS = CountedImageStats.__bases__[0]
"""LeRobot's own ``RunningQuantileStats`` (the writer puts the counted one in its place)."""


@contextlib.contextmanager
def lerobot_statistics() -> Iterator[None]:
    """The encoder threads keep LeRobot's own running image statistics within the block."""
    installed, install = compute_stats.RunningQuantileStats, writer.count_image_statistics
    compute_stats.RunningQuantileStats = LEROBOT_STATS
    writer.count_image_statistics = lambda: None
    try:
        yield
    finally:
        compute_stats.RunningQuantileStats = installed
        writer.count_image_statistics = install


def record_rollout(num_envs: int, steps: int, width: int, height: int) -> TensorDictBase:
    """One episode of ``steps`` chunks per env row, all 4 frames per chunk."""
    server = ServerConfig(width=width, height=height)
    prompts = ["urban street", "rural road at sunset", "highway in fog", "city at night"]
    env = OasisEnv(
        "local",
        num_envs,
        prompts[:num_envs],
        server=server,
        all_frames=True,
        max_steps=steps,
        expert=True,
    )
    try:
        return env.rollout(steps, Autopilot(), break_when_any_done=False)
    finally:
        env.close()


def best_of(repeats: int, run: Callable[[], float]) -> float:
    """The fastest of ``repeats`` runs (other processes share this machine)."""
    return min(run() for _ in range(repeats))


def codec_settings(spec: str) -> RGBEncoderConfig:
    """``"h264"`` (the project's quality) or ``"h264:30"`` (at crf 30) as encoder settings."""
    vcodec, _, crf = spec.partition(":")
    return camera_encoder(vcodec, float(crf)) if crf else camera_encoder(vcodec)


def _encode_camera(frames: np.ndarray, path: Path, encoder: RGBEncoderConfig) -> None:
    with av.open(str(path), "w") as container:
        options = encoder.get_codec_options(as_strings=True)
        stream = container.add_stream(encoder.vcodec, FPS, options=options)
        stream.pix_fmt = encoder.pix_fmt
        stream.height, stream.width = frames.shape[1:3]
        stream.time_base = Fraction(1, FPS)
        for index, image in enumerate(frames):
            frame = av.VideoFrame.from_ndarray(image, format="rgb24")
            frame.pts = index
            container.mux(stream.encode(frame))
        container.mux(stream.encode())


def time_floor(
    episodes: list[dict[str, np.ndarray]], encoder: RGBEncoderConfig, out: Path
) -> float:
    """PyAV alone, one thread per camera, episode after episode."""
    start = time.perf_counter()
    for number, images in enumerate(episodes):
        threads = [
            threading.Thread(
                target=_encode_camera, args=(frames, out / f"{number}_{k}.mp4", encoder)
            )
            for k, frames in enumerate(images.values())
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    return time.perf_counter() - start


def time_lerobot(
    episodes: list[list[dict[str, np.ndarray]]],
    features: dict,
    encoder: RGBEncoderConfig,
    root: Path,
) -> dict[str, float]:
    """LeRobot's API on in-memory rows; also times ``save_episode`` within the total."""
    start = time.perf_counter()
    dataset = open_dataset(root, features, FPS, vcodec=encoder.vcodec, crf=encoder.crf)
    saving = 0.0
    save_episode = dataset.save_episode

    def timed_save_episode() -> None:  # instrumentation only: the same call, timed
        nonlocal saving
        begin = time.perf_counter()
        save_episode()
        saving += time.perf_counter() - begin

    dataset.save_episode = timed_save_episode
    for rows in episodes:
        write_episode(dataset, rows, "benchmark")
    finalize_start = time.perf_counter()
    dataset.finalize()
    end = time.perf_counter()
    return {"total_s": end - start, "save_episode_s": saving, "finalize_s": end - finalize_start}


def time_recorder(rollout: TensorDictBase, encoder: RGBEncoderConfig, root: Path) -> float:
    start = time.perf_counter()
    with LeRobotRecorder(root, vcodec=encoder.vcodec, crf=encoder.crf) as recorder:
        recorder.write(rollout)
    return time.perf_counter() - start


def our_overheads(rollout: TensorDictBase, repeats: int, spill: Path) -> dict[str, float]:
    """Seconds of the recorder's own work: mapping + validation, and buffering the episodes
    (in memory, as these short episodes are, and spilled to disk, as long ones are)."""
    layout = infer_layout(rollout)
    features = build_features(layout)

    def mapping() -> None:
        check_columns(batch_to_rows(rollout, layout).columns, features, leading=3)

    rows = batch_to_rows(rollout, layout)

    def buffer_round_trip(memory_limit: int) -> None:
        for row in range(rows.shape[0]):
            buffer = EpisodeBuffer(spill, features, "benchmark", 0, memory_limit)
            for step in range(rows.shape[1]):
                buffer.append(rows.step(row, step))
            for item in buffer.rows():
                item["observation.images.front"].sum(dtype=np.uint64)  # touch every page
            buffer.discard()

    return {
        "mapping_and_checks_s": best_of(repeats, lambda: _timed(mapping)),
        "buffer_in_memory_s": best_of(repeats, lambda: _timed(lambda: buffer_round_trip(1 << 40))),
        "buffer_spilled_s": best_of(repeats, lambda: _timed(lambda: buffer_round_trip(0))),
    }


def _timed(work: Callable[[], object]) -> float:
    start = time.perf_counter()
    work()
    return time.perf_counter() - start


def lerobot_per_frame_us(image: np.ndarray, repeats: int = 50) -> dict[str, float]:
    """CPU microseconds per frame of what LeRobot's encoder threads do besides encoding."""

    def per_frame(work: Callable[[], object]) -> float:
        start = time.perf_counter()
        for _ in range(repeats):
            work()
        return (time.perf_counter() - start) / repeats * 1e6

    def update_stats(stats: compute_stats.RunningQuantileStats) -> Callable[[], None]:
        def update() -> None:
            small = auto_downsample_height_width(image.transpose(2, 0, 1))
            stats.update(small.transpose(1, 2, 0).reshape(-1, 3))

        return update

    return {
        "pil_round_trip_us": per_frame(lambda: av.VideoFrame.from_image(Image.fromarray(image))),
        "direct_from_ndarray_us": per_frame(lambda: av.VideoFrame.from_ndarray(image, "rgb24")),
        "frame_copy_us": per_frame(image.copy),
        "running_stats_us": per_frame(update_stats(LEROBOT_STATS())),
        "counted_stats_us": per_frame(update_stats(CountedImageStats())),
    }


def stored_psnr(root: Path, rollout: TensorDictBase) -> float:
    """Mean PSNR (dB) of a few stored front frames against the rollout's originals."""
    dataset = LeRobotDataset("local/bench", root=root, video_backend="pyav")
    values = []
    for index in (1, 2, 3, 5):  # rows 4t+j show frame j-1 of chunk t's next observation
        decoded = dataset[index]["observation.images.front"].permute(1, 2, 0).numpy() * 255
        original = rollout["next", "pixels", "front"][0, index // 4, index % 4 - 1].numpy()
        mse = float(np.mean((decoded.round() - original.astype(np.float64)) ** 2))
        values.append(10 * np.log10(255.0**2 / max(mse, 1e-10)))
    return round(float(np.mean(values)), 2)


def benchmark_codec(
    rollout: TensorDictBase, encoder: RGBEncoderConfig, repeats: int, work: Path
) -> dict:
    layout = infer_layout(rollout)
    rows = batch_to_rows(rollout, layout)
    count, steps = rows.shape
    episodes = [
        [item for step in range(steps) for item in _unstack(rows.step(row, step))]
        for row in range(count)
    ]
    image_keys = [key for key in rows.columns if key.startswith("observation.images.")]
    images = [
        {
            key: rows.columns[key][row].reshape(-1, *rows.columns[key].shape[-3:])
            for key in image_keys
        }
        for row in range(count)
    ]
    total_rows = sum(len(rows_) for rows_ in episodes)

    def fresh(name: str) -> Path:
        path = work / name
        shutil.rmtree(path, ignore_errors=True)
        return path

    floor_dir = work / "floor"
    floor_dir.mkdir(exist_ok=True)
    floor = best_of(repeats, lambda: time_floor(images, encoder, floor_dir))
    features = build_features(layout)
    with lerobot_statistics():
        lerobot = min(
            (time_lerobot(episodes, features, encoder, fresh("lerobot")) for _ in range(repeats)),
            key=lambda timing: timing["total_s"],
        )
        baseline = best_of(repeats, lambda: time_recorder(rollout, encoder, fresh("recorder")))
    recorder = best_of(repeats, lambda: time_recorder(rollout, encoder, fresh("recorder")))
    rate = lambda seconds: round(total_rows / seconds, 1)  # noqa: E731
    return {
        "rows": total_rows,
        "camera_frames": total_rows * len(layout.cameras),
        "floor_rows_per_s": rate(floor),
        "lerobot_rows_per_s": rate(lerobot["total_s"]),
        "recorder_rows_per_s": rate(recorder),
        "recorder_lerobot_stats_rows_per_s": rate(baseline),
        "counted_stats_speedup": round(baseline / recorder, 3),
        "recorder_vs_floor": round(floor / recorder, 3),
        "lerobot_vs_floor": round(floor / lerobot["total_s"], 3),
        "seconds": {
            "floor": round(floor, 3),
            "lerobot_total": round(lerobot["total_s"], 3),
            "lerobot_save_episode": round(lerobot["save_episode_s"], 3),
            "lerobot_finalize": round(lerobot["finalize_s"], 3),
            "recorder_total": round(recorder, 3),
            "recorder_lerobot_stats_total": round(baseline, 3),
        },
        "stored_psnr_db": stored_psnr(work / "recorder", rollout),
        "bytes_per_row": round(
            sum(p.stat().st_size for p in (work / "recorder" / "videos").rglob("*.mp4"))
            / total_rows
        ),
    }


def _unstack(columns: dict[str, np.ndarray]) -> list[dict[str, np.ndarray]]:
    """``key -> [R, ...]`` to R row dicts."""
    length = len(next(iter(columns.values())))
    return [{key: values[index] for key, values in columns.items()} for index in range(length)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-envs", type=int, default=2)
    parser.add_argument("--steps", type=int, default=12, help="chunks per episode")
    parser.add_argument("--width", type=int, default=768)
    parser.add_argument("--height", type=int, default=512)
    parser.add_argument(
        "--codecs", default="h264,libsvtav1", help="codec[:crf],...; default crf: the project's"
    )
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    av.logging.set_libav_level(av.logging.ERROR)
    os.environ.setdefault("SVT_LOG", "1")  # libsvtav1 prints its banner per episode otherwise
    torch.set_num_threads(1)  # the encoders get the cores, as in a recording run
    rollout = record_rollout(args.num_envs, args.steps, args.width, args.height)
    work = Path(tempfile.mkdtemp(prefix="export-bench-"))
    try:
        results = {
            codec: benchmark_codec(rollout, codec_settings(codec), args.repeats, work)
            for codec in args.codecs.split(",")
        }
        frame = rollout["pixels", "front"][0, 0, -1].numpy()
        report = {
            "setup": {
                "resolution": f"{args.width}x{args.height}",
                "num_envs": args.num_envs,
                "steps_per_episode": args.steps,
                "episodes": args.num_envs,
                "cameras": 3,
                "cpu_cores": len(os.sched_getaffinity(0)),
            },
            "codecs": results,
            "lerobot_per_frame_us": {
                k: round(v, 1) for k, v in lerobot_per_frame_us(frame).items()
            },
            "ours_seconds": {
                k: round(v, 3) for k, v in our_overheads(rollout, args.repeats, work).items()
            },
        }
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
