"""Another group's cropped finger renders (IMPOSE dev sample): triplets of known rolls, geometry only.

    python3 tools/bench_crops.py [--data ../shared/data/impose-dev] [--all-triplets]

Each triplet of ``sample2_<roll>.png`` files is fused as given (no cameras), then all of them at once; every
registered pair's relative rotation angle is compared with the difference of its rolls. Prints a markdown table.
With ``--all-triplets``, every triplet of the rolls instead (84 of nine; ~20 s each on 2 cores): how many came out
whole and within 2° / 1° at their worst pair, the pairs' median and worst error, and the triplets that were not.
"""
from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "impose-dev"
TRIPLETS = ((-13, 0, 14), (-18, 0, 23), (-45, -18, 14), (-13, 14, 48), (-38, 0, 48), (-45, 0, 47))


def main() -> int:
    from fingersplat3d.eval.machine import machine

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--all-triplets", action="store_true", help="every triplet of the rolls, summarised")
    args = parser.parse_args()
    if not args.data.is_dir():
        print(f"bench_crops: {args.data}: no such folder", file=sys.stderr)
        return 2
    every = tuple(sorted(int(path.stem.split("_")[-1]) for path in args.data.glob("sample2_*.png")
                         if path.stem.split("_")[-1].lstrip("-").isdigit()))
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores; geometry only.\n")
    if args.all_triplets:
        return _all_triplets(args.data, every)
    print("| rolls ° | views registered | pair errors ° (registered pairs) | turn sensitivity ° (same pairs) | residual px |\n"
          "|---|---|---|---|---|")
    errors_all, moves_all = [], []
    for rolls in TRIPLETS + ((every,) if len(every) > 3 else ()):
        aligned, errors, moves, residual = _fuse_rolls(args.data, rolls)
        n = len(rolls)
        if n == 3:
            shown = ", ".join(f"{e:.1f}" for e in errors) or "–"
            shown_moves = ", ".join(f"{m:.1f}" for m in moves) or "–"
            errors_all += errors
            moves_all += moves
        else:  # every view of the sample at once: the pairs' median and worst
            shown = f"median {np.median(errors):.2f}, max {np.max(errors):.2f} ({len(errors)} pairs)" if errors else "–"
            shown_moves = f"median {np.nanmedian(moves):.2f}, max {np.nanmax(moves):.2f}" if moves else "–"
        print(f"| {' / '.join(map(str, rolls))} | {sum(aligned)}/{n} | {shown} | {shown_moves} | {residual:.2f} |", flush=True)
    if len(errors_all) > 2:
        from scipy.stats import spearmanr

        rho = spearmanr(moves_all, errors_all)
        print(f"\nTriplets' pairs: turn sensitivity against error, Spearman {rho.statistic:.2f} (p = {rho.pvalue:.2g}).")
    return 0


def _fuse_rolls(data: Path, rolls: tuple[int, ...]) -> tuple[list[bool], list[float], list[float], float]:
    """Fuse the renders of ``rolls`` geometry-only: which views registered, each registered pair's angle error against
    the difference of its rolls and its turn sensitivity, and the residual in pixels."""
    from fingersplat3d.eval.poses import rotation_angle_deg
    from fingersplat3d.io.datasets import load_any
    from fingersplat3d.pipeline import FuseConfig, fuse

    capture = load_any([data / f"sample2_{roll}.png" for roll in rolls])[0]
    result = fuse(capture, FuseConfig(splat=None))
    aligned = list(result.report["alignment"]["aligned"].values())
    rotations = [camera.world_to_cam[:3, :3] for camera in result.cameras]
    pairs = [(i, j) for i, j in itertools.combinations(range(len(rolls)), 2) if aligned[i] and aligned[j]]
    errors = [abs(float(rotation_angle_deg(rotations[j] @ rotations[i].T, np.eye(3))) - abs(rolls[j] - rolls[i])) for i, j in pairs]
    names = result.capture.names
    sensitivity = result.report["alignment"].get("turn_sensitivity_deg", {})
    moves = [sensitivity.get(f"{names[i]}-{names[j]}", float("nan")) for i, j in pairs]
    return aligned, errors, moves, float(result.report["alignment"]["residual_px"])


def _all_triplets(data: Path, rolls: tuple[int, ...]) -> int:
    """Every triplet of ``rolls``: the summary row, then the triplets not whole or over 1° at their worst pair."""
    from tqdm import tqdm

    rows, errors_all = [], []
    for triplet in tqdm(list(itertools.combinations(rolls, 3)), desc="triplets", unit="triplet"):
        aligned, errors, _, _ = _fuse_rolls(data, triplet)
        rows.append((triplet, all(aligned), max(errors, default=float("nan"))))
        errors_all += errors
    whole = [worst for _, is_whole, worst in rows if is_whole]
    print("| triplets | whole (every view registered) | worst pair ≤ 2° (≤ 1°) among the whole | pair error median, max |\n"
          "|---|---|---|---|")
    print(f"| all {len(rows)} | {len(whole)} | {sum(w <= 2.0 for w in whole)} ({sum(w <= 1.0 for w in whole)}) | "
          f"{np.median(errors_all):.2f}°, {np.max(errors_all):.2f}° |\n")
    for triplet, is_whole, worst in rows:
        if not is_whole or worst > 1.0:
            print(f"- {' / '.join(map(str, triplet))}: {'worst pair' if is_whole else 'a view unregistered; worst registered pair'} {worst:.2f}°")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
