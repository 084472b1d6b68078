"""Data driven in rounds on the embedded server, shared by the reward networks' trainings
(``train depth``, ``train motion``): kept in a file for the next run, and split by round.

Rows carry the round they were driven in (``rounds``) and can be selected (``select``); a file
of them is written by ``save`` and read by the type's ``load``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import torch

logger = logging.getLogger(__name__)


class DrivenRows(Protocol):
    """Rows driven in rounds: their round ids ``[M]``, a selection and a file."""

    rounds: torch.Tensor

    def select(self, rows: torch.Tensor) -> DrivenRows:
        """The rows ``rows`` names (indices, or a bool mask)."""
        ...

    def save(self, path: str | Path) -> None:
        """Write the rows to ``path``."""
        ...


def kept_or_driven[Rows: DrivenRows](
    path: str | None, load: Callable[[str], Rows], drive: Callable[[], Rows]
) -> Rows:
    """The rows of the file ``path`` if it exists, else ``drive()``'s (then written to ``path``
    when it is set).

    Example:
        >>> kept_or_driven(None, lambda path: None, lambda: "driven")
        'driven'
    """
    if path is not None and Path(path).exists():
        logger.info("reading the rows of %s (no driving)", path)
        return load(path)
    data = drive()
    if path is not None:
        data.save(path)
    return data


def split_rounds[Rows: DrivenRows](data: Rows, validation: float) -> tuple[Rows, Rows | None]:
    """The training rows and the validation rows: the last ``validation`` share of the rounds
    (at least one round when the share is positive and there are two or more; None without).

    Example:
        >>> from oasis_torchrl.train.depth import DepthFrames
        >>> data = DepthFrames(torch.zeros(4, 1, 1, 3), torch.zeros(4, 1, 1), torch.arange(4))
        >>> train, held = split_rounds(data, 0.25)
        >>> train.rounds.tolist(), held.rounds.tolist()
        ([0, 1, 2], [3])
    """
    count = int(data.rounds.max()) + 1
    held = min(count - 1, max(1, round(count * validation))) if validation > 0 else 0
    if held <= 0:
        return data, None
    is_held = data.rounds >= count - held
    return data.select(~is_held), data.select(is_held)
