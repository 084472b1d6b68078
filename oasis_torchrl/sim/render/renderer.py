"""The renderer: the three cameras of a car in a scene, as RGB images and metric depth.

Several car poses (the 4 frames of a simulator step) are drawn in one pass, so the per-call
overhead of the many small NumPy calls that plan a frame is shared: every per-column and
per-object step runs over all views (cameras x poses) at once. The frames are a ``uint8``
palette-index image ``[views, rows, columns]``: sky (one gradient level per row), then ground
(:mod:`~oasis_torchrl.sim.render.ground`) and roadside walls
(:mod:`~oasis_torchrl.sim.render.roadside`) row by row, obstacles
(:mod:`~oasis_torchrl.sim.render.obstacles`) and weather particles on top. Palette indices
become packed RGB through the camera's palette
(:class:`~oasis_torchrl.sim.render.quad_palette.QuadPalette`). Per-pixel work is a few large
NumPy calls over all views; on large frames it runs as independent parts (per view and half
image) on the renderer's threads. The same drawing code optionally fills a metric depth buffer
(distance along the camera axis, ``inf`` for sky) for :meth:`Renderer.depth`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.render.camera import CAMERA_YAWS, CameraModel, Views
from oasis_torchrl.sim.render.ground import Ground
from oasis_torchrl.sim.render.lighting import build_palette, scene_look
from oasis_torchrl.sim.render.materials import GROUND_BANDS, SKY_LEVELS, material
from oasis_torchrl.sim.render.obstacles import ObstacleGeometry
from oasis_torchrl.sim.render.particles import Particles
from oasis_torchrl.sim.render.quad_palette import QuadPalette
from oasis_torchrl.sim.render.roadside import Roadside, WallPlan
from oasis_torchrl.sim.render.threads import Part, RenderThreads, thread_array
from oasis_torchrl.sim.scene import Scene
from oasis_torchrl.sim.vehicle import VehicleState

logger = logging.getLogger(__name__)

#: Images at least this large (pixels per camera) are drawn by several threads.
PARALLEL_PIXELS = 200_000
#: Relative per-pixel cost of ground and of each wall layer (a plain row costs 1), to split
#: each camera's rows into parts of equal work.
GROUND_WORK = 5.0
WALL_WORK = 12.0


class Renderer:
    """Draws the three cameras of a car in a :class:`~oasis_torchrl.sim.scene.Scene`.

    Several poses of the car (e.g. the 4 frames of a step) can be drawn in one pass
    (:meth:`render_many`): per-column and per-object work is done for all views (poses x
    cameras) at once; per-pixel work runs as a few large NumPy calls over all views, or on
    large images per view and half image, spread over the renderer's threads. :meth:`close`
    stops those threads.

    Args:
        width: Image width in pixels (any size >= 8).
        height: Image height in pixels (any size >= 8).

    Example:
        >>> from oasis_torchrl.sim.scene import build_scene
        >>> from oasis_torchrl.sim.world import World
        >>> scene = build_scene("rural", 0)
        >>> renderer = Renderer(96, 64)
        >>> renderer.prepare(scene)
        >>> frames = {name: np.zeros((64, 96, 3), np.uint8) for name in CAMERAS}
        >>> renderer.render(World(scene, 0.05).state, 0, frames)
        >>> int(frames["front"][0].mean()) > 0  # the sky
        True
        >>> renderer.close()
    """

    def __init__(self, width: int, height: int) -> None:
        self.model = model = CameraModel(width, height)
        depths = model.row_depths()
        self._row_depths = depths.astype(np.float32)
        self._first_below = int(np.searchsorted(-depths, -np.inf, side="right"))
        self._ground = Ground(model)
        self._roadside = Roadside(model, self._ground.sample_depths)
        self._index = np.zeros(0, dtype=np.uint8)
        self._threads = RenderThreads(parallel=width * height >= PARALLEL_PIXELS)
        self._scene: Scene | None = None

    def prepare(self, scene: Scene) -> None:
        """Bake everything that depends on the scene: palettes, profiles, particles."""
        model = self.model
        self._scene = scene
        self._look = look = scene_look(scene.style)
        elevation = np.clip(model.row_offsets() / (model.height / 2), 0.0, 1.0)
        sky_level = np.minimum(elevation**0.6 * SKY_LEVELS, SKY_LEVELS - 1).astype(np.uint8)
        levels = (np.arange(SKY_LEVELS) + 0.5) / SKY_LEVELS
        self._palettes = [
            QuadPalette(build_palette(look, CAMERA_YAWS[name], levels)) for name in CAMERAS
        ]
        background = material("sky") + sky_level
        background[self._first_below :] = material("grass") + GROUND_BANDS - 1
        self._background = np.repeat(background[:, None], model.padded_width, axis=1)
        self._ground.prepare(scene, look)
        self._obstacles = ObstacleGeometry.of(scene)
        self._particles = Particles(model, scene)
        logger.debug("renderer %dx%d ready for %r", model.width, model.height, scene.prompt)

    def render(self, car: VehicleState, frame: int, out: dict[str, np.ndarray]) -> None:
        """Draw every camera into ``out[name]`` (``uint8 [H, W, 3]``, written in place).

        ``frame`` (frames since the scene started) animates rain and snow.
        """
        self._check_images(out, (self.model.height, self.model.width, 3))
        self._render([car], [frame], {name: image[None] for name, image in out.items()})

    def render_many(
        self, cars: Sequence[VehicleState], frames: Sequence[int], out: dict[str, np.ndarray]
    ) -> None:
        """Draw every camera of several poses in one pass: ``out[name][k]`` (``out[name]`` is
        ``uint8 [len(cars), H, W, 3]``, written in place) shows ``cars[k]`` at ``frames[k]``.

        The same images as :meth:`render` of each pose in turn, at a fraction of the cost on
        small images (the per-call overhead is shared).

        Example:
            >>> from oasis_torchrl.sim.scene import build_scene
            >>> from oasis_torchrl.sim.world import World
            >>> world = World(build_scene("rural snow", 0), 0.05)
            >>> renderer = Renderer(96, 64)
            >>> renderer.prepare(world.scene)
            >>> poses = [world.state, world.state]
            >>> frames = {name: np.zeros((2, 64, 96, 3), np.uint8) for name in CAMERAS}
            >>> renderer.render_many(poses, [0, 5], frames)
            >>> bool(np.array_equal(frames["front"][0], frames["front"][1]))  # snow falls
            False
        """
        if len(frames) != len(cars):
            raise ValueError(f"frames must have one entry per car ({len(cars)}), got {len(frames)}")
        self._check_images(out, (len(cars), self.model.height, self.model.width, 3))
        self._render(cars, frames, out)

    def depth(self, car: VehicleState) -> dict[str, np.ndarray]:
        """Metric depth (along each camera axis, ``inf`` for sky) per camera, float32 [H, W]."""
        model = self.model
        buffer = np.empty((len(CAMERAS), model.height, model.padded_width), dtype=np.float32)
        buffer[...] = self._row_depths[:, None]
        self._draw(self._views([car]), buffer)
        return {
            name: np.ascontiguousarray(buffer[camera, :, : model.width])
            for camera, name in enumerate(CAMERAS)
        }

    def close(self) -> None:
        """Stop the renderer's threads (idempotent); it still renders, in the calling thread."""
        self._threads.close()

    def _render(
        self, cars: Sequence[VehicleState], frames: Sequence[int], out: dict[str, np.ndarray]
    ) -> None:
        """Draw the poses ``cars`` into ``out`` (checked by the caller)."""
        poses = len(cars)
        index = self._draw(self._views(cars), None)
        self._particles.draw(index, np.asarray(frames, dtype=np.float64))
        index = index.reshape(len(CAMERAS), poses, *index.shape[1:])
        width = self.model.width

        def convert(part: tuple[int, slice, slice]) -> None:
            camera, pose, rows = part
            indices = index[camera, pose, rows, :width]
            if not indices.flags.c_contiguous:  # padded rows: gather the visible columns
                scratch = thread_array("pixels", indices.shape, np.uint8)
                np.copyto(scratch, indices)
                indices = scratch
            self._palettes[camera].convert(indices.reshape(-1), out[CAMERAS[camera]][pose, rows])

        self._threads.run(convert, self._rgb_parts(poses))

    def _check_images(self, out: dict[str, np.ndarray], shape: tuple[int, ...]) -> None:
        """Raise unless ``out`` holds a writable C-contiguous uint8 ``shape`` array per camera."""
        for name in CAMERAS:
            image = out.get(name)
            if not isinstance(image, np.ndarray):
                raise TypeError(f"out[{name!r}] must be a numpy array, got {type(image).__name__}")
            if (
                image.shape != shape
                or image.dtype != np.uint8
                or not image.flags.c_contiguous
                or not image.flags.writeable
            ):
                raise ValueError(
                    f"out[{name!r}] must be a writable C-contiguous uint8 array of shape "
                    f"{shape}, got {image.dtype} {image.shape}"
                )

    def _rgb_parts(self, poses: int) -> list[tuple[int, slice, slice]]:
        """``(camera, poses, rows)`` of the palette conversions: one per camera, or per camera,
        pose and half image when converting in parallel."""
        height = self.model.height
        if not self._threads.parallel:
            return [(camera, slice(0, poses), slice(0, height)) for camera in range(len(CAMERAS))]
        middle = height // 8 * 4
        return [
            (camera, slice(pose, pose + 1), rows)
            for camera in range(len(CAMERAS))
            for pose in range(poses)
            for rows in (slice(0, middle), slice(middle, height))
            if rows.stop > rows.start
        ]

    def _require_scene(self) -> Scene:
        if self._scene is None:
            raise RuntimeError("Renderer.prepare(scene) must be called before rendering")
        return self._scene

    def _views(self, cars: Sequence[VehicleState]) -> Views:
        return Views.of(cars, self._require_scene().road)

    def _index_image(self, views: int) -> np.ndarray:
        """The palette-index image ``[views, rows, padded columns]`` (one buffer, grown to the
        most views drawn at once)."""
        model = self.model
        size = views * model.height * model.padded_width
        if self._index.size < size:
            self._index = np.zeros(size, dtype=np.uint8)
        return self._index[:size].reshape(views, model.height, model.padded_width)

    def _draw(self, views: Views, depth: np.ndarray | None) -> np.ndarray:
        """Fill and return the index image (and ``depth`` if given) of every view."""
        scene = self._require_scene()
        index = self._index_image(views.count)
        s_samples, d_samples = self._ground.samples(views, scene.road)
        ground = self._ground.plan(s_samples, d_samples)
        band_distance = self._look.band_distance
        plans = (
            self._roadside.plan(layer, s_samples, d_samples, band_distance)
            for layer in scene.roadside
        )
        walls = [plan for plan in plans if plan is not None]

        def draw_part(part: Part) -> None:
            np.copyto(index[part], self._background[part[1]])
            self._ground.draw_rows(ground, index, part)
            for plan in walls:
                self._roadside.draw_rows(plan, index, part, depth)

        self._threads.run(draw_part, self._draw_parts(walls, views.count))
        self._obstacles.draw(views, self.model, walls, band_distance, index, depth)
        return index

    def _draw_parts(self, walls: list[WallPlan], views: int) -> list[Part]:
        """All views in one part, or when drawing in parallel each view's rows split in two
        parts of about equal per-pixel work."""
        height = self.model.height
        if not self._threads.parallel:
            return [(slice(0, views), slice(0, height))]
        parts = []
        for view in range(views):
            work = np.ones(height)
            work[self._ground.first_row :] += GROUND_WORK
            for plan in walls:
                work[plan.first_row[view] : plan.last_row[view]] += WALL_WORK
            middle = int(np.searchsorted(np.cumsum(work), work.sum() / 2))
            one = slice(view, view + 1)
            parts += [(one, slice(0, middle)), (one, slice(middle, height))]
        return parts
