"""The committed generated modules must be exactly what protoc makes from the shipped sources."""

from __future__ import annotations

import subprocess
import sys
from importlib.resources import files
from pathlib import Path

from oasis_torchrl.proto import proto_sources


def test_generated_modules_match_protos(tmp_path: Path) -> None:
    sources = proto_sources()
    assert sources, "no .proto sources found"
    include = tmp_path / "include"
    for import_path, text in sources.items():
        (include / import_path).parent.mkdir(parents=True, exist_ok=True)
        (include / import_path).write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    out.mkdir()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "grpc_tools.protoc",
            f"-I{include}",
            f"--python_out={out}",
            f"--grpc_python_out={out}",
            f"--pyi_out={out}",
            *sorted(sources),
        ],
        check=True,
    )
    regenerated = {p.name: p.read_bytes() for p in (out / "oasis_torchrl" / "proto").iterdir()}
    committed = {
        entry.name: entry.read_bytes()
        for entry in files("oasis_torchrl.proto").iterdir()
        if entry.name.endswith((".py", ".pyi")) and entry.name != "__init__.py"
    }
    assert sorted(regenerated) == sorted(committed)
    stale = [name for name in regenerated if regenerated[name] != committed[name]]
    assert not stale, f"stale generated modules (run `make protos`): {stale}"
