"""Freed memory handed back to the system: pages glibc keeps for reuse after a fuse's arrays are freed."""
import numpy as np
import pytest

from fingersplat3d.heap import _trim, release_free_memory


def _resident_mb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * 4096 / 2**20


@pytest.mark.skipif(_trim() is None, reason="the C library has no malloc_trim")
def test_arrays_freed_on_the_heap_are_handed_back():
    big = np.ones(16 * 2**20 // 8)
    del big  # an mapped block freed: glibc now serves blocks up to its size from the heap, and keeps them when freed
    arrays = []
    for _ in range(100):  # 400 MB in 4 MB arrays, each with a small one after it
        arrays += [np.ones(4 * 2**20 // 8), np.ones(100)]
    held = _resident_mb()
    del arrays[:-2]
    kept = _resident_mb()
    assert kept > held - 100  # freed, still the process's
    assert release_free_memory()
    assert _resident_mb() < kept - 300

