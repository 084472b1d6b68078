"""Episodes end where they end, and every signal keeps its name and colour: recordings of an
evaluation-like drive (finished rows keep being stepped until every row is done), read back."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
import rerun as rr
import torch
from tensordict import TensorDict

from oasis_torchrl.viz import LogOptions, RolloutLogger
from oasis_torchrl.viz.palette import SIGNALS
from oasis_torchrl.viz.summary import EpisodeOutcome, EpisodeSummary

from ._readback import Readback, printed
from ._rollouts import observation

STEPS = 6
ENDS = {0: (1, "collision"), 1: (3, "depth"), 2: (5, "time")}
"""Row -> (the step its episode ends at, how): a collision (ground truth), the depth risk
reaching 1 (terminated, no collision), the time limit (truncated)."""


def _step(t: int, truth: bool) -> tuple[TensorDict, torch.Tensor]:
    """The ``"next"`` observation of step ``t`` and its action; a row that ended stays done."""
    rows = len(ENDS)
    collided = [ENDS[r] == (t, "collision") for r in range(rows)]
    nxt = observation(t, [0] * rows, reset=False, collided=collided)
    risk = [1.0 if ENDS[r] == (t, "depth") else 0.5 for r in range(rows)]
    nxt["reward_terms", "collision_risk"] = torch.tensor(risk)[:, None]
    nxt["truth", "distance"] = (2.0 * t + torch.arange(4.0)).expand(rows, 4).clone()
    ended = torch.tensor([t >= ENDS[r][0] for r in range(rows)])[:, None]
    truncated = torch.tensor([t >= ENDS[r][0] and ENDS[r][1] == "time" for r in range(rows)])
    nxt["reward"] = torch.ones(rows, 1)
    nxt["terminated"] = ended & ~truncated[:, None]
    nxt["truncated"] = truncated[:, None]
    nxt["done"] = ended
    if not truth:
        nxt = nxt.exclude("truth")
    return nxt, torch.full((rows, 4, 2), 0.5)


def _record(path: Path, truth: bool = True, **options: object) -> Readback:
    reset = observation(0, [0] * len(ENDS), reset=True)
    with RolloutLogger(path, LogOptions(**options)) as rerun_logger:
        rerun_logger.log_reset(reset if truth else reset.exclude("truth"))
        for t in range(STEPS):
            rerun_logger.log_step(*_step(t, truth))
    return Readback(path)


def _saved_evaluation() -> TensorDict:
    """The same drive as a rollout ``[N, T]`` (what ``rollout_episodes`` returns): a finished
    row's root observation is its last one, still ``done``."""
    root = observation(0, [0] * len(ENDS), reset=True)
    root["done"] = torch.zeros(len(ENDS), 1, dtype=torch.bool)
    root["truth", "distance"] = torch.zeros(len(ENDS), 4)
    steps = []
    for t in range(STEPS):
        nxt, action = _step(t, truth=True)
        steps.append(root.clone().update({"action": action, "next": nxt}))
        root = nxt.exclude("reward", "terminated", "truncated")
    return torch.stack(steps, dim=1)


def _last_frame(end: int) -> int:
    return 4 * (end + 1) + 3  # tick 0 is the reset; step t is tick t + 1


@pytest.mark.parametrize("way_in", ["steps", "saved rollout"])
def test_nothing_is_logged_for_a_row_after_its_episode_ends(tmp_path: Path, way_in: str) -> None:
    if way_in == "steps":  # an evaluation's recorder
        readback = _record(tmp_path / "eval.rrd")
    else:  # oasis-torchrl view of a saved evaluation
        with RolloutLogger(tmp_path / "eval.rrd") as rerun_logger:
            rerun_logger.log_rollout(_saved_evaluation())
        readback = Readback(tmp_path / "eval.rrd")

    expected = {
        0: ("ERROR", "collision (hit an obstacle) after 2 steps, 5.0 m, return 2.000"),
        1: ("WARN", "likely collision (depth risk 1.00) after 4 steps, 9.0 m, return 4.000"),
        2: ("INFO", "time limit after 6 steps, 13.0 m, return 6.000"),
    }
    for row, (level, text) in expected.items():
        end = _last_frame(ENDS[row][0])
        # The end event and the episode's last data share its last frame; nothing comes after.
        assert readback.frames(f"env/{row}")[-1] == end
        assert readback.scalars(f"env/{row}/action/throttle")[0][-1] == end
        assert readback.scalars(f"env/{row}/reward/total")[0][-1] == end
        assert readback.images(f"env/{row}/camera/front")[0][-1] == end
        assert readback.column(f"env/{row}/topdown/car", "LineStrips2D:strips")[0][-1] == end
        frames, texts = readback.texts(f"env/{row}/events")
        assert texts == [  # rows start together: episode numbers in row order
            f"episode {row} starts: 'road {row}-0', seed {100 * row}",
            f"episode {row} ends: {text}",
        ]
        assert frames == [0, end]
        assert readback.column(f"env/{row}/events", "TextLog:level")[1][-1] == [level]
    # The collision itself is marked on the speed and distance plots, at its own frame
    assert readback.scalars("env/0/collision/speed") == ([10], [1.0])
    assert readback.scalars("env/0/collision/obstacle_distance") == ([10], [0.0])
    assert "env/1/collision/speed" not in readback.entities()  # no collision: no mark
    table = readback.static("summary/table", "TextDocument:text")[0]
    assert table.splitlines()[0] == "| episode | row | prompt | seed | crashed | env |"
    lines = [
        "| 0 | 0 | road 0-0 | 0 | env | **collision (hit an obstacle)** at step 2, 5.0 m, "
        "frames 0-11 |",
        "| 1 | 1 | road 1-0 | 100 | env | **likely collision (depth risk 1.00)** at step 4, "
        "9.0 m, frames 0-19 |",
        "| 2 | 2 | road 2-0 | 200 | - | time limit at step 6, 13.0 m, frames 0-27 |",
    ]
    assert table.splitlines()[2:] == lines
    # A bar per episode, at its number: the distance it drove
    assert readback.static("summary/env", "BarChart:abscissa")[0]["buffer"] == [0, 1, 2]
    assert readback.static("summary/env", "BarChart:values")[0]["buffer"] == [5.0, 9.0, 13.0]


