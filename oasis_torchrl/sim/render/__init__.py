"""Vectorised software renderer of the car's three cameras, one concern per module.

- :mod:`~oasis_torchrl.sim.render.camera`: camera placement, intrinsics, views of poses;
- :mod:`~oasis_torchrl.sim.render.materials`: materials and their depth bands in the palette;
- :mod:`~oasis_torchrl.sim.render.lighting`: a style's colours, light and fog, as palettes;
- :mod:`~oasis_torchrl.sim.render.textures`: ground profiles, wall and obstacle textures;
- :mod:`~oasis_torchrl.sim.render.ground`, :mod:`~oasis_torchrl.sim.render.roadside`,
  :mod:`~oasis_torchrl.sim.render.obstacles`, :mod:`~oasis_torchrl.sim.render.particles`:
  the rasterisers of each kind of thing in view;
- :mod:`~oasis_torchrl.sim.render.quad_palette`: palette indices to packed RGB;
- :mod:`~oasis_torchrl.sim.render.threads`: the renderer's threads and scratch arrays;
- :mod:`~oasis_torchrl.sim.render.renderer`: :class:`Renderer`, which draws with all of them.

Example:
    >>> from oasis_torchrl.sim.render import Renderer
    >>> Renderer(96, 64).model.knot
    4
"""

from oasis_torchrl.sim.render.camera import OBSTACLE_FAR, CameraModel
from oasis_torchrl.sim.render.renderer import Renderer

__all__ = ["OBSTACLE_FAR", "CameraModel", "Renderer"]
