"""Sub-commands of the ``oasis-torchrl`` console script, one module per command.

A command module defines ``NAME`` (the sub-command), ``HELP`` (one line), ``add_arguments(parser)``
and ``run(args) -> int`` (the exit code). :func:`oasis_torchrl.cli.main` finds every module of
this package that does not start with ``_``, so adding a command means adding a module. Keep
module-level imports light (import heavy libraries inside ``run``): every command module is
imported whenever the CLI starts.
"""
