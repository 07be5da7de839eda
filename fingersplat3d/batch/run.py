"""``fs3d batch``: a dataset fused capture by capture on Ray, resumable (see :mod:`.task` for what is written).

A re-run skips the complete captures (``force`` redoes them), leaves earlier failures recorded
unless ``retry_failed``, and removes the hidden temporary folders an interrupted run left.
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from ..io.jobs import CaptureJob
from .engine import ray_map
from .results import write_results
from .task import FAILED, ROW_FILE, BatchOptions, failure_path, process_capture, record_failure

__all__ = ["BatchRun", "run_batch", "pending_jobs"]


@dataclass(frozen=True)
class BatchRun:
    rows: list[dict]
    submitted: int
    skipped_complete: int
    skipped_failed: int
    engine: dict


def _clean_partial(out: Path) -> int:
    """Remove the hidden ``.<name>.tmp-*`` / ``.old-*`` folders of an interrupted run; how many."""
    stale = [p for p in out.glob(".*") if p.is_dir() and (".tmp-" in p.name or ".old-" in p.name)]
    for path in stale:
        shutil.rmtree(path, ignore_errors=True)
    return len(stale)


def pending_jobs(jobs: Sequence[CaptureJob], out: Path, force: bool, retry_failed: bool) -> tuple[list[CaptureJob], int, int]:
    """The jobs to run, and how many were skipped as complete and as failed before."""
    todo, complete, failed = [], 0, 0
    for job in jobs:
        if (out / job.name / ROW_FILE).is_file() and not force:
            complete += 1
        elif failure_path(out, job.name).is_file() and not (retry_failed or force):
            failed += 1
        else:
            todo.append(job)
    return todo, complete, failed


def run_batch(jobs: Sequence[CaptureJob], out: str | Path, options: BatchOptions, *, address: str | None = None,
              num_cpus: int | None = None, retry_failed: bool = False, progress: bool = True) -> BatchRun:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / FAILED).mkdir(exist_ok=True)
    _clean_partial(out)
    names = [job.name for job in jobs]
    todo, complete, failed = pending_jobs(jobs, out, options.force, retry_failed)

    def on_result(job: CaptureJob, row: dict | None, error: str | None) -> None:
        if error is not None:  # the worker died or the task raised past its own guard: record it
            record_failure(out, {"capture": job.name, "status": "failed", "reason": error})
        write_results(out, names)

    engine = {"cpus": 0, "tasks": 0, "wall_s": 0.0}
    if todo:
        gpus = 1 if str(getattr(options.fuse, "device", "cpu")).startswith("cuda") else 0
        engine = ray_map(process_capture, todo, (str(out), options), on_result, address=address,
                         cpus_per_task=options.threads, gpus_per_task=gpus, num_cpus=num_cpus, progress=progress)
    rows = write_results(out, names)
    return BatchRun(rows, len(todo), complete, failed, engine)
