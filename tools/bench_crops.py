"""Another group's cropped finger renders (IMPOSE dev sample): triplets of known rolls, geometry only.

    python3 tools/bench_crops.py [--data ../shared/data/impose-dev]

Each triplet of ``sample2_<roll>.png`` files is fused as given (no cameras), then all of them at once; every
registered pair's relative rotation angle is compared with the difference of its rolls. Prints a markdown table.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "impose-dev"
TRIPLETS = ((-13, 0, 14), (-18, 0, 23), (-45, -18, 14), (-13, 14, 48), (-38, 0, 48), (-45, 0, 47))


def main() -> int:
    from fingersplat3d.eval.machine import machine
    from fingersplat3d.eval.poses import rotation_angle_deg
    from fingersplat3d.io.datasets import load_any
    from fingersplat3d.pipeline import FuseConfig, fuse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = parser.parse_args()
    if not args.data.is_dir():
        print(f"bench_crops: {args.data}: no such folder", file=sys.stderr)
        return 2
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores; geometry only.\n")
    print("| rolls ° | views registered | pair errors ° (registered pairs) | turn sensitivity ° (same pairs) | residual px |\n"
          "|---|---|---|---|---|")
    errors_all, moves_all = [], []
    every = tuple(sorted(int(path.stem.split("_")[-1]) for path in args.data.glob("sample2_*.png")
                         if path.stem.split("_")[-1].lstrip("-").isdigit()))
    for rolls in TRIPLETS + ((every,) if len(every) > 3 else ()):
        capture = load_any([args.data / f"sample2_{roll}.png" for roll in rolls])[0]
        result = fuse(capture, FuseConfig(splat=None))
        aligned = list(result.report["alignment"]["aligned"].values())
        rotations = [camera.world_to_cam[:3, :3] for camera in result.cameras]
        n = len(rolls)
        errors = [abs(float(rotation_angle_deg(rotations[j] @ rotations[i].T, np.eye(3))) - abs(rolls[j] - rolls[i]))
                  for i in range(n) for j in range(i + 1, n) if aligned[i] and aligned[j]]
        names = result.capture.names
        sensitivity = result.report["alignment"].get("turn_sensitivity_deg", {})
        moves = [sensitivity.get(f"{names[i]}-{names[j]}", float("nan"))
                 for i in range(n) for j in range(i + 1, n) if aligned[i] and aligned[j]]
        if n == 3:
            shown = ", ".join(f"{e:.1f}" for e in errors) or "–"
            shown_moves = ", ".join(f"{m:.1f}" for m in moves) or "–"
            errors_all += errors
            moves_all += moves
        else:  # every view of the sample at once: the pairs' median and worst
            shown = f"median {np.median(errors):.2f}, max {np.max(errors):.2f} ({len(errors)} pairs)" if errors else "–"
            shown_moves = f"median {np.nanmedian(moves):.2f}, max {np.nanmax(moves):.2f}" if moves else "–"
        print(f"| {' / '.join(map(str, rolls))} | {sum(aligned)}/{n} | {shown} | {shown_moves} | "
              f"{result.report['alignment']['residual_px']:.2f} |", flush=True)
    if len(errors_all) > 2:
        from scipy.stats import spearmanr

        rho = spearmanr(moves_all, errors_all)
        print(f"\nTriplets' pairs: turn sensitivity against error, Spearman {rho.statistic:.2f} (p = {rho.pvalue:.2g}).")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
