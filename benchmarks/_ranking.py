"""Rank agreement between two ratings of the same items, for the benchmarks that ask whether a
signal without ground truth orders policies as ground truth does.

    >>> kendall_tau([1.0, 2.0, 3.0], [10.0, 30.0, 20.0])
    0.3333333333333333
"""

from __future__ import annotations

import math

import numpy as np


def kendall_tau(a: list[float], b: list[float]) -> float:
    """Kendall's tau-a between two rankings of the same items (nan below two items)."""
    pairs = [(i, j) for i in range(len(a)) for j in range(i + 1, len(a))]
    signs = [np.sign(a[i] - a[j]) * np.sign(b[i] - b[j]) for i, j in pairs]
    return float(np.mean(signs)) if signs else math.nan
