"""The committed generated modules must be exactly what ``make protos`` makes from ``protos/``."""

from __future__ import annotations

import subprocess
import sys
from importlib.resources import files
from pathlib import Path

from oasis_torchrl.proto import IMPORT_PREFIX, proto_sources

ROOT = Path(__file__).resolve().parents[2]


def test_generated_modules_match_protos(tmp_path: Path) -> None:
    sources = sorted((ROOT / "protos").glob("*.proto"))
    assert [f"{IMPORT_PREFIX}/{path.name}" for path in sources] == sorted(proto_sources())
    subprocess.run(  # the Makefile's command, into a scratch folder
        [
            sys.executable,
            "-m",
            "grpc_tools.protoc",
            f"-I{IMPORT_PREFIX}={ROOT / 'protos'}",
            f"--python_out={tmp_path}",
            f"--grpc_python_out={tmp_path}",
            f"--pyi_out={tmp_path}",
            *map(str, sources),
        ],
        check=True,
    )
    regenerated = {p.name: p.read_bytes() for p in (tmp_path / IMPORT_PREFIX).iterdir()}
    committed = {
        entry.name: entry.read_bytes()
        for entry in files("oasis_torchrl.proto").iterdir()
        if entry.name.endswith((".py", ".pyi")) and entry.name != "__init__.py"
    }
    assert sorted(regenerated) == sorted(committed)
    stale = [name for name in regenerated if regenerated[name] != committed[name]]
    assert not stale, f"stale generated modules (run `make protos`): {stale}"
