"""The one drive loop: a policy drives an env step by step and every step goes to a consumer.

Recording (``oasis-torchrl record``), demonstrations (the autopilot's labels over noisy or
learner-driven execution) and evaluation (one episode per row) all drive through
:func:`drive`; they differ only in their policy, what they do with each step, and whether a
finished row starts its next episode.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

Policy = Callable[[TensorDictBase], TensorDictBase]
StepConsumer = Callable[[TensorDictBase], None]


def drive(
    env: EnvBase,
    policy: Policy,
    on_step: StepConsumer,
    *,
    until: Callable[[], bool],
    max_steps: int | None = None,
    reset_finished: bool = True,
    on_reset: StepConsumer | None = None,
) -> int:
    """Drive ``env`` with ``policy`` until ``until()`` holds or ``max_steps`` steps are done.

    Args:
        env: a batched env (rows are episodes running side by side).
        policy: ``td -> td`` setting ``"action"``; it acts deterministically
            (``ExplorationType.DETERMINISTIC``, no gradients).
        on_step: sees every step: the observation, its ``"action"`` and ``"next"``.
        until: checked before every step; the loop ends once it returns true.
        max_steps: steps at most (``None``: no limit).
        reset_finished: a finished row starts its next episode (recording); if false, every
            row drives one episode and finished rows step on unrecorded (evaluation).
        on_reset: sees the first observation.

    Returns:
        The number of steps driven.

    Example:
        >>> from oasis_torchrl.drivers import ScriptedDriver
        >>> from oasis_torchrl.envs import OasisEnv
        >>> from oasis_torchrl.sim.config import ServerConfig
        >>> env = OasisEnv("local", 2, server=ServerConfig(width=96, height=64), max_steps=2)
        >>> dones = []
        >>> record = lambda td: dones.append(td["next", "done"].sum().item())
        >>> policy = ScriptedDriver.from_spec("throttle=1")
        >>> drive(env, policy, record, until=lambda: len(dones) == 3)
        3
        >>> env.close(); dones
        [0, 2, 0]
    """
    steps = 0
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        td = env.reset()
        if on_reset is not None:
            on_reset(td)
        while not until() and (max_steps is None or steps < max_steps):
            td = policy(td)
            if reset_finished:
                td, following = env.step_and_maybe_reset(td)
            else:
                td = env.step(td)
                following = step_mdp(td)
            on_step(td)
            steps += 1
            td = following
    return steps
