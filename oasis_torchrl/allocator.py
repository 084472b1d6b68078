"""Keep batch-sized tensors in the process heap instead of fresh pages from the kernel.

glibc's ``malloc`` serves a request above its mmap threshold with fresh pages from ``mmap`` and
gives them back on ``free``. The threshold starts at 128 KiB and only creeps up as such blocks
are freed, so a training loop that allocates and frees the same tens-of-MB tensors every step
(a behaviour-cloning batch of 64 samples x 3 cameras x 2 frames at 64x96 is 28 MB as floats,
and its normalised copy, padding and activations as much again) page-faults every one of them
in again, zero-filled by the kernel, on every step. Fixing the threshold at glibc's maximum
(32 MiB on 64-bit) keeps those blocks in the heap for the next step.

docs/experiments/2026-11-27-allocator.md has the page faults and step times with and without
it. ``oasis-torchrl`` calls :func:`keep_batches_in_heap` before any command; other entry points
(``lerobot-train``, your own script) get the same with ``MALLOC_MMAP_THRESHOLD_=33554432`` in the
environment, or by calling it first.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import sys
from collections.abc import Callable

logger = logging.getLogger(__name__)

M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
"""``mallopt``'s parameter numbers (glibc's ``malloc.h``)."""
MAX_MMAP_THRESHOLD = 32 * 1024 * 1024
"""glibc's largest mmap threshold on 64-bit systems (``DEFAULT_MMAP_THRESHOLD_MAX``)."""
TRIM_PER_THRESHOLD = 8
"""Free memory kept at the top of the heap, in mmap thresholds (256 MiB at the maximum): a
fixed mmap threshold also stops glibc raising the trim threshold with it, and at its default
(128 KiB) the heap would hand the freed batches back to the kernel instead."""


def keep_batches_in_heap(threshold: int = MAX_MMAP_THRESHOLD) -> bool:
    """Fix glibc's mmap threshold at ``threshold`` bytes: blocks up to that size are reused
    from the heap after ``free`` instead of being unmapped (and up to ``TRIM_PER_THRESHOLD``
    times as much free memory stays at the heap's top). Returns whether it was applied
    (``False`` off glibc, e.g. macOS or musl, where nothing changes).

    Example:
        >>> keep_batches_in_heap() in (True, False)
        True
        >>> keep_batches_in_heap(0)
        Traceback (most recent call last):
        ...
        ValueError: the mmap threshold must be in [1, 33554432] bytes, got 0
    """
    if not 0 < threshold <= MAX_MMAP_THRESHOLD:
        raise ValueError(
            f"the mmap threshold must be in [1, {MAX_MMAP_THRESHOLD}] bytes, got {threshold}"
        )
    mallopt = _glibc_mallopt()
    if mallopt is None:
        return False
    trim = TRIM_PER_THRESHOLD * threshold
    applied = bool(mallopt(M_MMAP_THRESHOLD, threshold)) and bool(mallopt(M_TRIM_THRESHOLD, trim))
    if not applied:
        logger.warning(
            "glibc refused an mmap threshold of %d or a trim threshold of %d", threshold, trim
        )
    return applied


def _glibc_mallopt() -> Callable[[int, int], int] | None:
    """glibc's ``mallopt``, or ``None`` where the C library is not glibc."""
    if not sys.platform.startswith("linux"):
        return None
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        libc.gnu_get_libc_version  # noqa: B018 - present in glibc only
    except (OSError, TypeError, AttributeError):
        return None
    mallopt = libc.mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return mallopt
