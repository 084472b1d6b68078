"""Every script in ``examples/`` runs, at the smoke size its ``OASIS_EXAMPLE_SMOKE`` selects, from
a scratch folder (as a user runs a copied script) against the source tree under test."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from oasis_torchrl.protocol import API_KEY_ENV_VAR, ENDPOINT_ENV_VAR
from oasis_torchrl.sim.launcher import LocalServer

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"


def _run(script: str, cwd: Path, **env: str) -> subprocess.CompletedProcess[str]:
    variables = {
        k: v for k, v in os.environ.items() if k not in (API_KEY_ENV_VAR, ENDPOINT_ENV_VAR)
    }
    variables.update(OASIS_EXAMPLE_SMOKE="1", PYTHONPATH=str(ROOT), **env)
    return subprocess.run(
        [sys.executable, str(EXAMPLES / script)],
        cwd=cwd,
        env=variables,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_every_example_is_tested_and_linked_from_the_readme() -> None:
    scripts = {path.name for path in EXAMPLES.glob("*.py")}
    tested = {"ppo_torchrl.py", "rerun_rollouts.py", "hosted_service.py", "gymnasium_envs.py"}
    assert tested <= scripts
    readme = (ROOT / "README.md").read_text()
    assert all(f"examples/{name}" in readme for name in scripts)


def test_torchrl_ppo(tmp_path: Path) -> None:
    done = _run("ppo_torchrl.py", tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "16 frames" in done.stdout
    curves = tmp_path / "outputs/examples/ppo/ppo/scalars/train"
    assert (curves / "loss.csv").read_text().count("\n") == 2  # one line per batch


def test_rerun_live_rollout_and_dataset_replay(tmp_path: Path) -> None:
    done = _run("rerun_rollouts.py", tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    output = tmp_path / "outputs/examples/rerun"
    assert (output / "drives/meta/info.json").is_file()
    for name in ("live.rrd", "dataset.rrd"):
        assert (output / name).stat().st_size > 10_000
        assert f"wrote outputs/examples/rerun/{name}" in done.stdout


def test_gymnasium_make_and_the_vector_env(tmp_path: Path) -> None:
    done = _run("gymnasium_envs.py", tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "single env: front camera (64, 96, 3)" in done.stdout
    assert "episodes ended" in done.stdout  # the vector env's rows ended and were reset
    assert "vector env: 4 rows, front camera (4, 64, 96, 3)" in done.stdout


def test_hosted_service_needs_a_key_and_runs_with_one(
    tmp_path: Path, local_server: LocalServer
) -> None:
    done = _run("hosted_service.py", tmp_path)
    assert done.returncode == 1 and f"{API_KEY_ENV_VAR} is not set" in done.stderr
    # The same script on an A2V server of our own (the endpoint variable, as the SDK reads it).
    done = _run(
        "hosted_service.py",
        tmp_path,
        **{API_KEY_ENV_VAR: local_server.api_key, ENDPOINT_ENV_VAR: local_server.endpoint},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "batched env: torch.Size([2, 128, 192, 3])" in done.stdout
