"""``fs3d rig calibrate``: a fixed rig's poses and focal lengths from many captures."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..atomic import check_free
from ..errors import EXIT_NOT_REGISTERED, InputError
from .options import add_dataset_arguments, fuse_config
from .types import number

__all__ = ["add", "run", "register_job", "shared_factor"]

NAME = "rig"
HELP = "a fixed camera rig: calibrate it from many captures"


def add(commands) -> None:
    """``fs3d rig calibrate``: its arguments."""
    rig = commands.add_parser(NAME, help=HELP,
                              description="Tools for a fixed multi-camera rig (UWA's three cameras).")
    actions = rig.add_subparsers(dest="action", metavar="ACTION", required=True)
    calibrate = actions.add_parser(
        "calibrate", help="estimate the rig's camera poses and focal from many captures (no target needed)",
        description="Register every capture (on Ray), then fit one set of camera poses and focal lengths to "
                    "the correspondences of all captures jointly, leaving out captures that disagree. Writes "
                    "rig.json (the cameras.json schema without the finger) for 'fs3d fuse --rig' and 'fs3d batch --rig'.")
    add_dataset_arguments(calibrate)
    calibrate.add_argument("-o", "--output", type=Path, required=True, help="rig.json to write")
    calibrate.add_argument("--rounds", type=number(int, 0, 20), default=0,
                           help="then re-match every capture through the calibrated rig and fit again, this many times "
                                "(default 0; each round costs one more registration per capture, see the README)")
    calibrate.add_argument("--focal", choices=("each", "one"), default="each",
                           help="each: every camera its own focal length (default; the UWA rig's front camera fits one "
                                "6 %% shorter than its side cameras'); one: one focal length for all cameras")
    calibrate.add_argument("--overwrite", action="store_true", help="replace an existing file")
    calibrate.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..io.jobs import list_jobs

    check_free(args.output, args.overwrite)
    jobs = list_jobs(args.dataset, args.select)  # a wrong path or selection is said before torch loads (~2 s)
    if len(jobs) < 2:  # one (list_jobs refuses none), said before it is registered: nothing could make up the second
        selected = f" ({args.select})" if args.select else ""
        raise InputError(f"1 capture in {', '.join(map(str, args.dataset))}{selected}; a rig needs at least 2")
    from ..align.solve.rig import calibrate_rig
    from ..align.solve.settings import GlobalAlignConfig
    from ..batch.engine import ray_map
    from ..io.rig import write_rig

    config = fuse_config(args)
    captures, failures = [], {}

    def on_result(job, capture, error):
        if error is not None:
            failures[job.name] = error
        elif not all(capture.alignment.aligned):
            failures[job.name] = "not every view registered"
        else:
            captures.append(capture)

    # One working resolution for every capture: the focal lengths the calibration pools are in its pixels.
    factor = shared_factor(jobs, config.ridge_px)

    def register(selected, rig=None, desc="fs3d rig calibrate"):
        return ray_map(register_job, selected, (config, args.threads_per_task, rig, factor), on_result,
                       address=args.address, cpus_per_task=args.threads_per_task, num_cpus=args.workers, desc=desc)

    def calibrated(selected):  # the rig file's focal is the photos'
        return calibrate_rig(sorted(selected, key=lambda c: c.name), names[0], fit,
                             per_camera_focal=args.focal == "each").in_photo_pixels(factor)

    run = register(jobs)
    names = sorted({c.view_names for c in captures})
    if len(captures) < 2:
        print(f"fs3d rig calibrate: only {len(captures)} of {len(jobs)} captures registered with all their views; "
              "a rig needs at least 2", file=sys.stderr)
        return EXIT_NOT_REGISTERED
    if len(names) != 1:
        raise InputError(f"the captures do not share one set of view names ({names}); a rig's captures must")
    start = time.perf_counter()
    fit = GlobalAlignConfig()  # Levenberg-Marquardt, as a single capture's alignment
    calibration = calibrated(captures)
    for round_ in range(args.rounds):  # re-match through the rig, fit again (its matches snap to the right ridges)
        used = [job for job in jobs if job.name in calibration.used]
        captures.clear()
        register(used, calibration.rig, desc=f"fs3d rig calibrate: round {round_ + 1}")
        if len(captures) < 2:
            break
        calibration = calibrated(captures)
    rig = calibration.rig
    rig.info.update(failed=failures, rounds=args.rounds, register_seconds=round(run["wall_s"], 1),
                    fit_seconds=round(time.perf_counter() - start, 1))
    write_rig(args.output, rig)
    from ..eval.poses import rotation_angle_deg

    angles = ", ".join(f"{rig.names[i]}-{rig.names[j]} {rotation_angle_deg(rig.rotations[i], rig.rotations[j]):.2f} deg"
                       for i in range(len(rig.names)) for j in range(i + 1, len(rig.names)))
    focals = (f"focal {rig.focal:.1f} px" if rig.one_focal else
              "focals " + ", ".join(f"{name} {focal:.1f}" for name, focal in zip(rig.names, rig.focals))
              + f" px (geometric mean {rig.focal:.1f})")
    print(f"wrote {args.output}: {len(calibration.used)} captures used ({len(calibration.left_out)} left out, "
          f"{len(failures)} not registered), {focals}, {angles}")
    return 0


def shared_factor(jobs, ridge_px: float | None) -> float:
    """One working resolution for every capture a rig pools (the focal lengths it pools are in its pixels): that of
    the first capture that can be read (1 when none can: their failures come later, each with its reason)."""
    from ..io.jobs import load_job
    from ..working_scale import working_views

    for job in jobs:
        try:
            return working_views(load_job(job).views, ridge_px)[2].factor
        except InputError:
            continue
    return 1.0


def register_job(job, config, threads: int, rig=None, factor: float | None = None):
    """A Ray task of 'fs3d rig calibrate': one capture registered (what the calibration pools)."""
    from ..device import use_threads
    from ..io.jobs import load_job
    from ..pipeline import register_capture

    use_threads(threads)
    return register_capture(load_job(job), config, rig, factor)
