"""The default rerun layout: per row, the cameras side by side, time series below, the top-down
view, depth maps and the event log beside them; one tab per row."""

from __future__ import annotations

from collections.abc import Sequence

import rerun.blueprint as rrb

from oasis_torchrl.viz.paths import ENV_ROOT, RowPaths
from oasis_torchrl.viz.topdown import DEFAULT_WINDOW, Window

BACKGROUND = (30, 34, 30)
"""Background of the top-down view: dark green-grey, off the road."""
RISK_SERIES = ("reward/collision_risk", "reward/near_fraction", "truth/collided", "truth/off_road")
"""Series shown in the risk plot (and kept out of the reward and truth plots)."""


def _series_view(
    name: str, paths: RowPaths, include: Sequence[str], exclude: Sequence[str] = ()
) -> rrb.TimeSeriesView:
    contents = [f"+ $origin/{path}" for path in include]
    contents += [f"- $origin/{path}" for path in exclude]
    return rrb.TimeSeriesView(origin=paths.base, contents=contents, name=name)


def _time_series(paths: RowPaths) -> rrb.Horizontal:
    return rrb.Horizontal(
        _series_view("actions", paths, ("action/**", "state/**")),
        _series_view("reward", paths, ("reward/**",), RISK_SERIES),
        _series_view("collision risk", paths, RISK_SERIES),
        _series_view("truth", paths, ("truth/**",), RISK_SERIES),
    )


def topdown_view(paths: RowPaths, window: Window = DEFAULT_WINDOW) -> rrb.Spatial2DView:
    """The top-down view: its bounds are the window around the car (the map is logged in the
    car's frame, so the window follows the car).

    Example:
        >>> type(topdown_view(RowPaths("env", 0))).__name__
        'Spatial2DView'
    """
    return rrb.Spatial2DView(
        origin=paths.topdown(),
        name="top-down",
        visual_bounds=rrb.VisualBounds2D(x_range=window.x_range, y_range=window.y_range),
        background=BACKGROUND,
    )


def _side_panel(
    paths: RowPaths, depth_cameras: Sequence[str], topdown: Window | None
) -> rrb.Vertical:
    views: list = [topdown_view(paths, topdown)] if topdown is not None else []
    views += [
        rrb.Spatial2DView(origin=paths.depth(camera), name=f"depth {camera}")
        for camera in depth_cameras
    ]
    views.append(rrb.TextLogView(origin=paths.events, name="events"))
    # The top-down view gets the most room: the map has to be read at a glance.
    shares = [3 if topdown is not None and i == 0 else 1 for i in range(len(views))]
    return rrb.Vertical(*views, row_shares=shares)


def row_layout(
    paths: RowPaths,
    cameras: Sequence[str],
    depth_cameras: Sequence[str] = (),
    topdown: Window | None = DEFAULT_WINDOW,
) -> rrb.Horizontal:
    """The layout of one row: cameras over time series, side panel on the right.

    Example:
        >>> layout = row_layout(RowPaths("env", 0), ["left_forward", "front", "right_forward"])
        >>> type(layout).__name__
        'Horizontal'
    """
    cameras_row = rrb.Horizontal(
        *(rrb.Spatial2DView(origin=paths.camera(camera), name=camera) for camera in cameras)
    )
    main = rrb.Vertical(cameras_row, _time_series(paths), row_shares=[3, 2])
    return rrb.Horizontal(
        main,
        _side_panel(paths, depth_cameras, topdown),
        column_shares=[3, 1],
        name=f"{paths.root} {paths.row}",
    )


def default_blueprint(
    rows: Sequence[int],
    cameras: Sequence[str],
    *,
    root: str = ENV_ROOT,
    depth_cameras: Sequence[str] = (),
    topdown: Window | None = DEFAULT_WINDOW,
) -> rrb.Blueprint:
    """One tab per logged row (a single row gets no tabs).

    Args:
        rows: the logged rows (env rows or dataset episode indices).
        cameras: camera names, left to right.
        root: entity root (``env`` for rollouts, ``episode`` for datasets).
        depth_cameras: cameras with depth maps.
        topdown: the top-down view's window around the car; None leaves the view out.

    Example:
        >>> blueprint = default_blueprint([0, 5], ["front"])
        >>> type(blueprint).__name__
        'Blueprint'
    """
    if not rows:
        raise ValueError("default_blueprint needs at least one row")
    layouts = [row_layout(RowPaths(root, row), cameras, depth_cameras, topdown) for row in rows]
    container = layouts[0] if len(layouts) == 1 else rrb.Tabs(*layouts, active_tab=0)
    return rrb.Blueprint(container)