def test_every_signal_has_its_fixed_name_and_colour(tmp_path: Path) -> None:
    first = _record(tmp_path / "first.rrd")
    second = _record(tmp_path / "second.rrd", rows=(2,))

    keys = ("action/throttle", "action/steering", "reward/total", "reward/collision_risk")
    keys += ("truth/speed", "truth/obstacle_distance")
    colors = set()
    for key in keys:
        signal = SIGNALS[key]
        packed = int.from_bytes(bytes([*signal.color, 255]), "big")
        for readback, row in ((first, 0), (first, 2), (second, 2)):
            entity = f"env/{row}/{key}"
            assert readback.static(entity, "SeriesLines:names") == [signal.name]
            assert readback.static(entity, "SeriesLines:colors") == [packed]
        colors.add(packed)
    assert len(colors) == len(keys)  # no two signals share a colour
    assert first.static("env/0/topdown/scale", "LineStrips2D:labels") == ["10 m"]


def test_frames_only_recordings_have_no_truth_and_still_end(tmp_path: Path) -> None:
    readback = _record(tmp_path / "hosted.rrd", truth=False)

    assert not any("/topdown/" in e or "/truth/" in e for e in readback.entities())
    assert readback.frames("env/1")[-1] == _last_frame(ENDS[1][0])
    ends = [readback.texts(f"env/{row}/events")[1][-1] for row in ENDS]
    assert ends == [
        "episode 0 ends: terminated after 2 steps, return 2.000",
        "episode 1 ends: likely collision (depth risk 1.00) after 4 steps, return 4.000",
        "episode 2 ends: time limit after 6 steps, return 6.000",
    ]
    table = readback.static("summary/table", "TextDocument:text")[0]
    assert "| 0 | 0 | road 0-0 | 0 | - | terminated at step 2, return 2.00, frames 0-11 |" in table


def test_periodic_evaluations_number_their_episodes_on(tmp_path: Path) -> None:
    """PPO evaluates with one evaluator, again and again, into one recording: each evaluation's
    episodes get the next numbers, and a row's tab names both of its episodes."""
    from oasis_torchrl.config import load_config
    from oasis_torchrl.drivers import ScriptedDriver
    from oasis_torchrl.evaluation import Evaluator

    path = tmp_path / "evaluations.rrd"
    settings = ["episodes=2", "max_steps=2", "env.image_size=[64,96]", f"rerun={path}"]
    cfg = load_config("eval", settings)
    with Evaluator(cfg.env, cfg, progress=False) as evaluator:
        for _ in range(2):
            evaluator.evaluate(ScriptedDriver.from_spec("throttle=1"))
    readback = Readback(path)

    frames, texts = readback.texts("env/1/events")
    assert [text.split(":")[0] for text in texts] == [
        "episode 1 starts",
        "episode 1 ends",
        "episode 3 starts",
        "episode 3 ends",
    ]
    assert frames == [0, 11, 12, 23]  # the second evaluation from tick max_steps + 1
    assert "[episode 1: time limit at step 2; episode 3: time limit at step 2]" in printed(path)


def test_the_first_episode_of_a_summary_logs_without_a_warning() -> None:
    """Every recording's summary starts with a chart of one bar, which rerun's 1-D check (it
    counts the dimensions longer than 1) would warn about."""
    summary = EpisodeSummary(rr.RecordingStream("one-episode"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        summary.add(EpisodeOutcome("env", 0, 0, "urban", 7, 0, 239, 59, "collision", "", 1.0, 0.1))
    assert [str(warning.message) for warning in caught] == []
