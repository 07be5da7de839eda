"""``fs3d batch``: every capture of a dataset reconstructed on Ray, resumable."""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from ..errors import EXIT_INCOMPLETE, InputError
from .options import add_dataset_arguments, add_splat_arguments, fuse_config, read_rig
from .types import POSITIVE, number

__all__ = ["add", "run"]

NAME = "batch"
HELP = "reconstruct every capture of a dataset on Ray, resumable, with a results table and an HTML report"


def add(commands) -> None:
    """``fs3d batch``: its arguments."""
    batch = commands.add_parser(
        NAME, help=HELP,
        description="Fuse (and splat and render) every capture of a dataset, each as one Ray task (a local Ray "
                    "instance by default, --address to join a cluster). OUT/<capture>/ is written exactly as "
                    "'fs3d fuse' writes it (+ renders/ and thumbs/) and appears only when complete; a re-run "
                    "skips complete captures. A failing capture is recorded (OUT/.failed/, results.csv) and the "
                    "run goes on. Writes OUT/results.csv and OUT/report.html.")
    add_dataset_arguments(batch)
    batch.add_argument("-o", "--output", type=Path, required=True, help="folder of the capture folders and results")
    batch.add_argument("--rig", type=Path, help="rig.json from 'fs3d rig calibrate': fixed camera poses and focal")
    batch.add_argument("--focal-px", type=POSITIVE,
                       help="the cameras' focal length in the photos' pixels, when known: kept instead of fitted per capture")
    batch.add_argument("--device", default="cpu",
                       help="where each capture's splat fit runs: cpu (default) or cuda (each task then declares one GPU)")
    add_splat_arguments(batch)
    batch.add_argument("--render-count", type=number(int, 0, 1000), default=12, help="novel views per capture (0 = none; default 12)")
    batch.add_argument("--mesh", action="store_true", help="also write mesh.ply per capture")
    batch.add_argument("--force", action="store_true", help="redo complete captures")
    batch.add_argument("--retry-failed", action="store_true", help="run again the captures that failed before")
    batch.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..io.jobs import list_jobs

    jobs = list_jobs(args.dataset, args.select)  # a wrong path or selection is said before torch loads (~2 s)
    if args.device not in ("cpu", "cuda") and not args.device.startswith("cuda:"):
        raise InputError(f"--device {args.device!r}: use cpu or cuda")
    from ..batch.run import run_batch
    from ..batch.task import BatchOptions
    from ..pipeline import refuse_focal_with_rig

    refuse_focal_with_rig(args.focal_px, args.rig)
    config = replace(fuse_config(args), device=args.device, focal_px=args.focal_px)
    options = BatchOptions(fuse=config, render=0 if args.no_splat else args.render_count, rig=read_rig(args.rig),
                           threads=args.threads_per_task, force=args.force)
    run = run_batch(jobs, args.output, options, address=args.address, num_cpus=args.workers, retry_failed=args.retry_failed)
    done = sum(row["status"] == "done" for row in run.rows)
    print(f"wrote {args.output}: {done} of {len(jobs)} captures complete ({run.submitted} run now, {run.skipped_complete} "
          f"complete before, {run.skipped_failed} failed before) in {run.engine['wall_s']:.1f} s; "
          f"{args.output / 'results.csv'}, {args.output / 'report.html'}")
    if done < len(jobs):
        print(f"fs3d batch: {len(jobs) - done} of {len(jobs)} captures failed or were not registered; "
              f"{args.output / 'results.csv'} says why", file=sys.stderr)
        return EXIT_INCOMPLETE
    return 0
