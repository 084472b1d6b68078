"""Settings of the looking commands: ``view`` (rerun) and ``drive`` (a filmed autopilot drive)."""

from __future__ import annotations

from dataclasses import dataclass

from oasis_torchrl.options import REQUIRED, option


def parse_indices(text: str) -> list[int]:
    """``"0,3,5"`` -> ``[0, 3, 5]``.

    Example:
        >>> parse_indices("0, 3,5")
        [0, 3, 5]
        >>> parse_indices("a")
        Traceback (most recent call last):
        ...
        ValueError: expected comma-separated non-negative integers, got 'a'
    """
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        values = []
    if not values or min(values) < 0:
        raise ValueError(f"expected comma-separated non-negative integers, got {text!r}")
    return values


@dataclass
class ViewConfig:
    """``oasis-torchrl view PATH``: an ``.rrd`` (opened in the native viewer), a LeRobot dataset
    folder or a rollout saved with ``oasis_torchrl.viz.replay.save_rollout``, shown in a spawned
    rerun viewer, sent to a running one (``--connect``) or saved (``--save out.rrd``); two
    ``.rrd`` files are laid out side by side."""

    path: str = option(
        REQUIRED,
        help=".rrd file, LeRobot dataset folder or saved rollout folder",
        positional=True,
    )
    beside: str | None = option(
        None,
        help="a second .rrd file: both recordings are laid out side by side on one timeline, "
        "where their actions diverge marked",
        positional=True,
        metavar="B.rrd",
    )
    episodes: list[int] | None = option(
        None, help="dataset episodes to show, e.g. 0,3,5 (null: all)", parse=parse_indices
    )
    rows: list[int] | None = option(
        None, help="rollout env rows to show, e.g. 0,5 (null: all)", parse=parse_indices
    )
    save: str | None = option(None, help="write an .rrd file instead", metavar="OUT.rrd")
    connect: str | None = option(
        None,
        help="send to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy",
        metavar="URL",
    )
    memory_limit: str | None = option(
        None, help="memory limit of a spawned viewer, e.g. 4GB or 50% (null: rerun's 25%)"
    )
    jpeg_quality: int | None = option(
        None, help="JPEG quality 1-100 of frames (null: 85)", ge=1, le=100
    )
    scenes: str | None = option(
        None,
        help="an embedded server (oasis-torchrl serve) to ask a saved rollout's roads and "
        "obstacles for the top-down view, its key in DECART_API_KEY (null: car and path only)",
        metavar="URL",
    )

    def __post_init__(self) -> None:
        if self.save is not None and self.connect is not None:
            raise ValueError("--save and --connect exclude each other: give one")
        if self.beside is not None and "=" in self.beside and not self.beside.endswith(".rrd"):
            raise ValueError(
                f"{self.beside!r} stands where a second .rrd goes: give view's settings as flags "
                "(--rows 0,5), not KEY=VALUE"
            )

    @property
    def target(self) -> str:
        """Where the recording goes: the ``--save`` file, the ``--connect`` URL or a spawned
        viewer."""
        return self.save or self.connect or "spawn"


@dataclass
class FilmConfig:
    """``oasis-torchrl film``: the autopilot drives one route on the embedded server, filmed; the
    three cameras go side by side to an MP4."""

    output: str = option("outputs/film", help="output folder")
    prompt: str = option("urban street, sunset", help="scene prompt")
    seed: int = option(0, help="world seed")
    steps: int = option(60, help="action chunks to drive")
    width: int = option(768, help="camera width")
    height: int = option(512, help="camera height")
