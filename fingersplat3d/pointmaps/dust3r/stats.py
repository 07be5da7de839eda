"""Time and peak memory of network inference, for the report and the benchmark.

CPU peak memory is the largest resident-set size seen while the work ran (sampled every 2 ms from
``/proc/self/statm``) minus the size when it started, after glibc has returned freed memory to the
OS: what inference added, not what the process held before. On CUDA it is ``torch.cuda.max_memory_allocated`` over the call.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass

import torch

__all__ = ["InferenceStats", "PeakMemory"]


@dataclass(frozen=True)
class InferenceStats:
    """One backend call."""

    task: str
    """``views`` (monocular passes, the image paired with itself) or ``pairs``."""
    device: str
    """Where the network ran."""
    forward_passes: int
    """Ordered image pairs decoded (a symmetrised pair counts 2)."""
    images_encoded: int
    """Images run through the encoder (each distinct image once per backend)."""
    seconds: float
    """Wall time of the call (preprocessing, network, mapping back)."""
    seconds_per_pair: float
    """``seconds / forward_passes``."""
    peak_memory_mb: float
    """Peak memory added during the call (see the module docstring)."""
    network_size: tuple[int, int]
    """(width, height) of the network input of the first image."""


def _release_free_memory() -> None:
    """Hand memory that was freed but kept by glibc's allocator back to the OS (so RSS tracks use)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def _rss_bytes() -> int:
    try:
        with open("/proc/self/statm") as handle:
            return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):  # not Linux
        return 0


class PeakMemory:
    """``with PeakMemory(device) as peak: ...``; then ``peak.megabytes``."""

    def __init__(self, device: torch.device) -> None:
        self.device = device
        self.megabytes = 0.0
        self._stop = threading.Event()
        self._peak = 0

    def __enter__(self) -> "PeakMemory":
        self._started = time.perf_counter()
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
            torch.cuda.reset_peak_memory_stats(self.device)
            self._base = torch.cuda.memory_allocated(self.device)
        else:
            _release_free_memory()
            self._base = self._peak = _rss_bytes()
            self._thread = threading.Thread(target=self._sample, daemon=True)
            self._thread.start()
        return self

    def _sample(self) -> None:
        while not self._stop.wait(0.002):
            self._peak = max(self._peak, _rss_bytes())

    def __exit__(self, *exc) -> None:
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
            peak = torch.cuda.max_memory_allocated(self.device)
        else:
            self._stop.set()
            self._thread.join()
            peak = max(self._peak, _rss_bytes())
        self.megabytes = max(peak - self._base, 0) / 2 ** 20
        self.seconds = time.perf_counter() - self._started
