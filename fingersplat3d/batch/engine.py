"""Run one function over many items on Ray: a local instance by default, a user's cluster by address.

Each item is one Ray task with ``cpus_per_task`` CPUs (and ``gpus_per_task`` GPUs) declared (so Ray
never runs more tasks on a node than it has cores or GPUs for) and the same number of torch threads inside it, so that the node is
not oversubscribed; items travel by value but are small (file paths, not images). Tasks are
submitted a bounded number ahead of the finished ones, results are handed to ``on_result`` in the
driver as they come (which is where they are persisted), and a task whose worker dies is a
failure with that reason, not a crash of the run. One progress bar with rate and ETA.
Ray is imported on use.
"""
from __future__ import annotations

import os
from typing import Any, Callable, Sequence

__all__ = ["ray_map"]


def ray_map(function: Callable, items: Sequence[Any], args: tuple, on_result: Callable[[Any, Any, str | None], None], *,
            address: str | None = None, cpus_per_task: int = 1, gpus_per_task: float = 0, num_cpus: int | None = None,
            desc: str = "fs3d batch", progress: bool = True) -> dict:
    """``function(item, *args)`` for every item on Ray; ``on_result(item, result, error)`` as each one ends.

    ``error`` is None, or one sentence when the task raised or its worker died. Returns figures
    of the run: ``cpus`` (of the cluster), ``tasks``, ``wall_s``.
    """
    import time

    import ray
    from tqdm import tqdm

    from ..device import cpu_threads

    started = time.perf_counter()
    if not ray.is_initialized():
        options = dict(include_dashboard=False, log_to_driver=False, configure_logging=False)
        if address:
            ray.init(address=address, **options)
        else:
            ray.init(num_cpus=num_cpus or cpu_threads(), **options)  # the cores this process may use
    cpus = int(ray.cluster_resources().get("CPU", 1))
    remote = ray.remote(num_cpus=cpus_per_task, num_gpus=gpus_per_task, max_retries=0)(function)
    window = max(1, 2 * cpus // max(1, cpus_per_task))
    pending: dict = {}
    queue = list(items)
    bar = tqdm(total=len(queue), desc=desc, unit="capture", disable=not progress, smoothing=0.1)
    try:
        while queue or pending:
            while queue and len(pending) < window:
                item = queue.pop(0)
                pending[remote.options(name=f"{desc}: {getattr(item, 'name', item)}").remote(item, *args)] = item
            done, _ = ray.wait(list(pending), num_returns=1)
            for reference in done:
                item = pending.pop(reference)
                try:
                    result, error = ray.get(reference), None
                except ray.exceptions.RayError as failure:
                    cause = getattr(failure, "cause", None) or failure
                    result, error = None, " ".join(str(cause).split())[:500] or type(failure).__name__
                on_result(item, result, error)
                bar.update()
    finally:
        bar.close()
    return {"cpus": cpus, "tasks": len(items), "wall_s": time.perf_counter() - started, "pid": os.getpid()}
