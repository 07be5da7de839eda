"""One capture of a dataset run, as a worker does it: load, fuse (+ splat, + novel views), write, mark done.

Never lose work: the capture's folder is written into a hidden temporary folder next to it and
renamed into place only when everything is written (:func:`fingersplat3d.atomic.atomic_dir`), so
``OUT/<capture>/`` is either complete (with its ``batch.json`` row) or absent, whatever kills the
run. A capture that fails (a bad image, views that cannot be registered at all) leaves
``OUT/.failed/<capture>.json`` with the reason instead, and the run goes on.
"""
from __future__ import annotations

import json
import resource
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..atomic import atomic_dir, atomic_path
from ..errors import InputError
from ..io.jsonio import to_jsonable
from ..io.jobs import CaptureJob

__all__ = ["BatchOptions", "FAILED", "ROW_FILE", "process_capture", "failure_path", "record_failure"]

FAILED = ".failed"
ROW_FILE = "batch.json"
THUMB_WIDTH = 240


@dataclass(frozen=True)
class BatchOptions:
    """What each capture gets (picklable: it travels to the workers)."""

    fuse: object  # pipeline.FuseConfig (splat None = geometry only)
    render: int = 12  # novel views on the arc (0 = none; needs the splat)
    rig: object | None = None  # align.solve.rig.Rig, fixed poses
    threads: int = 1  # torch threads in the worker
    force: bool = False  # redo a complete capture


def failure_path(out: Path, name: str) -> Path:
    return Path(out) / FAILED / f"{name}.json"


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _rig_angles(cameras) -> dict:
    from ..eval.poses import rotation_angle_deg

    return {f"{i}-{j}": round(float(rotation_angle_deg(cameras[i].rotation, cameras[j].rotation)), 3)
            for i in range(len(cameras)) for j in range(i + 1, len(cameras))}


def _thumbnails(folder: Path, capture) -> None:
    import cv2

    from ..io.images import write_image

    (folder / "thumbs").mkdir()
    for view in capture.views:
        scale = THUMB_WIDTH / view.width
        image = cv2.resize(np.asarray(view.image, np.float32), (THUMB_WIDTH, max(1, round(view.height * scale))),
                           interpolation=cv2.INTER_AREA)
        write_image(folder / "thumbs" / f"{view.name}.png", np.clip(image, 0, 1))


def _render_arc(folder: Path, result, count: int) -> None:
    from ..io.renders import write_renders
    from ..splat.novel import arc_views_at

    views = arc_views_at(result.gaussians, result.cameras, count, THUMB_WIDTH * 2)
    write_renders(folder / "renders", views, result.units, result.scale_mm_per_unit)


def record_failure(out: Path, row: dict) -> Path:
    """Write a failed capture's row to ``out/.failed/<capture>.json`` (atomically); returns the path."""
    path = failure_path(out, row["capture"])
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(row, indent=2, default=str) + "\n")
    return path


def process_capture(job: CaptureJob, out: str, options: BatchOptions) -> dict:
    """Fuse ``job`` into ``out/<name>/``; the row of the results table (``status``: done, not_registered, failed)."""
    from ..device import use_threads
    from ..geometry import skip_open3d_web_viewer

    skip_open3d_web_viewer()  # before the pipeline's modules load Open3D
    from ..pipeline import fuse, write_reconstruction_files

    use_threads(options.threads)
    out = Path(out)
    started = time.perf_counter()
    row = {"capture": job.name, "status": "failed", "reason": "", "seconds": None, "peak_rss_mb": None,
           "residual_px": None, "focal_px": None, "views": None, "gaussians": None, "rig_angles_deg": None}
    try:
        from ..io.jobs import load_job

        capture = load_job(job)
        result = fuse(capture, options.fuse, rig=options.rig)
        alignment = result.report["alignment"]
        # As JSON holds them: where no view registered the residual is NaN, and the row's JSON has no NaN (null).
        row.update(to_jsonable(dict(
            status="done" if result.registered else "not_registered", reason=alignment.get("reason", ""),
            residual_px=alignment.get("residual_px"), focal_px=(alignment.get("focals_px") or [None])[0],
            views=len(capture), gaussians=None if result.gaussians is None else len(result.gaussians),
            rig_angles_deg=_rig_angles(result.cameras)), "batch row"))
        with atomic_dir(out / job.name, overwrite=options.force) as temporary:
            write_reconstruction_files(result, temporary)
            _thumbnails(temporary, capture)
            if options.render and result.gaussians is not None and result.registered:
                _render_arc(temporary, result, options.render)
            row.update(seconds=round(time.perf_counter() - started, 3), peak_rss_mb=round(_peak_rss_mb(), 1))
            (temporary / ROW_FILE).write_text(json.dumps(row, indent=2, allow_nan=False) + "\n")
        failure_path(out, job.name).unlink(missing_ok=True)
        return row
    except (InputError, FileExistsError, ValueError, RuntimeError, OSError, MemoryError) as error:
        row.update(status="failed", reason=" ".join(str(error).split()) or type(error).__name__,
                   seconds=round(time.perf_counter() - started, 3), peak_rss_mb=round(_peak_rss_mb(), 1))
        if not isinstance(error, InputError):
            row["trace"] = traceback.format_exc(limit=4)
        record_failure(out, row)
        return row
