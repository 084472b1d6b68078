"""Per-row episode bookkeeping: which prompt and which seed each row's next episode gets.

Seeding: ``set_seed(s)`` gives row ``i`` its own generator spawned from ``SeedSequence(s)``; every
reset of that row draws the next episode seed (and feeds a prompt sampler) from it. The same seed
therefore replays the same sequence of worlds on every row, and rows never share a world by
accident. Before any ``set_seed`` the rows are seeded from ``SeedSequence(0)``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

PromptSampler = Callable[[int, np.random.Generator], str]
"""Called at each reset of a row as ``sampler(row, rng)``; returns that episode's prompt."""

Prompts = str | Sequence[str] | PromptSampler


class EpisodePlanner:
    """Chooses the prompt and seed of each row's next episode.

    Args:
        prompts: one prompt for every row, one prompt per row, or a sampler
            ``sampler(row, rng) -> str`` called at each reset of a row.
        num_rows: number of env rows.

    Example:
        >>> planner = EpisodePlanner(["urban street", "rural road"], num_rows=2)
        >>> planner.set_seed(7)
        >>> prompts, seeds = planner.next_episodes([0, 1])
        >>> prompts
        ['urban street', 'rural road']
        >>> len(seeds)
        2
    """

    def __init__(self, prompts: Prompts, num_rows: int) -> None:
        if num_rows < 1:
            raise ValueError(f"num_rows must be >= 1, got {num_rows}")
        self.num_rows = num_rows
        self._sampler = _as_sampler(prompts, num_rows)
        self.set_seed(0)

    def set_seed(self, seed: int) -> None:
        """Re-seed every row from ``seed`` (rows get independent streams)."""
        children = np.random.SeedSequence(int(seed)).spawn(self.num_rows)
        self._rngs = [np.random.default_rng(child) for child in children]

    def next_episodes(self, rows: Sequence[int]) -> tuple[list[str], list[int]]:
        """Draw the prompt and seed of the next episode of each of ``rows``."""
        prompts, seeds = [], []
        for row in rows:
            rng = self._rngs[row]
            seeds.append(int(rng.integers(0, 2**63 - 1)))
            prompt = self._sampler(row, rng)
            if not isinstance(prompt, str) or not prompt.strip():
                raise ValueError(f"prompt sampler returned {prompt!r} for row {row}; expected text")
            prompts.append(prompt)
        return prompts, seeds


class _PromptPerRow:
    """A picklable sampler: row ``i`` always gets ``prompts[i]``."""

    def __init__(self, prompts: Sequence[str]) -> None:
        self.prompts = tuple(prompts)

    def __call__(self, row: int, rng: np.random.Generator) -> str:
        return self.prompts[row]


def _as_sampler(prompts: Prompts, num_rows: int) -> PromptSampler:
    if callable(prompts):
        return prompts
    prompt_list = [prompts] * num_rows if isinstance(prompts, str) else list(prompts)
    if len(prompt_list) != num_rows:
        raise ValueError(
            f"got {len(prompt_list)} prompts for {num_rows} env rows; pass one per row"
        )
    bad = [p for p in prompt_list if not isinstance(p, str) or not p.strip()]
    if bad:
        raise ValueError(f"prompts must be non-empty strings, got {bad[0]!r}")
    return _PromptPerRow(prompt_list)


def episode_prompts(prompts: Sequence[str]) -> Prompts:
    """One prompt for every episode, or a sampler drawing one uniformly per episode.

    Example:
        >>> episode_prompts(["urban"])
        'urban'
        >>> sampler = episode_prompts(["urban", "rural"])
        >>> sampler(0, np.random.default_rng(0)) in ("urban", "rural")
        True
    """
    choices = [str(prompt) for prompt in prompts]
    if not choices:
        raise ValueError("env.prompts must hold at least one prompt")
    if len(choices) == 1:
        return choices[0]

    def sample(row: int, rng: np.random.Generator) -> str:
        return choices[int(rng.integers(len(choices)))]

    return sample
