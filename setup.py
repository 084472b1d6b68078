"""Build hook (the project's metadata is pyproject.toml): the wheel carries the top-level
``configs/`` (named presets) and ``protos/`` (the ``.proto`` sources) inside the package, where
:mod:`oasis_torchrl.shipped` finds them once installed."""

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

SHIPPED = {"configs/*.yaml": "oasis_torchrl/configs", "protos/*.proto": "oasis_torchrl/proto"}
"""Each top-level pattern and the package folder its files go to."""


class BuildPyWithShippedFiles(build_py):
    """``build_py``, then the top-level files of :data:`SHIPPED` copied into the build."""

    def run(self) -> None:
        super().run()
        for pattern, target in SHIPPED.items():
            folder = Path(self.build_lib, target)
            self.mkpath(str(folder))
            for path in sorted(Path().glob(pattern)):
                self.copy_file(str(path), str(folder / path.name))


setup(cmdclass={"build_py": BuildPyWithShippedFiles})
