"""SeriesBuffer: bounded buffering of scalar series, sent as columns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

from oasis_torchrl.viz.series import SeriesBuffer

from ._readback import Readback


def test_series_are_sent_at_the_value_limit_and_on_flush(tmp_path: Path) -> None:
    recording = rr.RecordingStream("series-test")
    recording.save(tmp_path / "series.rrd")
    series = SeriesBuffer(recording, fps=20.0, max_delay_s=3600.0, max_values=8)
    series.add("env/0/action/throttle", np.arange(4), [0.0, 0.1, 0.2, np.inf])
    assert series.pending == 4
    series.add("env/0/action/throttle", np.arange(4, 8), np.full(4, 0.5))
    assert series.pending == 0  # 8 values: sent
    series.add("env/0/reward/total", [11], [2.5])
    series.flush()
    recording.flush()
    recording.disconnect()

    readback = Readback(tmp_path / "series.rrd")
    frames, values = readback.scalars("env/0/action/throttle")
    assert frames == list(range(8))
    np.testing.assert_allclose(values, [0.0, 0.1, 0.2, np.nan, 0.5, 0.5, 0.5, 0.5])
    assert readback.scalars("env/0/reward/total") == ([11], [2.5])
    seconds, _ = readback.column("env/0/reward/total", "Scalars:scalars", index="sim_time")
    assert seconds[0].total_seconds() == 11 / 20
