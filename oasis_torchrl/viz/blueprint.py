"""The default rerun layout: a summary tab, then one tab per row, named after its episodes
(:mod:`~oasis_torchrl.viz.titles`): the cameras side by side, the plots below them (one unit
each, :data:`~oasis_torchrl.viz.palette.PLOTS`), the top-down view, depth maps and the event log
beside them. The time panel opens at the start of the ``frame`` timeline.

Every panel's title starts with its ``owner`` (:func:`~oasis_torchrl.viz.titles.panel_title`):
the policy whose episodes it shows, or the dataset or robot where there is no policy, alone or
side by side, so every panel says whose it is."""

from __future__ import annotations

import inspect
from collections.abc import Collection, Sequence
from dataclasses import dataclass

import rerun.blueprint as rrb

from oasis_torchrl.viz.palette import PLOTS
from oasis_torchrl.viz.paths import ENV_ROOT, FRAME_TIMELINE, RowPaths
from oasis_torchrl.viz.summary import SUMMARY_ROOT, TABLE, chart_path
from oasis_torchrl.viz.titles import RowEpisodes, panel_title, tab_title
from oasis_torchrl.viz.topdown import DEFAULT_WINDOW, Window

BACKGROUND = (30, 34, 30)
"""Background of the top-down view: dark green-grey, off the road."""
PLOTS_PER_LINE = 3


def plot_views(
    paths: RowPaths, signals: Collection[str] | None = None, owner: str = ""
) -> rrb.Vertical | None:
    """The row's plots that show at least one of ``signals`` (palette keys such as
    ``truth/speed``; None: every plot), three to a line, titled with their ``owner``; None if
    there is none.

    Example:
        >>> views = plot_views(RowPaths("env", 0), {"action/throttle", "truth/speed"}, "bc")
        >>> [view.name for line in views.contents for view in line.contents]
        ['bc: actions (-1 to 1)', 'bc: speed (m/s)']
    """
    chosen = [plot for plot in PLOTS if signals is None or any(plot.shows(key) for key in signals)]
    views = [
        rrb.TimeSeriesView(
            origin=paths.base, contents=plot.contents(), name=panel_title(owner, plot.title)
        )
        for plot in chosen
    ]
    if not views:
        return None
    lines = [views[i : i + PLOTS_PER_LINE] for i in range(0, len(views), PLOTS_PER_LINE)]
    return rrb.Vertical(*(rrb.Horizontal(*line) for line in lines))


def topdown_view(
    paths: RowPaths, window: Window = DEFAULT_WINDOW, owner: str = ""
) -> rrb.Spatial2DView:
    """The top-down view: its bounds are the window around the car (the map is logged in the
    car's frame, so the window follows the car).

    Example:
        >>> type(topdown_view(RowPaths("env", 0))).__name__
        'Spatial2DView'
    """
    return rrb.Spatial2DView(
        origin=paths.topdown(),
        name=panel_title(owner, "top-down"),
        visual_bounds=rrb.VisualBounds2D(x_range=window.x_range, y_range=window.y_range),
        background=BACKGROUND,
    )


def camera_views(paths: RowPaths, cameras: Sequence[str], owner: str = "") -> rrb.Horizontal:
    """The row's cameras, left to right (each image scaled to its panel by the viewer), titled
    with their ``owner``.

    Example:
        >>> views = camera_views(RowPaths("env", 0), ["left_forward", "front"], "autopilot")
        >>> [view.name for view in views.contents]
        ['autopilot: left_forward', 'autopilot: front']
    """
    return rrb.Horizontal(
        *(
            rrb.Spatial2DView(origin=paths.camera(camera), name=panel_title(owner, camera))
            for camera in cameras
        )
    )


def events_view(paths: RowPaths, owner: str = "") -> rrb.TextLogView:
    """The row's event log (episode starts and ends, collisions), titled with its ``owner``.

    Example:
        >>> events_view(RowPaths("env", 0), "autopilot").name
        'autopilot: events'
    """
    return rrb.TextLogView(origin=paths.events, name=panel_title(owner, "events"))


def _side_panel(
    paths: RowPaths, depth_cameras: Sequence[str], topdown: Window | None, owner: str
) -> rrb.Vertical:
    views: list = [topdown_view(paths, topdown, owner)] if topdown is not None else []
    views += [
        rrb.Spatial2DView(origin=paths.depth(camera), name=panel_title(owner, f"depth {camera}"))
        for camera in depth_cameras
    ]
    views.append(events_view(paths, owner))
    # The top-down view gets the most room: the map has to be read at a glance.
    shares = [3 if topdown is not None and i == 0 else 1 for i in range(len(views))]
    return rrb.Vertical(*views, row_shares=shares)


def row_layout(
    paths: RowPaths,
    cameras: Sequence[str],
    depth_cameras: Sequence[str] = (),
    topdown: Window | None = DEFAULT_WINDOW,
    signals: Collection[str] | None = None,
    title: str | None = None,
    owner: str = "",
) -> rrb.Horizontal:
    """The layout of one row, titled ``title`` (default ``row <row>``): cameras over plots (those
    with signals), side panel on the right, every panel titled with its ``owner``.

    Example:
        >>> layout = row_layout(RowPaths("env", 0), ["left_forward", "front", "right_forward"])
        >>> type(layout).__name__
        'Horizontal'
    """
    plots = plot_views(paths, signals, owner)
    cameras_row = camera_views(paths, cameras, owner)
    # 2 to 3: three 3:2 cameras across fill their panels on a wide screen, without black bars.
    main = cameras_row if plots is None else rrb.Vertical(cameras_row, plots, row_shares=[2, 3])
    return rrb.Horizontal(
        main,
        _side_panel(paths, depth_cameras, topdown, owner),
        column_shares=[3, 1],
        name=title or tab_title(paths.row, {}),
    )


