"""keep_batches_in_heap: batch-sized tensors are served from the heap, not fresh mappings."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from oasis_torchrl.allocator import MAX_MMAP_THRESHOLD, _glibc_mallopt, keep_batches_in_heap

# In a fresh interpreter: the bytes malloc holds in its own mappings (mallinfo2's ``hblkhd``)
# gained by allocating a batch-sized tensor (28 MiB, as a BC batch of floats).
_BATCH = """
import ctypes, json, sys, torch
if sys.argv[1] == "keep":
    from oasis_torchrl.allocator import keep_batches_in_heap
    assert keep_batches_in_heap()
class MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]
mallinfo2 = ctypes.CDLL(None).mallinfo2
mallinfo2.restype = MallInfo2
before = mallinfo2().hblkhd
batch = torch.ones(7 << 20)
print(json.dumps(mallinfo2().hblkhd - before))
"""

BATCH_BYTES = 28 << 20


def mapped_for_a_batch(setting: str) -> int:
    """Bytes of fresh mappings malloc made for one batch-sized tensor."""
    command = [sys.executable, "-c", _BATCH, setting]
    return json.loads(subprocess.run(command, check=True, capture_output=True, text=True).stdout)


@pytest.mark.skipif(_glibc_mallopt() is None, reason="glibc's mallopt only")
def test_batch_sized_tensors_come_from_the_heap_not_fresh_mappings() -> None:
    """glibc maps a fresh block for a 28 MiB tensor (and unmaps it on free, so the next step
    faults its pages in again); with the threshold fixed it comes from the heap. Deterministic,
    unlike the page faults it saves, which the kernel's own memory management moves from run to
    run."""
    assert mapped_for_a_batch("default") >= BATCH_BYTES
    assert mapped_for_a_batch("keep") == 0


def test_thresholds_outside_glibcs_range_are_refused() -> None:
    with pytest.raises(ValueError, match="mmap threshold must be in"):
        keep_batches_in_heap(MAX_MMAP_THRESHOLD + 1)
