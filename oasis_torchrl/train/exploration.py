"""Exploration held over several chunks: a collecting policy whose noise persists.

Why one would: a lane change is about four chunks of steering one way and four back, and
braking for an obstacle takes a second or more; noise drawn afresh every chunk (0.2 s) averages
such moves out.

How: each env row keeps its noise, a uniform number that picks the mixture's component (by
the weights' cumulative sum) and a standard normal per action number, and redraws it with
probability ``1 / hold_chunks`` each chunk, so noise lives ``hold_chunks`` chunks on average
(a geometric time, so episode ends need no bookkeeping). Each action is still distributed as
the policy's mixture at its observation, and its stored log-probability is that density, what
PPO's ratio reads; as in generalised state-dependent exploration (gSDE, Raffin et al.), the
noise is correlated across steps while the log-probability is per step.

``exploration.hold_chunks`` defaults to 1 (off): held noise made PPO from scratch shrink its
steering scale and drive worse than fresh noise, and the same PPO handed the privileged state
learns lane changes with fresh noise (docs/experiments/2026-11-28-ppo-from-scratch.md).
"""

from __future__ import annotations

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.envs.utils import ExplorationType, exploration_type
from torchrl.modules import ProbabilisticActor

from oasis_torchrl.models.distributions import TanhNormalMixture


class HeldNoise:
    """Per-row noise ``(uniform [N], normal [N, *E])`` redrawn with probability ``1 / hold``
    per call.

    Args:
        hold: mean calls a row's noise lives (>= 1; 1 redraws every call).
        generator: the random source (None: torch's global one).

    Example:
        >>> noise = HeldNoise(hold=1e9)
        >>> first = noise.draw(3, (4, 2))
        >>> all(torch.equal(a, b) for a, b in zip(first, noise.draw(3, (4, 2))))
        True
        >>> noise.draw(5, (4, 2))[1].shape  # another batch: fresh noise
        torch.Size([5, 4, 2])
    """

    def __init__(self, hold: float, generator: torch.Generator | None = None) -> None:
        if not hold >= 1:
            raise ValueError(f"noise must be held for at least 1 chunk on average, got {hold}")
        self.hold = float(hold)
        self.generator = generator
        self.uniform: torch.Tensor | None = None
        self.normal: torch.Tensor | None = None

    def draw(self, rows: int, event_shape: tuple[int, ...]) -> tuple[torch.Tensor, torch.Tensor]:
        """The noise of ``rows`` rows: kept, or redrawn for the rows whose time is up (all of
        them when the batch's shape changed)."""
        uniform = torch.rand(rows, generator=self.generator)
        normal = torch.randn(rows, *event_shape, generator=self.generator)
        if self.normal is not None and self.normal.shape == normal.shape:
            keep = torch.rand(rows, generator=self.generator) >= 1.0 / self.hold
            uniform = torch.where(keep, self.uniform, uniform)
            normal = torch.where(keep.view(-1, *[1] * len(event_shape)), self.normal, normal)
        self.uniform, self.normal = uniform, normal
        return uniform, normal


class HeldNoisePolicy(TensorDictModuleBase):
    """A PPO actor that explores with :class:`HeldNoise`: it writes ``"action"`` and its
    ``"action_log_prob"`` under the actor's distribution, as the actor does, under
    ``ExplorationType.RANDOM`` (what collectors set); otherwise (a deterministic evaluation) it
    is the actor itself.

    Args:
        policy: the stochastic actor (:attr:`oasis_torchrl.models.ActorCritic.policy`).
        hold_chunks: mean chunks each row's noise is held for.

    Example:
        >>> from tensordict import TensorDict
        >>> from torchrl.envs.utils import set_exploration_type
        >>> from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
        >>> net = DrivingNet(DrivingNetConfig(image_size=(32, 48)))
        >>> policy = HeldNoisePolicy(make_actor_critic(net).policy, hold_chunks=1e9)
        >>> frames = torch.zeros(2, 2, 32, 48, 3, dtype=torch.uint8)
        >>> td = TensorDict({"frame_stack": {c: frames for c in net.config.cameras},
        ...                  "state": torch.zeros(2, 2)}, batch_size=[2])
        >>> with set_exploration_type(ExplorationType.RANDOM):
        ...     first, second = (policy(td.clone())["action"] for _ in range(2))
        >>> torch.equal(first, second)  # the same observation, the noise held
        True
    """

    def __init__(self, policy: ProbabilisticActor, hold_chunks: float) -> None:
        super().__init__()
        self.policy = policy
        self.noise = HeldNoise(hold_chunks)
        self.in_keys = list(policy.in_keys)
        self.out_keys = list(policy.out_keys)
        (self.log_prob_key,) = policy.log_prob_keys

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        if exploration_type() != ExplorationType.RANDOM:
            return self.policy(tensordict)
        with torch.no_grad():
            dist = self.policy.get_dist(tensordict)  # writes the features and parameters
            mixture = TanhNormalMixture.of_params(
                tensordict.get("loc"),
                tensordict.get("scale"),
                tensordict.get("logits", None),
                event_dims=len(dist.event_shape),
            )
            rows = tensordict.numel()
            uniform, normal = self.noise.draw(rows, tuple(dist.event_shape))
            batch = tensordict.batch_size
            action = mixture.from_noise(uniform.view(batch), normal.view(*batch, *dist.event_shape))
            tensordict.set("action", action)
            tensordict.set(self.log_prob_key, dist.log_prob(action))
        return tensordict
