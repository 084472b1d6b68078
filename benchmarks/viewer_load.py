"""Seconds until rerun's web viewer shows an evaluation's summary: the recording as written
(its final layout first, the summary next: ``oasis_torchrl.viz.recording.layout_first``) against
the same recording in the order it was logged (the baseline: layout and summary at its end).

Two policies (``--policy`` beside ``--compare``; by default the main job's pair, the shipped
clone beside the autopilot) are evaluated on the same seeds and recorded side by side, as
``oasis-torchrl eval policy=... compare=[...] rerun=eval.rrd`` does: a small evaluation by
default, the main job's ``eval.rrd`` with ``--episodes 16 --max-steps 150``. The benchmark wraps
the rewrite to copy the file just before it (the product has no option to skip it), so both
files hold the same chunks. Each is then opened in rerun's web viewer (``rerun --serve-web``) in
headless Chromium (WebGL on the CPU) and timed from the page's request until the summary's
table of episodes shows its rows (the probe of ``tests/web/test_rerun_viewer.py``, shared in
``tests/web/_viewer.py``), ``--repeats`` times each, alternating which goes first, after one
untimed opening that loads the viewer's own code. The report gives each file's size, bytes per
episode-step, the median seconds to the summary, and the ratios as written / as logged.

Needs Debian's ``chromium`` and ``chromium-driver``, Selenium (the ``dev`` extra) and rerun-sdk
0.32 or newer (its web viewer, and the reader the rewrite uses); without them it exits with an
error that says what is missing. Target: the main job's ``eval.rrd`` shows its summary within
15 s.

Usage: ``python benchmarks/viewer_load.py [--episodes 4 --max-steps 60 --repeats 1]``; prints
JSON.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import statistics
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any
from unittest import mock

import rerun as rr

from oasis_torchrl.config import load_config
from oasis_torchrl.drivers import load_driver
from oasis_torchrl.evaluation import evaluate_side_by_side
from oasis_torchrl.viz import side_by_side
from oasis_torchrl.viz.recording import layout_first

TESTS = Path(__file__).resolve().parents[1] / "tests"
TARGET_SUMMARY_S = 15.0
"""The main job's ``eval.rrd`` (16 episodes x 2 policies x up to 150 steps) shows its summary
within this many seconds."""
WAYS = ("written", "logged")
"""The recording as written (layout first, summary next) and as logged (the baseline)."""


def viewer_helpers() -> ModuleType:
    """``tests/web/_viewer.py``: the browser, the web viewer and the summary's probe."""
    if str(TESTS) not in sys.path:
        sys.path.insert(0, str(TESTS))
    from web import _viewer

    return _viewer


def record(
    folder: Path, policy: str, compare: str, episodes: int, max_steps: int
) -> tuple[dict[str, Path], int]:
    """Evaluate ``policy`` beside ``compare`` into ``folder/written.rrd``, keeping the file as
    logged, before its rewrite, in ``folder/logged.rrd``; returns both and the episode-steps."""
    paths = {way: folder / f"{way}.rrd" for way in WAYS}
    settings = [f"episodes={episodes}", f"max_steps={max_steps}", f"rerun={paths['written']}"]
    cfg = load_config("eval", [*settings, "progress=false"])
    rewritten = []

    def keep_logged(path: Path, blueprint: Any, first: Sequence[str] = ()) -> bool:
        shutil.copyfile(path, paths["logged"])
        rewritten.append(layout_first(path, blueprint, first))
        return rewritten[-1]

    drivers = {spec: load_driver(spec) for spec in (policy, compare)}
    with mock.patch.object(side_by_side, "layout_first", keep_logged):
        reports = evaluate_side_by_side(cfg.env, cfg, drivers, progress=False)
    if rewritten != [True]:
        raise SystemExit(
            f"viewer_load: rerun-sdk {rr.__version__} cannot rewrite a recording (0.32 or newer "
            "reads files back): there is no layout-first file to time"
        )
    steps = sum(episode.steps for report in reports.values() for episode in report.episodes)
    return paths, steps


