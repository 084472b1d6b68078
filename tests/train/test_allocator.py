"""keep_batches_in_heap: freed batch-sized tensors come back without fresh page faults."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from oasis_torchrl.allocator import MAX_MMAP_THRESHOLD, _glibc_mallopt, keep_batches_in_heap

# A training step's pattern: a batch-sized tensor (28 MiB), its normalised copy and a smaller
# one, freed again, 100 times.
_STEPS = """
import json, resource, sys, torch
if sys.argv[1] == "keep":
    from oasis_torchrl.allocator import keep_batches_in_heap
    assert keep_batches_in_heap()
def step():
    batch = torch.ones(7 << 20)
    normalised = batch.mul(2)
    other = torch.ones(3 << 20)
    del batch
    return normalised.add(other.sum()).sum()
step()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(100):
    step()
print(json.dumps(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before))
"""


def page_faults(setting: str) -> int:
    """Page faults of 100 such steps in a fresh interpreter."""
    command = [sys.executable, "-c", _STEPS, setting]
    return json.loads(subprocess.run(command, check=True, capture_output=True, text=True).stdout)


@pytest.mark.skipif(_glibc_mallopt() is None, reason="glibc's mallopt only")
def test_freed_batches_are_reused_without_page_faults() -> None:
    default, kept = page_faults("default"), page_faults("keep")
    # Fresh mappings fault their pages in again on every step (measured: about 2,700 a step);
    # reused heap memory faults only while the heap first grows (about 7,000 in all).
    assert default > 100 * 1000
    assert kept < default // 5


def test_thresholds_outside_glibcs_range_are_refused() -> None:
    with pytest.raises(ValueError, match="mmap threshold must be in"):
        keep_batches_in_heap(MAX_MMAP_THRESHOLD + 1)
