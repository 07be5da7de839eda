"""``fs3d eval register``: minutiae carried between views, 3D vs the 2D baselines."""
from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from ..atomic import atomic_dir, check_free
from ..errors import InputError
from .common import finished, nbis_needed
from .types import view_pairs

__all__ = ["add", "run"]

NAME = "register"
HELP = "minutiae carried between views: 3D model vs rigid 2D and TPS baselines"


def add(actions) -> None:
    register = actions.add_parser(
        NAME, help=HELP,
        description="Carry minutiae of view A into view B through each reconstruction (depth + cameras) and with "
                    "the paper's 2D baselines (a RANSAC similarity and a thin-plate spline, fitted to the mates and "
                    "cross-validated), and measure the mean pixel distance to their mates in B. Mates: --mates CSV, "
                    "else ground truth (minutiae.json beside the capture's images/, or --truth), else mindtct minutiae "
                    "of both photos paired as bozorth3 pairs them (the paper's UWA* protocol). Writes "
                    "register_errors.csv, mates/, pictures/ and summary.md.")
    register.add_argument("reconstructions", nargs="+", type=Path, help="reconstruction folders from 'fs3d fuse'")
    register.add_argument("--pairs", type=view_pairs,
                          help="view pairs as A:B, comma-separated (default: the middle camera to each other camera)")
    register.add_argument("--mates", type=Path, help="CSV with columns view_a, view_b, x_a, y_a, x_b, y_b")
    register.add_argument("--truth", type=Path, help="minutiae.json with per-view ground truth (fs3d synth)")
    register.add_argument("--matcher", action="store_true",
                          help="mates from mindtct + bozorth3-style pairing even where ground truth exists (UWA*)")
    register.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    register.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    register.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..experiments.register import run_register_evaluation

    check_free(args.output, args.overwrite)
    if args.matcher and (args.mates is not None or args.truth is not None):
        raise InputError("--matcher takes the mates from the photos: leave out --mates and --truth")
    if args.mates is None and args.truth is None:
        nbis_needed("fs3d eval register (without --mates or --truth)")
    if args.mates is not None and len(args.reconstructions) > 1:
        raise InputError("--mates holds one reconstruction's mates: give one reconstruction with it")
    for path in (args.mates, args.truth):
        if path is not None and not path.is_file():
            raise InputError(f"{path}: not found")
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        rows = run_register_evaluation(args.reconstructions, folder, pairs=args.pairs, mates_csv=args.mates,
                                       truth=args.truth, matcher=args.matcher)
    done = [r for r in rows if r["status"] == "done"]
    for method in ("3D", "rigid 2D", "TPS"):
        values = [r["mean_px"] for r in done if r["method"] == method]
        if values:
            print(f"{method}: mean {statistics.mean(values):.2f} px over {len(values)} view pair(s)")
    print(f"wrote {args.output}")
    return finished("fs3d eval register", len(rows) - len(done), len(rows), "could not be scored", args.output)