def time_openings(
    browser: Any,
    url: Callable[[str | None], str],
    paths: dict[str, Path],
    repeats: int,
    within_s: float,
) -> tuple[float | None, dict[str, list[float | None]]]:
    """The untimed first opening's seconds (the viewer's code loaded), then each way's seconds
    to the summary, ``repeats`` times, alternating which goes first (None: not within
    ``within_s``)."""
    viewer = viewer_helpers()
    first, _ = viewer.open_on_table(browser, url(paths["written"].name), within_s)
    seconds: dict[str, list[float | None]] = {way: [] for way in WAYS}
    for repeat in range(repeats):
        for way in WAYS if repeat % 2 else WAYS[::-1]:
            browser.get("about:blank")  # the last viewer unloads before the clock starts
            found, _ = viewer.open_on_table(browser, url(paths[way].name), within_s)
            seconds[way].append(None if found is None else round(found, 2))
    return None if first is None else round(first, 2), seconds


def median(values: list[float | None]) -> float | None:
    """The median of ``values``; None if one of them is None (not shown in time).

    Example:
        >>> median([3.0, 1.0, 2.0]), median([1.0, None])
        (2.0, None)
    """
    return None if None in values else statistics.median(values)


def ratio(a: float | None, b: float | None) -> float | None:
    """``a / b`` to 3 places, or None where either is missing."""
    return None if a is None or not b else round(a / b, 3)


def parse_arguments(argv: list[str] | None = None) -> argparse.Namespace:
    """The flags of ``argv`` (default: the process's)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="pretrained:clone", help="the evaluated policy")
    parser.add_argument("--compare", default="autopilot", help="the policy beside it")
    parser.add_argument("--episodes", type=int, default=4, help="episodes per policy")
    parser.add_argument("--max-steps", type=int, default=60, help="steps per episode at most")
    parser.add_argument("--repeats", type=int, default=1, help="timed openings of each file")
    parser.add_argument(
        "--within", type=float, default=300.0, help="seconds an opening may take at most"
    )
    return parser.parse_args(argv)


def main() -> None:
    """Record, open both files in the viewer, print the report."""
    args = parse_arguments()
    viewer = viewer_helpers()
    missing = viewer.missing_browser()
    if missing is not None:
        raise SystemExit(f"viewer_load needs headless Chromium: {missing}")
    with tempfile.TemporaryDirectory() as name, contextlib.ExitStack() as stack:
        folder = Path(name)
        try:  # the viewer and the browser first: a missing one is said before the evaluation
            url = stack.enter_context(viewer.web_viewer(folder))
            browser = stack.enter_context(viewer.headless_chromium())
        except Exception as error:  # said as it is: no viewer, no benchmark
            raise SystemExit(f"viewer_load cannot open rerun's web viewer: {error}") from None
        paths, steps = record(folder, args.policy, args.compare, args.episodes, args.max_steps)
        load_before = os.getloadavg()
        first, seconds = time_openings(browser, url, paths, args.repeats, args.within)
        load_after = os.getloadavg()
        sizes = {way: path.stat().st_size for way, path in paths.items()}
    medians = {way: median(values) for way, values in seconds.items()}
    written = medians["written"]
    report = {
        "benchmark": "viewer_load",
        "rerun_sdk": rr.__version__,
        "policies": [args.policy, args.compare],
        "episodes": args.episodes,
        "max_steps": args.max_steps,
        "episode_steps": steps,
        **{f"{way}_bytes": sizes[way] for way in WAYS},
        **{f"{way}_bytes_per_episode_step": round(sizes[way] / steps) for way in WAYS},
        "size_ratio": ratio(sizes["written"], sizes["logged"]),
        **{f"{way}_summary_s": seconds[way] for way in WAYS},
        **{f"{way}_summary_median_s": medians[way] for way in WAYS},
        "summary_time_ratio": ratio(written, medians["logged"]),
        "first_opening_s": first,
        "load_average": [round(load_before[0], 2), round(load_after[0], 2)],
        "target_main_job_summary_s": TARGET_SUMMARY_S,
        "meets_target": written is not None and written <= TARGET_SUMMARY_S,
    }
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
