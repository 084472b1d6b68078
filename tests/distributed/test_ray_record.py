"""``oasis-torchrl record --ray``: two Ray workers record shards that merge into one dataset."""

from __future__ import annotations

import logging
import os
import pickle
import signal
from pathlib import Path

import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from tensordict import TensorDict

from oasis_torchrl.cli import main
from oasis_torchrl.config import EmbeddedServerConfig, EnvConfig
from oasis_torchrl.distributed import RayCollectionConfig, env_factory, record_on_ray
from oasis_torchrl.drivers import DriverSpec, PolicyDriver

pytestmark = pytest.mark.usefixtures("ray_runtime")

EPISODES, SESSIONS, STEPS = 5, 2, 2
SMALL = ["--width", "96", "--height", "64", "--max-steps", str(STEPS)]


def test_record_on_two_ray_workers_merges_one_dataset(tmp_path: Path) -> None:
    root = tmp_path / "drives"
    command = ["record", "--root", str(root), "--episodes", str(EPISODES), *SMALL]
    command += ["--ray", "--collectors", "2", "--sessions-per-env", str(SESSIONS)]
    assert main([*command, "--batch-steps", "2"]) == 0

    dataset = LeRobotDataset("local/drives", root=root, video_backend="pyav")
    # shares 3 + 2; every row ends an episode every STEPS chunks of 4 frame rows
    assert dataset.meta.total_episodes == EPISODES
    episode_index = torch.as_tensor(dataset.hf_dataset["episode_index"])
    assert episode_index.unique().tolist() == list(range(EPISODES))
    assert torch.equal(episode_index, episode_index.sort().values)  # contiguous episodes
    assert len(dataset) == EPISODES * STEPS * 4
    seeds = torch.as_tensor(dataset.hf_dataset["episode_seed"]).unique()
    assert len(seeds) == EPISODES  # the workers are seeded apart: no world twice
    assert dataset[len(dataset) - 1]["observation.images.front"].shape == (3, 64, 96)
    assert not (tmp_path / "drives.shards").exists()  # merged, then removed


@pytest.mark.parametrize(
    ("flags", "named"),
    [
        (["--ray", "--append"], "--append"),
        (["--ray", "--server-address", "http://127.0.0.1:1", "--endpoint", "x:1"], "--endpoint"),
        (["--ray", "--driver", "policy"], "--policy"),
        (["--ray", "--shard-root", "{busy}"], "not empty"),
    ],
)
def test_bad_ray_flags_are_refused_before_ray_runs(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, flags: list[str], named: str
) -> None:
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "worker-000-part-0000").mkdir()
    flags = [flag.format(busy=busy) for flag in flags]
    with caplog.at_level(logging.ERROR):
        assert main(["record", "--root", str(tmp_path / "drives"), *flags]) == 2
    assert named in caplog.text
    assert not (tmp_path / "drives").exists()


def test_a_torchscript_policy_driver_travels_as_its_spec(tmp_path: Path) -> None:
    path = tmp_path / "policy.pt"
    torch.jit.save(torch.jit.script(torch.nn.Linear(2, 8)), path)
    spec = pickle.loads(pickle.dumps(DriverSpec(str(path), in_keys=(("state",),))))
    driver = spec()
    assert isinstance(driver, PolicyDriver)
    action = driver(TensorDict(state=torch.ones(3, 2), batch_size=[3]))["action"]
    assert action.shape == (3, 4, 2)


def _parent(pid: int) -> int:
    # /proc/<pid>/stat: "pid (comm) state ppid ...", and comm may hold spaces or parentheses.
    stat = Path(f"/proc/{pid}/stat").read_text()
    return int(stat.rsplit(")", 1)[1].split()[1])


def _descends_from_this_process(pid: int) -> bool:
    """Whether ``pid`` runs under this test process (its own Ray runtime: raylet, then workers),
    not under another Ray runtime on the same machine."""
    me = os.getpid()
    while pid > 1:
        pid = _parent(pid)
        if pid == me:
            return True
    return False


def _kill_a_collector_process() -> None:
    """SIGKILL one of this test's Ray collector actor processes, as a crashed machine would."""
    for proc in Path("/proc").iterdir():
        try:
            title = (proc / "cmdline").read_bytes()
            ours = proc.name.isdigit() and _descends_from_this_process(int(proc.name))
        except OSError:
            continue
        if ours and title.startswith(b"ray::Collector"):
            os.kill(int(proc.name), signal.SIGKILL)
            return
    raise AssertionError("no Ray collector process of this test found")


@pytest.mark.skipif(not Path("/proc/self/cmdline").exists(), reason="finds workers in /proc")
@pytest.mark.timeout(600)  # two Ray workers start, record, lose one and close: 260 s seen loaded
def test_a_lost_worker_stops_the_run_keeping_its_finalized_shards(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    shard_root = tmp_path / "shards"
    config = RayCollectionConfig(
        num_collectors=2, sessions_per_env=SESSIONS, shard_root=str(shard_root), part_batches=1
    )
    server = EmbeddedServerConfig(width=96, height=64)
    create_env = env_factory(EnvConfig(max_steps=STEPS, image_size=None, server=server), config)
    killed: list[int] = []

    def kill_once(episodes: int) -> None:
        if not killed:
            killed.append(episodes)
            _kill_a_collector_process()

    with caplog.at_level(logging.WARNING):
        result = record_on_ray(
            config,
            create_env,
            DriverSpec("scripted:throttle=0.5"),
            tmp_path / "drives",
            episodes=4 * SESSIONS,
            batch_steps=STEPS,
            progress=kill_once,
        )
    # One batch (an episode per row) from both workers, then the survivor's next batch, which
    # it records while the lost one fails; each batch is a finalized shard part.
    assert killed == [2 * SESSIONS]
    # The collection raised WorkerLostError (the run stopped), naming the lost worker.
    assert result.stopped and len(result.lost_workers) == 1
    assert f"worker(s) {result.lost_workers} lost" in caplog.text
    dataset = LeRobotDataset("local/drives", root=result.output, video_backend="pyav")
    assert result.episodes == dataset.meta.total_episodes == 3 * SESSIONS
    episode_index = torch.as_tensor(dataset.hf_dataset["episode_index"]).unique()
    assert episode_index.tolist() == list(range(3 * SESSIONS))
    assert len(list(shard_root.iterdir())) == 3  # kept
    assert str(shard_root) in caplog.text
