"""How experiments run a measurement: each in a fresh process, its peak memory its own."""
from __future__ import annotations

import multiprocessing
import resource
from concurrent.futures import ProcessPoolExecutor

__all__ = ["in_fresh_process", "peak_rss_mb"]


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, MB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _as_fs3d_runs(function, *args):
    """``function(*args)`` in a process set up as ``fs3d``'s own (:func:`~fingersplat3d.cli.main.main`) and its batch
    workers are: Open3D loaded without its Plotly/Dash viewer, so that a measured time is what the command takes."""
    from ..geometry import skip_open3d_web_viewer

    skip_open3d_web_viewer()
    return function(*args)


def in_fresh_process(function, *args):
    """``function(*args)`` in a fresh process (spawned: nothing inherited, so its time and memory are its own), set up
    as ``fs3d``'s are (:func:`_as_fs3d_runs`)."""
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_as_fs3d_runs, function, *args).result()
