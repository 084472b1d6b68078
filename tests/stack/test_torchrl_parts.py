"""TorchRL 0.14 on this stack: everything the project uses imports and runs without torchrl's
compiled extension.

torchrl 0.14.0 and 0.14.1 ship an extension built against torch 2.12's autograd ABI (nodes held
by ``intrusive_ptr``); torch 2.10 and 2.11, the releases LeRobot 0.6 allows, export the
``shared_ptr`` form, so the extension does not load and prioritized replay (its only user in
TorchRL) is unavailable. The project does not use it; these tests keep it that way.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import torch
from tensordict.nn import NormalParamExtractor, TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.envs import Compose, RewardSum, StepCounter, TransformedEnv
from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE
from torchrl.record.loggers import get_logger
from torchrl.testing.mocking_classes import ContinuousActionVecMockEnv

import oasis_torchrl

ROOT = Path(oasis_torchrl.__file__).parents[1]
SOURCES = ("oasis_torchrl", "policies", "benchmarks")
EXTENSION_ONLY = {
    "PrioritizedReplayBuffer",
    "TensorDictPrioritizedReplayBuffer",
    "PrioritizedSampler",
    "PrioritizedSliceSampler",
}
"""TorchRL parts that need the compiled extension (its segment trees)."""


def torchrl_imports() -> set[tuple[str, str]]:
    """``(module, name)`` of every ``from torchrl... import name`` in the project's code."""
    found = set()
    for folder in SOURCES:
        for path in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
                if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("torchrl"):
                    found.update((node.module, alias.name) for alias in node.names)
    return found


def test_every_torchrl_name_the_project_imports_exists() -> None:
    names = torchrl_imports()
    assert ("torchrl.objectives", "ClipPPOLoss") in names  # the scan sees the project's imports
    missing = [
        f"{module}.{name}"
        for module, name in sorted(names)
        if not hasattr(importlib.import_module(module), name)
    ]
    assert missing == []


def test_the_project_uses_no_part_that_needs_the_compiled_extension() -> None:
    assert {name for _, name in torchrl_imports()} & EXTENSION_ONLY == set()


def test_collection_and_a_ppo_update_run(tmp_path: Path) -> None:
    """The TorchRL parts the project trains with, end to end on TorchRL's own mock env."""
    torch.manual_seed(0)
    env = TransformedEnv(ContinuousActionVecMockEnv(), Compose(RewardSum(), StepCounter(5)))
    observation = env.observation_spec["observation"].shape[-1]
    action = env.action_spec.shape[-1]
    actor = ProbabilisticActor(
        TensorDictModule(
            nn.Sequential(nn.Linear(observation, 2 * action), NormalParamExtractor()),
            in_keys=["observation"],
            out_keys=["loc", "scale"],
        ),
        in_keys=["loc", "scale"],
        spec=env.action_spec,
        distribution_class=TanhNormal,
        return_log_prob=True,
    )
    critic = ValueOperator(nn.Linear(observation, 1), in_keys=["observation"])
    loss = ClipPPOLoss(actor, critic)
    advantage = GAE(gamma=0.99, lmbda=0.95, value_network=critic)
    optimizer = torch.optim.Adam(loss.parameters(), lr=1e-2)
    logger = get_logger("csv", logger_name=str(tmp_path), experiment_name="ppo")
    collector = Collector(env, actor, frames_per_batch=8, total_frames=16)
    updates = 0
    for batch in collector:
        advantage(batch)
        terms = loss(batch)
        total = terms["loss_objective"] + terms["loss_critic"] + terms["loss_entropy"]
        optimizer.zero_grad()
        total.backward()
        optimizer.step()
        logger.log_scalar("loss", total.item(), step=updates)
        updates += 1
    collector.shutdown()
    assert updates == 2 and torch.isfinite(total)
    assert list(tmp_path.rglob("loss.csv"))
