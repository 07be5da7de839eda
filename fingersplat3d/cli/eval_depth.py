"""``fs3d eval depth``: depth error against PolyU 3D+ height maps or a capture's depth."""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

from ..atomic import atomic_dir, check_free
from ..errors import InputError
from .common import finished, refuse_missing

__all__ = ["add", "run"]

NAME = "depth"
HELP = "depth error against PolyU 3D+ height maps or a capture's depth/"


def add(actions) -> None:
    """``fs3d eval depth``: its arguments."""
    depth = actions.add_parser(
        NAME, help=HELP,
        description="Reconstruct each image alone (monocular mode) and compare its depth with the height map of the "
                    "same name in --truth (PolyU 3D+ .mat files: the variable 'fc', flipped upside down), or fuse "
                    "capture folders and compare every view with its depth/. Mean absolute error after a "
                    "least-squares scale + shift, after a scale only, and weighted by the reconstruction's "
                    "confidence. Writes depth_errors.csv, summary.md and error_maps/.")
    depth.add_argument("inputs", nargs="+", type=Path, help="images or folders of images (with --truth), or capture folders")
    depth.add_argument("--truth", type=Path, help="folder of .mat height maps named after the images")
    depth.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    depth.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    depth.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    refuse_missing(args.inputs)  # said before torch loads (~2 s)
    from ..experiments.depth import capture_cases, polyu_cases, run_depth_evaluation
    from ..pipeline import FuseConfig

    check_free(args.output, args.overwrite)
    unpaired = ([], [])
    if args.truth is not None:
        cases, *unpaired = polyu_cases(args.inputs, args.truth)
        if not cases:
            raise InputError(f"no image in {', '.join(map(str, args.inputs))} has a height map of the same name in {args.truth}")
        for path in unpaired[0]:
            print(f"fs3d eval depth: {path} has no height map in {args.truth}; skipped", file=sys.stderr)
        for path in unpaired[1]:
            print(f"fs3d eval depth: {path} has no image; skipped", file=sys.stderr)
    else:
        cases = capture_cases(args.inputs)
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:  # complete or absent
        rows = run_depth_evaluation(cases, folder, FuseConfig(splat=None), unpaired=tuple(unpaired))
    done = [r for r in rows if r["status"] == "done"]
    if done:
        print(f"wrote {args.output}: {len(done)} of {len(rows)} scored; mean MAE after scale + shift "
              f"{statistics.mean(r['mae_scale_shift'] for r in done):.4f}, confidence-weighted "
              f"{statistics.mean(r['mae_weighted'] for r in done):.4f} (ground-truth units)")
    return finished("fs3d eval depth", len(rows) - len(done), len(rows), "could not be scored", args.output)
