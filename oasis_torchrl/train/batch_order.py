"""Shuffled batches whose order depends on the seed and the step alone, so a resumed run
continues exactly where a stopped one was.

A ``DataLoader(shuffle=True)`` draws each epoch's order when its iterator starts: a run resumed
half way through an epoch starts a new order there, and from then on trains on other batches
than the run that never stopped. :class:`StepBatches` gives step ``s`` the batch that position
holds in its epoch's permutation, drawn from ``(seed, epoch)``; a resumed run starts it at the
step it had reached.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from torch.utils.data import Sampler


class StepBatches(Sampler[list[int]]):
    """Endless shuffled batches of dataset indices, epoch after epoch, from ``first_step`` on.

    Args:
        size: the dataset's length.
        batch_size: indices per batch.
        seed: the run's seed; epoch ``e``'s order is drawn from ``(seed, e)``.

    An epoch's last, smaller batch is left out, unless it is the epoch's only one (fewer rows
    than ``batch_size``).

    Example:
        >>> batches = StepBatches(size=5, batch_size=2, seed=0)
        >>> stream = iter(batches)
        >>> taken = [next(stream) for _ in range(3)]
        >>> batches.first_step = 2  # a run resumed after its second step
        >>> next(iter(batches)) == taken[2]
        True
    """

    def __init__(self, size: int, batch_size: int, seed: int) -> None:
        if size < 1 or batch_size < 1:
            raise ValueError(f"need a non-empty dataset and batch, got {size} rows, {batch_size}")
        self.size, self.batch_size, self.seed = size, batch_size, seed
        self.per_epoch = max(1, size // batch_size)
        self.first_step = 0

    def __iter__(self) -> Iterator[list[int]]:
        epoch, position = divmod(self.first_step, self.per_epoch)
        while True:
            order = np.random.default_rng((self.seed, epoch)).permutation(self.size)
            for start in range(
                position * self.batch_size, self.per_epoch * self.batch_size, self.batch_size
            ):
                yield order[start : start + self.batch_size].tolist()
            epoch, position = epoch + 1, 0
