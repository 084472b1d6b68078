"""A mixture of tanh-squashed normals over an action chunk, for TorchRL's ProbabilisticActor.

Why a mixture: the autopilot's lane changes go left or right for reasons the cameras often
cannot tell, so a unimodal head fitted to them answers their median, straight ahead, and never
steers. A mixture keeps each manoeuvre as its own component; the deterministic action is the
most probable component's chunk, so the policy commits to one side.

The components share the tanh, so the mixture of tanh-normals is the tanh of a mixture of
normals: the log-probability is exact (a log-sum-exp over components of the normal densities
of ``atanh(action)``, minus the tanh's log-Jacobian). The entropy has no closed form; it is
estimated with reparameterised samples of every component, weighted by the component
probabilities, so it is unbiased and its gradient reaches the weights, locations and scales
(a plain sample-based estimate would give the weights no gradient).
"""

from __future__ import annotations

import math

import torch
from torch import distributions as D
from torch.distributions import constraints

ACTION_BOUND = 1.0 - 1e-6
"""Actions are clamped to this before ``atanh`` (float32's tanh reaches 1.0 near 9)."""


def tanh_log_jacobian(pre_tanh: torch.Tensor) -> torch.Tensor:
    """``log(1 - tanh(u)^2)`` elementwise, computed from ``u`` (exact where tanh saturates).

    Example:
        >>> u = torch.tensor([0.0, 2.0])
        >>> torch.allclose(tanh_log_jacobian(u), torch.log1p(-torch.tanh(u) ** 2))
        True
    """
    return 2.0 * (math.log(2.0) - pre_tanh - torch.nn.functional.softplus(-2.0 * pre_tanh))


