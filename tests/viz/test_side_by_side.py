"""Policies side by side: one recording, a root per policy on one timeline, the divergence
marked; ``oasis-torchrl view A.rrd B.rrd`` and ``oasis-torchrl eval compare=[...]``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from oasis_torchrl.cli import main
from oasis_torchrl.viz import RolloutLogger
from oasis_torchrl.viz.palette import POLICY_COLORS
from oasis_torchrl.viz.side_by_side import SideBySide

from ._readback import Readback, blueprint_count, blueprint_views, chunk_paths, printed
from ._rollouts import CAMERAS, rollout

STEPS = 4
DIVERGES = 2
"""The step (0-based) at which the second policy steers away."""


def _drive(rerun_logger: RolloutLogger, steer_away: bool) -> None:
    """One episode that crashes at its last step; the second policy steers away, and its env
    serves the front crop (not logged by default: a part of the front frame) and a camera more."""
    td = rollout(1, STEPS, {0: [STEPS - 1]})
    if steer_away:
        td["action"][:, DIVERGES:, :, 1] += 0.5
        for key in ("pixels", ("next", "pixels")):
            td[key]["front_crop"] = td[key]["front"].clone()
            td[key]["rear"] = td[key]["front"].clone()
    rerun_logger.log_rollout(td)


def _check_side_by_side(readback: Readback, path: Path, roots: tuple[str, str]) -> None:
    first, second = roots
    for index, root in enumerate(roots):
        entities = {f"{root}/0/camera/{camera}" for camera in CAMERAS}
        entities |= {f"{root}/0/topdown/car", f"{root}/0/events", f"summary/{root}"}
        assert entities <= readback.entities()
        # Both start at frame 0: one shared timeline
        assert readback.images(f"{root}/0/camera/front")[0][0] == 3
        # The signals the policies share a plot for are in the policy's colour, named after it
        packed = int.from_bytes(bytes([*POLICY_COLORS[index], 255]), "big")
        assert readback.static(f"{root}/0/truth/speed", "SeriesLines:colors") == [packed]
        assert readback.static(f"{root}/0/truth/speed", "SeriesLines:names") == [f"{root} speed"]
    frames, texts = readback.texts("divergence/0")
    assert len(texts) == 1 and f"{second} diverges from {first} (by 0.50)" in texts[0]
    assert frames == [4 * (DIVERGES + 1)]  # the first frame of that step
    views = blueprint_views(path)
    for root in roots:
        # Every panel says whose it is; both lines show the same cameras
        for camera in (*CAMERAS, "rear"):
            assert ("2D", f"{root}: {camera}", f"{root}/0/camera/{camera}") in views
        assert f"{root}/0/camera/front_crop" not in readback.entities()
        assert ("2D", f"{root}: top-down", f"{root}/0/topdown") in views
        assert ("TextLog", f"{root}: events", f"{root}/0/events") in views
        assert ("TimeSeries", f"{root}: actions (-1 to 1)", f"{root}/0") in views
    # Speed, distance ahead and reward: one plot each, every policy on the same axes
    for plot in ("speed (m/s)", "distance to obstacle ahead (m)", "reward"):
        assert ("TimeSeries", plot, "/") in views
    assert ("TimeSeries", "lateral offset (m)", "/") not in views  # not in these rollouts
    # Both policies' lines (and collision marks) in the speed plot (the printout cuts it there)
    speed = f"[+ /{first}/0/collision/speed, + /{first}/0/truth/speed, + /{second}/0/collision/"
    assert speed in printed(path)
    assert ("TextLog", "divergence", "divergence/0") in views
    assert ("TextDocument", "episodes", "summary/table") in views


def test_two_policies_share_one_recording_and_their_divergence_is_marked(tmp_path: Path) -> None:
    path = tmp_path / "pair.rrd"
    recording = SideBySide(path, ["autopilot", "bc+ppo"])
    for name in ("autopilot", "bc+ppo"):
        with recording.logger(name) as rerun_logger:
            _drive(rerun_logger, steer_away=name == "bc+ppo")
    recording.close()
    readback = Readback(path)

    _check_side_by_side(readback, path, ("autopilot", "bc_ppo"))
    table = readback.static("summary/table", "TextDocument:text")[0]
    assert "| episode | row | prompt | seed | crashed | autopilot | bc_ppo |" in table
    assert "| 0 | 0 | road 0-0 | 0 | autopilot, bc_ppo |" in table
    assert table.count("**collision (hit an obstacle)** at step 4") == 2
    title = "episode 0: autopilot collision at step 4, bc_ppo collision at step 4"
    assert f"[{title}]" in printed(path)
    assert blueprint_count(path) == 1  # a file gets its layout once, complete
    # ... at its start, then the summary: a viewer lays the file out and shows the summary at
    # once, while it reads the episodes
    order = chunk_paths(path)
    first_summary = next(i for i, p in enumerate(order) if p.startswith("/summary/"))
    first_episode = next(i for i, p in enumerate(order) if p.startswith("/autopilot/"))
    assert order[0].startswith(("/view/", "/container/", "/viewport"))
    assert first_summary < first_episode


def test_view_aligns_two_saved_recordings(tmp_path: Path) -> None:
    for name, steer_away in (("before", False), ("after", True)):
        with RolloutLogger(tmp_path / f"{name}.rrd") as logger:
            _drive(logger, steer_away)
    out = tmp_path / "both.rrd"
    args = ["view", str(tmp_path / "before.rrd"), str(tmp_path / "after.rrd"), "--save", str(out)]
    assert main(args) == 0

    _check_side_by_side(Readback(out), out, ("before", "after"))
    # The tab is named after the episode, read back from each recording's events
    assert "[episode 0: before collision at step 4, after collision at step 4]" in printed(out)
    assert main(["view", str(tmp_path / "before.rrd"), str(tmp_path), "--save", str(out)]) == 2


def test_eval_records_policies_side_by_side_on_the_same_seeds(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "pair.rrd"
    settings = ["episodes=1", "max_steps=3", "env.image_size=[64,96]", "divergence=0.3"]
    policy, other = "constant:throttle=1.0,steering=0.0", "constant:throttle=1.0,steering=0.5"
    settings += [f"policy={policy}", f"compare=[{other!r}]", f"rerun={out}"]
    assert main(["eval", *settings]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["policy"] == policy and list(report["compared"]) == [other]
    readback = Readback(out)

    roots = ("constant_throttle_1_0_steering_0_0", "constant_throttle_1_0_steering_0_5")
    seeds = [readback.texts(f"{root}/0/events")[1][0] for root in roots]
    assert seeds[0] == seeds[1]  # the same prompt and seed
    for root in roots:
        assert readback.images(f"{root}/0/camera/front")[0][0] == 3  # both from the start
    assert readback.texts("divergence/0")[1] == [
        f"step 1: {roots[1]} diverges from {roots[0]} (by 0.50)"
    ]
    assert main(["eval", *settings[:-1]]) == 2  # side by side needs a recording


def test_the_main_job_records_the_final_policy_beside_the_compared_ones(tmp_path: Path) -> None:
    from oasis_torchrl.config import load_config
    from oasis_torchrl.evaluation import side_by_side_for

    cfg = load_config("eval", [f"rerun={tmp_path / 'eval.rrd'}", "compare=[autopilot]"])
    policies = {"autopilot": "autopilot", "constant": "constant", "bc": "out", "bc+ppo": "out"}
    recording = side_by_side_for(cfg, policies)
    assert list(recording.roots) == ["autopilot", "bc"]  # a spec's first name: evaluated once
    recording.close()
    alone = {"constant": "constant", "bc": "out"}
    assert side_by_side_for(cfg, alone) is None  # the final policy alone: recorded as before
