"""The mixture of tanh-normals: exact density, samples, entropy estimate, marginalisation."""

from __future__ import annotations

import pytest
import torch
from torch import distributions as D

from oasis_torchrl.models.distributions import TanhNormalMixture


def _chunk_mixture(batch: int = 5, components: int = 3) -> TanhNormalMixture:
    generator = torch.Generator().manual_seed(0)
    logits = torch.randn(batch, components, generator=generator)
    loc = torch.randn(batch, components, 4, 2, generator=generator)
    scale = 0.1 + 0.5 * torch.rand(batch, components, 4, 2, generator=generator)
    return TanhNormalMixture(logits, loc, scale, event_dims=2)


def test_log_prob_is_the_tanh_of_a_gaussian_mixture() -> None:
    dist = _chunk_mixture()
    reference = D.TransformedDistribution(
        D.MixtureSameFamily(
            D.Categorical(logits=dist.logits), D.Independent(D.Normal(dist.loc, dist.scale), 2)
        ),
        [D.TanhTransform()],
    )
    actions = dist.sample((100,))
    assert actions.shape == (100, 5, 4, 2) and actions.abs().max() < 1
    torch.testing.assert_close(dist.log_prob(actions), reference.log_prob(actions))


def test_the_density_integrates_to_one() -> None:
    loc = torch.tensor([[[-1.5], [0.2], [2.0]]])
    dist = TanhNormalMixture(torch.tensor([[0.5, -1.0, 0.0]]), loc, torch.full_like(loc, 0.3))
    grid = torch.linspace(-1, 1, 200_001)[1:-1]
    density = dist.log_prob(grid.reshape(-1, 1, 1)).exp().squeeze(-1)
    assert torch.trapezoid(density, grid).item() == pytest.approx(1.0, abs=1e-3)


def test_samples_follow_the_component_weights() -> None:
    loc = torch.tensor([[[-2.0], [0.0], [2.0]]])
    weights = torch.tensor([0.2, 0.5, 0.3])
    dist = TanhNormalMixture(weights.log().unsqueeze(0), loc, torch.full_like(loc, 0.05))
    samples = dist.sample((20_000,)).flatten()
    fractions = torch.stack([(samples < -0.5).float().mean(), (samples.abs() < 0.5).float().mean()])
    torch.testing.assert_close(fractions, weights[:2], atol=0.015, rtol=0)
    torch.testing.assert_close(dist.deterministic_sample, torch.zeros(1, 1))  # the heaviest


def test_a_single_tanh_normal_is_a_mixture_of_one() -> None:
    loc, scale = torch.randn(5, 4, 2), 0.1 + torch.rand(5, 4, 2)
    dist = TanhNormalMixture.of_params(loc, scale, event_dims=2)
    single = D.TransformedDistribution(D.Independent(D.Normal(loc, scale), 2), [D.TanhTransform()])
    actions = dist.sample()
    torch.testing.assert_close(dist.log_prob(actions), single.log_prob(actions))


def test_the_entropy_estimate_matches_sampled_log_probs() -> None:
    torch.manual_seed(0)
    dist = _chunk_mixture()
    sampled = -dist.log_prob(dist.sample((200_000,))).mean(0)
    estimate = torch.stack([dist.entropy() for _ in range(2000)]).mean(0)
    assert estimate.shape == (5,)
    torch.testing.assert_close(estimate, sampled, atol=0.06, rtol=0)


def test_the_entropy_gradient_reaches_weights_and_scales() -> None:
    torch.manual_seed(0)
    logits = torch.tensor([[1.0, 0.0]], requires_grad=True)
    log_scale = torch.zeros(1, 2, 1, requires_grad=True)
    loc = torch.tensor([[[-1.0], [1.0]]])  # apart: the entropy grows towards equal weights
    entropy = TanhNormalMixture(logits, loc, 0.1 * log_scale.exp(), entropy_samples=256)
    entropy.entropy().sum().backward()
    assert logits.grad[0, 0] < 0 < logits.grad[0, 1]
    assert (log_scale.grad > 0).all()  # wider components: more entropy


def test_unobserved_numbers_are_marginalised_out() -> None:
    dist = _chunk_mixture(batch=2)
    observed = torch.ones(2, 4, 1, dtype=torch.bool)
    observed[0, 2:] = False  # the last two actions of the first chunk: past the episode's end
    actions = dist.sample()
    first_two = TanhNormalMixture(dist.logits, dist.loc[:, :, :2], dist.scale[:, :, :2], 2)
    masked = dist.log_prob(actions, observed)
    torch.testing.assert_close(masked[0], first_two.log_prob(actions[:, :2])[0])
    torch.testing.assert_close(masked[1], dist.log_prob(actions)[1])


def test_shapes_are_checked() -> None:
    with pytest.raises(ValueError, match=r"loc must be \[\*B, K, \*event\]"):
        TanhNormalMixture(torch.zeros(2, 3), torch.zeros(2, 4, 2), torch.ones(2, 4, 2), 2)