def summary_layout(roots: Sequence[str], owners: Sequence[str] | None = None) -> rrb.Vertical:
    """The summary tab: the table of episodes over one bar chart per policy (root), each titled
    with its owner (where unnamed: its root); a single owner's table too (several policies'
    table names them in its columns).

    Example:
        >>> tab = summary_layout(["env"], ["autopilot"])
        >>> tab.name, [view.name for view in tab.contents[:1]]
        ('summary', ['autopilot: episodes'])
    """
    owners = owners or [""] * len(roots)
    charts = [
        rrb.BarChartView(
            origin=chart_path(root),
            name=panel_title(owner or root, "distance driven in m (or return) by episode number"),
        )
        for root, owner in zip(roots, owners, strict=True)
    ]
    table_owner = owners[0] if len(owners) == 1 else ""
    table = rrb.TextDocumentView(origin=TABLE, name=panel_title(table_owner, "episodes"))
    return rrb.Vertical(table, rrb.Horizontal(*charts), row_shares=[2, 1], name=SUMMARY_ROOT)


def time_panel(fps: float | None = None) -> rrb.TimePanel:
    """The time panel: the ``frame`` timeline from its start (the viewer's default follows the
    end of the data).

    Example:
        >>> type(time_panel()).__name__
        'TimePanel'
    """
    # rerun-sdk 0.26's time panel takes a cursor; newer ones have none, but a panel set to
    # "playing" starts from the beginning, and looping brings a cursor left at the end (a file's
    # layout comes last) back to it.
    if "play_state" in inspect.signature(rrb.TimePanel).parameters:
        start: dict = {"play_state": "playing", "loop_mode": "all"}
    else:
        start = {"sequence_cursor": 0}
    return rrb.TimePanel(timeline=FRAME_TIMELINE, fps=fps, **start)


def default_blueprint(
    rows: Sequence[int],
    cameras: Sequence[str],
    *,
    root: str = ENV_ROOT,
    depth_cameras: Sequence[str] = (),
    topdown: Window | None = DEFAULT_WINDOW,
    signals: Collection[str] | None = None,
    summary: bool = False,
    fps: float | None = None,
    titles: Sequence[str] | None = None,
    owner: str = "",
) -> rrb.Blueprint:
    """A summary tab (when ``summary``) and one tab per logged row (a single row and no summary
    get no tabs).

    Args:
        rows: the logged rows (env rows or dataset episode indices).
        cameras: camera names, left to right.
        root: entity root (``env`` for rollouts, ``episode`` for datasets).
        depth_cameras: cameras with depth maps.
        topdown: the top-down view's window around the car; None leaves the view out.
        signals: the logged signals' palette keys (which plots to show; None: all).
        summary: add the summary tab (ended episodes exist).
        fps: the frame timeline's playback rate (frames per second).
        titles: each row's tab title (default ``row <row>``).
        owner: whose episodes these are (the policy's, dataset's or robot's name), which every
            panel's title starts with (none: the panels' own names alone).

    Example:
        >>> blueprint = default_blueprint([0, 5], ["front"])
        >>> type(blueprint).__name__
        'Blueprint'
    """
    if not rows:
        raise ValueError("default_blueprint needs at least one row")
    titles = titles or [None] * len(rows)
    layouts = [
        row_layout(RowPaths(root, row), cameras, depth_cameras, topdown, signals, title, owner)
        for row, title in zip(rows, titles, strict=True)
    ]
    if summary:
        layouts.insert(0, summary_layout([root], [owner]))
    container = layouts[0] if len(layouts) == 1 else rrb.Tabs(*layouts, active_tab=0)
    return rrb.Blueprint(container, time_panel(fps))


@dataclass(frozen=True)
class RowsLayout:
    """What a writer has logged so far, all its layout depends on (``episodes``: each row's,
    for its tab's title; ``owner``: whose episodes they are, for every panel's title).

    Example:
        >>> layout = RowsLayout("env", (0,), ("front",), (), None, frozenset(), False)
        >>> type(layout.blueprint(fps=20.0)).__name__
        'Blueprint'
    """

    root: str
    rows: tuple[int, ...]
    cameras: tuple[str, ...]
    depth_cameras: tuple[str, ...]
    topdown: Window | None
    signals: frozenset[str]
    summary: bool
    episodes: tuple[RowEpisodes, ...] = ()
    owner: str = ""

    def row_episodes(self, row: int) -> RowEpisodes:
        """The episodes row ``row`` has shown (none if unknown)."""
        if row not in self.rows or not self.episodes:
            return RowEpisodes()
        return self.episodes[self.rows.index(row)]

    def blueprint(self, fps: float | None = None) -> rrb.Blueprint:
        """The default blueprint of these rows."""
        return default_blueprint(
            self.rows,
            self.cameras,
            root=self.root,
            depth_cameras=self.depth_cameras,
            topdown=self.topdown,
            signals=self.signals,
            summary=self.summary,
            fps=fps,
            titles=[tab_title(row, {self.root: self.row_episodes(row)}) for row in self.rows],
            owner=self.owner,
        )
