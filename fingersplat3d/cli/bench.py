"""``fs3d bench``: the speed / accuracy sweep."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..atomic import atomic_dir, check_free
from ..errors import InputError
from .common import finished
from .types import COUNT, size

__all__ = ["add", "run"]

NAME = "bench"
HELP = "the speed / accuracy trade: presets and knobs swept, time and memory against error"


def add(commands) -> None:
    """``fs3d bench``: its arguments."""
    from ..experiments.bench import sweep
    from ..splat.config import PRESETS

    knobs = ("preset", "resolution", "iterations", "gaussians", "views")
    bench = commands.add_parser(
        NAME, help=HELP,
        description="Fuse synthetic captures (ring rig, varied finger shapes by seed) under a baseline preset and "
                    "under a sweep of one knob at a time (presets, working resolution, fit iterations, Gaussian "
                    "budget, number of views), each run in a fresh process: stage times and peak memory against "
                    "depth error, rotation error and held-out PSNR; with --real, the rig consistency of real "
                    "captures per working resolution. Writes bench.csv, summary.md, trade_depth.png and trade_psnr.png.")
    bench.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    bench.add_argument("--seeds", type=COUNT, default=2, help="synthetic fingers per setting (default 2)")
    bench.add_argument("--size", type=size, default=(640, 512), help="synthetic image size WxH (default 640x512)")
    bench.add_argument("--preset", choices=sorted(PRESETS), default="fast", help="the baseline preset (default fast)")
    bench.add_argument("--presets", default="fast,balanced",
                       help="presets the preset knob compares, comma-separated (default fast,balanced)")
    bench.add_argument("--knobs", default=",".join(knobs),
                       help=f"knobs to sweep, comma-separated, from {','.join(knobs)} (default all)")
    bench.add_argument("--real", type=Path, help="a folder of real rig captures (UWA naming) for rig consistency")
    bench.add_argument("--device", default="auto", help="where the fits run: auto (CUDA when available), cpu, cuda")
    bench.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    bench.set_defaults(run=run, sweep=sweep, all_knobs=knobs)


def run(args: argparse.Namespace) -> int:
    from ..experiments.bench import run_bench
    from ..splat.config import PRESETS

    knobs = tuple(k.strip() for k in args.knobs.split(",") if k.strip())
    unknown = [k for k in knobs if k not in args.all_knobs]
    presets = tuple(p.strip() for p in args.presets.split(",") if p.strip())
    unknown_presets = [p for p in presets if p not in PRESETS]
    if unknown or unknown_presets:
        raise InputError(f"unknown {'knob' if unknown else 'preset'} {(unknown or unknown_presets)[0]!r}: choose from "
                         f"{', '.join(args.all_knobs if unknown else sorted(PRESETS))}")
    if args.seeds < 1:
        raise InputError(f"--seeds {args.seeds}: give at least 1")
    if args.real is not None and not args.real.is_dir():
        raise InputError(f"{args.real}: not a folder of real captures")
    check_free(args.output, args.overwrite)
    settings = args.sweep(args.preset, presets, knobs)
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        result = run_bench(settings, list(range(args.seeds)), folder, size=args.size, real=args.real, device=args.device)
    failed = [r for r in result["rows"] if r["status"] != "done"]
    print(f"wrote {args.output}: {len(result['rows']) - len(failed)} of {len(result['rows'])} runs")
    return finished("fs3d bench", len(failed), len(result["rows"]), "runs failed", args.output)
