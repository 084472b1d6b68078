"""The committed generated modules must be exactly what protoc makes from ``protos/``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PROTO_DIR = ROOT / "protos"
GENERATED_DIR = ROOT / "oasis_torchrl" / "proto"


def test_generated_modules_match_protos(tmp_path: Path) -> None:
    sources = sorted(str(p.relative_to(PROTO_DIR)) for p in PROTO_DIR.rglob("*.proto"))
    assert sources, "no .proto sources found"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "grpc_tools.protoc",
            f"-I{PROTO_DIR}",
            f"--python_out={tmp_path}",
            f"--grpc_python_out={tmp_path}",
            f"--pyi_out={tmp_path}",
            *sources,
        ],
        check=True,
    )
    regenerated = {p.name: p.read_bytes() for p in (tmp_path / "oasis_torchrl" / "proto").iterdir()}
    committed = {
        p.name: p.read_bytes()
        for p in GENERATED_DIR.iterdir()
        if p.suffix in {".py", ".pyi"} and p.name != "__init__.py"
    }
    assert sorted(regenerated) == sorted(committed)
    stale = [name for name in regenerated if regenerated[name] != committed[name]]
    assert not stale, f"stale generated modules (run `make protos`): {stale}"
