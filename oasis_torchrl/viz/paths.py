"""Entity paths and timelines of oasis recordings (so logger, replay and blueprint agree).

Every env row (or replayed dataset episode) lives under ``<root>/<row>``:

=====================================  ==============  ==========================================
entity                                 archetype       what
=====================================  ==============  ==========================================
``<root>/<row>/camera/<camera>``       EncodedImage    camera frames (JPEG by default, as served)
                                                       or Image
``<root>/<row>/depth/<camera>``        DepthImage      metric depth (metres; sky and unknown 0)
``<root>/<row>/action/<name>``         Scalars         ``throttle`` and ``steering``, one per frame
``<root>/<row>/reward/total``          Scalars         the step reward
``<root>/<row>/reward/<term>``         Scalars         each reward term (``collision_risk``, ...)
``<root>/<row>/truth/<field>``         Scalars         embedded-server ground truth per frame
``<root>/<row>/collision/<field>``     Scalars         ``speed`` and ``obstacle_distance`` at a
                                                       collision's frame (a cross on their plots)
``<root>/<row>/state/<name>``          Scalars         ``observation.state`` of replayed datasets
``<root>/<row>/events``                TextLog         episode starts (prompt, seed), episode
                                                       ends (cause, figures; on the episode's
                                                       last frame)
``<root>/<row>/topdown/road``          LineStrips2D    the road surface near the car (one thick
                                                       strip along the centreline)
``<root>/<row>/topdown/lanes``         LineStrips2D    road edges and lane lines (dashed)
``<root>/<row>/topdown/obstacles``     LineStrips2D    obstacles, filled to size (one thick
                                                       segment each)
``<root>/<row>/topdown/path``          LineStrips2D    the car's recent path
``<root>/<row>/topdown/car``           LineStrips2D    the car, filled (red after a collision)
``<root>/<row>/topdown/scale``         LineStrips2D    a 10 m scale bar (static)
``summary/table``                      TextDocument    every ended episode's outcome (static)
``summary/<root>``                     BarChart        each episode's distance (or return)
``divergence/<row>``                   TextLog         side by side: where the policies diverge
=====================================  ==============  ==========================================

``<root>`` is ``env`` for env rows, ``episode`` for dataset episodes, and each policy's own root
in a side-by-side recording (:mod:`oasis_torchrl.viz.side_by_side`). Every scalar entity also
holds its static ``SeriesLines`` style (:mod:`oasis_torchrl.viz.palette`).

The top-down layers are in the car's frame (x metres to its right, y metres behind it), logged
every step, so the view's fixed bounds follow the car.

Timelines: ``frame`` (sequence: world frames, 4 per env step), ``step`` (sequence: env steps,
``frame // 4``, the steps events speak of) and ``sim_time`` (duration: ``frame / fps``), set
together by :mod:`oasis_torchrl.viz.timelines`.
"""

from __future__ import annotations

from dataclasses import dataclass

FRAME_TIMELINE = "frame"
"""Sequence timeline: the world frame index."""
TIME_TIMELINE = "sim_time"
"""Duration timeline: simulated seconds (``frame / fps``)."""
STEP_TIMELINE = "step"
"""Sequence timeline: the env step (``frame // 4``; a dataset's own steps when replayed)."""
ENV_ROOT = "env"
"""Root of live env rows."""
EPISODE_ROOT = "episode"
"""Root of replayed dataset episodes."""


@dataclass(frozen=True)
class RowPaths:
    """Entity paths of one row.

    Example:
        >>> paths = RowPaths("env", 5)
        >>> paths.camera("front"), paths.scalar("reward", "total")
        ('env/5/camera/front', 'env/5/reward/total')
    """

    root: str
    row: int

    @property
    def base(self) -> str:
        """The row's own entity, parent of everything it logs."""
        return f"{self.root}/{self.row}"

    def camera(self, camera: str) -> str:
        """Frames of ``camera``."""
        return f"{self.base}/camera/{camera}"

    def depth(self, camera: str) -> str:
        """Depth map of ``camera``."""
        return f"{self.base}/depth/{camera}"

    def scalar(self, group: str, name: str) -> str:
        """A time series: ``group`` is ``action``, ``reward``, ``truth`` or ``state``."""
        return f"{self.base}/{group}/{name}"

    @property
    def events(self) -> str:
        """The row's text log."""
        return f"{self.base}/events"

    def topdown(self, layer: str = "") -> str:
        """The top-down map (``layer``: ``road``, ``obstacles``, ``path``, ``car``)."""
        return f"{self.base}/topdown/{layer}" if layer else f"{self.base}/topdown"
