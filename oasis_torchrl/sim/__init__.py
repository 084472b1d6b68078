"""The embedded A2V server and the procedural driving simulator behind it.

Modules: ``scene`` (prompt + seed to a static world), ``vehicle`` (kinematic bicycle),
``world`` (the car in the scene: collisions and ground truth), ``render`` (a package: the three
cameras), ``autopilot`` (a privileged driver), ``simulator`` (the facade the server calls), plus
the server side (``server``, ``sessions``, ``encoding``, ...).
"""
