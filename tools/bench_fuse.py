"""The geometry of ``fs3d fuse`` against synthetic ground truth, per rig and number of views.

    python3 tools/bench_fuse.py [--seeds 3] [--cases ring2,ring3,ring5,uwa3,cfpose2,cfpose3,cfpose5]
        [--ridge-px 16] [--csv out.csv]

Cases and scoring: :mod:`fingersplat3d.experiments.geometry` (images and masks only; rotation error of
every view pair, depth MAE after scale + shift over each whole view). Each case runs in a fresh process.
Prints the markdown table of docs/measurements.md and the machine it ran on.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fingersplat3d.errors import run_script


def main() -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.experiments.geometry import CASES, geometry_table, run_geometry
    from fingersplat3d.experiments.tables import write_rows
    from fingersplat3d.pipeline import FuseConfig
    from fingersplat3d.working_scale import RIDGE_PX

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="synthetic fingers per case, seeds 0..N-1 (default 3)")
    parser.add_argument("--cases", default="ring2,ring3,ring5,uwa3,cfpose2,cfpose3,cfpose5",
                        help=f"comma-separated, from {','.join(CASES)}")
    parser.add_argument("--ridge-px", type=float, default=RIDGE_PX,
                        help=f"working pixels per ridge period (default {RIDGE_PX:g}; 0: the photos' own resolution)")
    parser.add_argument("--csv", type=Path, help="write every row here")
    args = parser.parse_args()
    names = [name.strip() for name in args.cases.split(",") if name.strip()]
    unknown = [name for name in names if name not in CASES]
    if unknown or args.seeds < 1:
        print(f"bench_fuse: unknown case {unknown[0]!r}" if unknown else "bench_fuse: --seeds must be at least 1",
              file=sys.stderr)
        return 2
    rows = run_geometry([CASES[name] for name in names], list(range(args.seeds)),
                        FuseConfig(splat=None, ridge_px=args.ridge_px or None))
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores, load {info['load'][0]:.2f}; torch {info['torch']}; "
          f"seeds 0-{args.seeds - 1}, geometry only, {args.ridge_px:g} px per ridge (0: photo resolution).\n")
    print(geometry_table(rows))
    if args.csv:
        columns = ("case", "seed", "views", "status", "reason", "registered_all", "rotation_error_deg", "rotation_mean_deg",
                   "rotation_max_deg", "turn_uncertainty_max_deg", "turn_sensitivity_max_deg", "depth_mae_mm", "depth_worst_view_mm",
                   "depth_two_views_mm", "depth_one_view_mm", "residual_px", "warned", "skin_loop", "wall_s", "peak_rss_mb")
        write_rows(args.csv, columns, rows)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