class TanhNormalMixture(D.Distribution):
    """``tanh`` of a mixture of ``K`` diagonal normals over an event of ``event_dims`` dims.

    Args:
        logits: component log-weights ``[*B, K]`` (unnormalised).
        loc: component locations before the tanh, ``[*B, K, *E]``.
        scale: component scales before the tanh, broadcastable to ``loc``.
        event_dims: number of trailing dimensions of an action (2 for a ``[4, 2]`` chunk).
        entropy_samples: reparameterised samples per component of the entropy estimate.

    Example:
        >>> logits = torch.tensor([[0.0, 0.0]])
        >>> loc = torch.tensor([[[-1.0], [1.0]]])  # two components of one number
        >>> dist = TanhNormalMixture(logits, loc, torch.full_like(loc, 0.1), event_dims=1)
        >>> dist.sample((1000,)).sign().mean().abs().item() < 0.2  # both sides, half each
        True
        >>> dist.deterministic_sample  # the first of equally likely components
        tensor([[-0.7616]])
        >>> middle, committed = torch.tensor([[0.0]]), dist.deterministic_sample
        >>> bool(dist.log_prob(middle) < dist.log_prob(committed))
        True
    """

    arg_constraints = {
        "logits": constraints.real_vector,
        "loc": constraints.real,
        "scale": constraints.positive,
    }
    has_rsample = False

    def __init__(
        self,
        logits: torch.Tensor,
        loc: torch.Tensor,
        scale: torch.Tensor,
        event_dims: int = 1,
        entropy_samples: int = 4,
    ) -> None:
        batch_dims = logits.dim() - 1
        if loc.dim() != batch_dims + 1 + event_dims or loc.shape[: batch_dims + 1] != logits.shape:
            raise ValueError(
                f"loc must be [*B, K, *event] for logits [*B, K] = {list(logits.shape)} and "
                f"{event_dims} event dims, got {list(loc.shape)}"
            )
        self.logits = logits
        self.loc = loc
        self.scale = scale.expand_as(loc)
        self.event_dims = event_dims
        self.entropy_samples = entropy_samples
        super().__init__(logits.shape[:-1], loc.shape[batch_dims + 1 :], validate_args=False)

    @classmethod
    def of_params(
        cls,
        loc: torch.Tensor,
        scale: torch.Tensor,
        logits: torch.Tensor | None = None,
        event_dims: int = 1,
    ) -> TanhNormalMixture:
        """The mixture of a head's parameters; without ``logits``, ``loc`` ``[*B, *E]`` is one
        tanh-normal, as a mixture of one component (the same density).

        Example:
            >>> loc = torch.zeros(5, 4, 2)
            >>> TanhNormalMixture.of_params(loc, torch.ones_like(loc), event_dims=2).logits.shape
            torch.Size([5, 1])
        """
        if logits is None:
            loc, scale = loc.unsqueeze(-event_dims - 1), scale.unsqueeze(-event_dims - 1)
            logits = loc.new_zeros((*loc.shape[: -event_dims - 1], 1))
        return cls(logits, loc, scale, event_dims=event_dims)

    @property
    def support(self) -> constraints.Constraint:
        return constraints.independent(constraints.interval(-1.0, 1.0), self.event_dims)

    @property
    def log_weights(self) -> torch.Tensor:
        """Normalised component log-weights ``[*B, K]``."""
        return torch.log_softmax(self.logits, dim=-1)

    def _joint_log_prob(
        self, pre_tanh: torch.Tensor, observed: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """For actions ``tanh(u)``, ``u`` ``[*S, *B, *E]``: the log-density of each component
        jointly with its weight, ``[*S, *B, K]`` (normals at ``u`` plus the log-weights), and
        the tanh's log-Jacobian ``[*S, *B]`` to subtract, over the ``observed`` numbers."""
        component = self.event_dims + 1  # where the component axis goes in [*S, *B, K, *E]
        per_component = D.Normal(self.loc, self.scale).log_prob(pre_tanh.unsqueeze(-component))
        jacobian = tanh_log_jacobian(pre_tanh)
        if observed is not None:
            per_component = per_component * observed.unsqueeze(-component)
            jacobian = jacobian * observed
        joint = per_component.flatten(-self.event_dims).sum(-1) + self.log_weights
        return joint, jacobian.flatten(-self.event_dims).sum(-1)

    def _mixture_log_prob(
        self, pre_tanh: torch.Tensor, observed: torch.Tensor | None
    ) -> torch.Tensor:
        """Log-density of the actions ``tanh(u)``: the mixture of normals at ``u`` minus the
        tanh's log-Jacobian, over the ``observed`` numbers."""
        joint, jacobian = self._joint_log_prob(pre_tanh, observed)
        return torch.logsumexp(joint, dim=-1) - jacobian

    def component_log_prob(
        self, value: torch.Tensor, component: torch.Tensor, observed: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Log-density ``[*B]`` of actions ``[*B, *E]`` under one component each,
        ``component`` ``[*B]`` (int), its weight left out: with :attr:`log_weights` at the same
        component, the joint log-density of an action and the component it came from (fitting
        both fits each component to its own actions and the weights as a classifier of them;
        :meth:`log_prob` marginalises the component out instead).

        Example:
            >>> logits = torch.tensor([[0.0, 0.0]])
            >>> loc = torch.tensor([[[-1.0], [1.0]]])
            >>> dist = TanhNormalMixture(logits, loc, torch.full_like(loc, 0.1), event_dims=1)
            >>> value = torch.tanh(torch.tensor([[1.0]]))
            >>> own, other = (dist.component_log_prob(value, torch.tensor([k])) for k in (1, 0))
            >>> bool(own + dist.log_weights[0, 1] > dist.log_prob(value) - 1e-4 > other)
            True
        """
        pre_tanh = torch.atanh(value.clamp(-ACTION_BOUND, ACTION_BOUND))
        joint, jacobian = self._joint_log_prob(pre_tanh, observed)
        densities = joint - self.log_weights
        return densities.gather(-1, component.unsqueeze(-1)).squeeze(-1) - jacobian

    def log_prob(self, value: torch.Tensor, observed: torch.Tensor | None = None) -> torch.Tensor:
        """Exact log-density of actions ``[*S, *B, *E]`` in ``[-1, 1]`` -> ``[*S, *B]``.

        ``observed`` (bool, broadcastable to ``value``) marks the action numbers that are
        known; the others are marginalised out (e.g. a demonstration's actions past the end of
        its episode): with diagonal components that is leaving them out of each component's
        density.
        """
        pre_tanh = torch.atanh(value.clamp(-ACTION_BOUND, ACTION_BOUND))
        return self._mixture_log_prob(pre_tanh, observed)

    @torch.no_grad()
    def sample(self, sample_shape: torch.Size | tuple[int, ...] = ()) -> torch.Tensor:
        """Draw a component per sample, then its tanh-normal chunk."""
        shape = torch.Size(sample_shape)
        component = D.Categorical(logits=self.logits).sample(shape)
        normal = torch.randn(shape + self.batch_shape + self.event_shape, device=self.loc.device)
        return self.component_chunk(component, normal)

    def component_chunk(self, component: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
        """``tanh(loc + scale * normal)`` ``[*S, *B, *E]`` of each row's ``component``
        ``[*S, *B]``, with ``normal`` ``[*S, *B, *E]`` standard normal deviations (bounded as every
        action is).

        Example:
            >>> loc = torch.tensor([[[-1.0], [1.0]]])
            >>> dist = TanhNormalMixture(torch.zeros(1, 2), loc, torch.ones_like(loc), 1)
            >>> dist.component_chunk(torch.tensor([1]), torch.zeros(1, 1))
            tensor([[0.7616]])
        """
        pre_tanh = self._component(self.loc, component) + self._component(
            self.scale, component
        ) * normal.to(self.loc.dtype)
        return torch.tanh(pre_tanh).clamp(-ACTION_BOUND, ACTION_BOUND)

    def _component(self, values: torch.Tensor, component: torch.Tensor) -> torch.Tensor:
        """``values`` ``[*B, K, *E]`` at ``component`` ``[*S, *B]`` -> ``[*S, *B, *E]``."""
        index = component.reshape(*component.shape, 1, *([1] * self.event_dims))
        index = index.expand(*component.shape, 1, *self.event_shape)
        expanded = values.expand(*component.shape[: -len(self.batch_shape) or None], *values.shape)
        return expanded.gather(len(component.shape), index).squeeze(len(component.shape))

    def most_probable(self, values: torch.Tensor) -> torch.Tensor:
        """``values`` ``[*B, K, *E]`` (e.g. :attr:`loc` or :attr:`scale`) at each row's most
        probable component, ``[*B, *E]``.

        Example:
            >>> loc = torch.tensor([[[-1.0], [1.0]]])
            >>> dist = TanhNormalMixture(torch.tensor([[0.0, 2.0]]), loc, torch.ones_like(loc), 1)
            >>> dist.most_probable(dist.loc)
            tensor([[1.]])
        """
        return self._component(values, self.logits.argmax(-1))

    @property
    def deterministic_sample(self) -> torch.Tensor:
        """The most probable component's chunk, ``tanh(loc)`` (the policy commits to it)."""
        return torch.tanh(self.most_probable(self.loc))

    def entropy(self) -> torch.Tensor:
        """Unbiased estimate ``[*B]`` of the entropy ``-E[log p(a)]``: ``entropy_samples``
        reparameterised draws of every component, weighted by its probability."""
        noise = torch.randn(
            (self.entropy_samples, *self.loc.shape), device=self.loc.device, dtype=self.loc.dtype
        )
        # [S, *B, K, *E] -> [K, S, *B, *E]: every component's draws, scored by the mixture
        pre_tanh = (self.loc + self.scale * noise).movedim(-self.event_dims - 1, 0)
        log_prob = self._mixture_log_prob(pre_tanh, None).mean(1)  # [K, *B]
        return -(log_prob * self.log_weights.exp().movedim(-1, 0)).sum(0)
