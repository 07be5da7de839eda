"""Where work runs: the torch device (``auto`` is CUDA when present, else the CPU) and the CPU threads.

:func:`cpu_threads` is the one setting for how many threads CPU work uses: the ``FS3D_THREADS``
environment variable when set, else the cores this process may run on (its CPU affinity and, in a
container or a Ray worker, its cgroup CPU quota), so that a process never starts more threads than
it was given cores.
"""
from __future__ import annotations

import math
import os
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import Callable, Iterator, Sequence, TypeVar

import torch

from .errors import InputError

Item = TypeVar("Item")
Result = TypeVar("Result")

__all__ = ["resolve_device", "cpu_threads", "numba_threads", "use_threads", "single_threaded", "per_item"]


def resolve_device(device: str | torch.device | None = "auto") -> torch.device:
    """``auto``/None -> CUDA when available, else CPU; ``cpu``, ``cuda``, ``cuda:N`` as given (checked)."""
    if device is None or device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        resolved = torch.device(device)
    except (RuntimeError, TypeError):
        raise InputError(f"unknown device {device!r}; use auto, cpu, cuda or cuda:N") from None
    if resolved.type not in ("cpu", "cuda"):
        raise InputError(f"unsupported device {device!r}; use auto, cpu, cuda or cuda:N")
    if resolved.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"device {device!r} was asked for but CUDA is not available here")
    return resolved


@lru_cache(maxsize=1)
def _cgroup_quota() -> float | None:
    """CPUs allowed by the cgroup v2 (``cpu.max``) or v1 (``cfs_quota_us / cfs_period_us``) quota, if any; read once
    a process (every render asks: three files a call had cost ~0.1 ms)."""
    try:
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()[:2]
        return None if quota == "max" else int(quota) / int(period)
    except (OSError, ValueError):
        pass
    try:
        quota = int(Path("/sys/fs/cgroup/cpu/cpu.cfs_quota_us").read_text())
        period = int(Path("/sys/fs/cgroup/cpu/cpu.cfs_period_us").read_text())
        return quota / period if quota > 0 and period > 0 else None
    except (OSError, ValueError):
        return None


def cpu_threads() -> int:
    """Threads for CPU work (see the module docstring); at least 1."""
    setting = os.environ.get("FS3D_THREADS", "").strip()
    if setting:
        try:
            return max(1, int(setting))
        except ValueError:
            raise InputError(f"FS3D_THREADS must be a whole number of threads, got {setting!r}") from None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    quota = _cgroup_quota()
    if quota is not None:
        cores = min(cores, max(1, math.floor(quota)))
    return max(1, cores)


def numba_threads() -> int:
    """Threads for the numba kernels (the rasterizer's, the alignment's normal matrix): :func:`cpu_threads`, capped at
    numba's pool size, made numba's count for the next kernel. Called before each launch, it also sets numba's threading
    layers' order before the first: OpenMP first (torch uses it too), then numba's own pool, TBB only when nothing else
    loads (an old libtbb on the path would otherwise be tried first and rejected with a warning)."""
    import numba

    numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
    threads = min(cpu_threads(), numba.config.NUMBA_NUM_THREADS)
    numba.set_num_threads(threads)
    return threads


def use_threads(threads: int) -> None:
    """Make ``threads`` the process's setting (a Ray task that declared that many CPUs): torch's
    pool, the BLAS and OpenMP pools loaded by then (numpy's and scipy's; threadpoolctl reaches only
    libraries already loaded) and, through ``FS3D_THREADS``, every later :func:`cpu_threads` (the
    numba kernels)."""
    from threadpoolctl import threadpool_limits

    threads = max(1, int(threads))
    os.environ["FS3D_THREADS"] = str(threads)
    torch.set_num_threads(threads)
    threadpool_limits(limits=threads)


@contextmanager
def single_threaded() -> Iterator[None]:
    """Torch, OpenCV and the BLAS/OpenMP pools under numpy and scipy on one thread for the duration:
    for many small operations (a Levenberg-Marquardt loop over a few hundred unknowns, per-patch
    matching), where worker threads only add hand-offs and, beside another busy process, spin on the
    cores that process needs. The BLAS pool is limited through threadpoolctl (numpy has no setting of
    its own): a real capture's registration beside another process using both cores took 18.6 s
    with it free and 8.2 s with it held here (4.5 s alone)."""
    import cv2
    from threadpoolctl import threadpool_limits

    torch_threads, cv_threads = torch.get_num_threads(), cv2.getNumThreads()
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    try:
        with threadpool_limits(limits=1):
            yield
    finally:
        torch.set_num_threads(torch_threads)
        cv2.setNumThreads(cv_threads)


def per_item(function: Callable[[Item], Result], items: Sequence[Item]) -> list[Result]:
    """``[function(item) for item in items]``, the items on :func:`cpu_threads` threads at once with the libraries
    under them on one thread each (:func:`single_threaded`): for work whose items are OpenCV, numpy and Open3D calls
    that release the GIL, each one too small for those libraries' own threads to pay (a capture's few views: masks,
    ridge periods, pointmaps, clouds; a pair's patch searches). The results are in the items' order and the same as
    one at a time; the first item (in order) whose call raises raises here. A single item keeps the libraries' own
    threads; a process given one core runs its items in turn, the libraries on one thread all the same."""
    from concurrent.futures import ThreadPoolExecutor

    items = list(items)
    cores = cpu_threads()
    if cores > 1 and len(items) <= 1:
        return [function(item) for item in items]
    with single_threaded():
        if cores == 1:
            return [function(item) for item in items]
        with ThreadPoolExecutor(min(cores, len(items))) as pool:
            return list(pool.map(function, items))
