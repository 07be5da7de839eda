"""How experiments run a measurement: each in a fresh process, its peak memory its own."""
from __future__ import annotations

import multiprocessing
import resource
from concurrent.futures import ProcessPoolExecutor

__all__ = ["in_fresh_process", "peak_rss_mb"]


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, MB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def in_fresh_process(function, *args):
    """``function(*args)`` in a fresh process (spawned: nothing inherited, so its time and memory are its own)."""
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(function, *args).result()
