"""Where the warp check's shortfall lies: geometry or appearance, depth or cameras.

    fs3d batch ../shared/data/uwa-real-dev -o REC --no-splat
    python3 tools/bench_warp_residual.py REC/*_*_*

For each reconstruction's default pairs (:mod:`fingersplat3d.experiments.warp_residual`): the warp check's ridge
correlation as it is and after a smooth flow over six ridge periods, the same flow from another finger's photo (the
control), the flow's median shift across the ridges where a depth change could move them and where only the cameras
could, and B's depth corrected by one pair's flow, scored on that pair and on the pair it was not fitted to. Prints
a markdown table and its medians (finger by finger when the folders are named subject_finger_...).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from fingersplat3d.errors import InputError, run_script
from fingersplat3d.experiments.warp_residual import SMOOTH_PERIODS, warp_residual_rows

COLUMNS = (("warp_ncc", "NCC"), ("warp_ncc_flowed", "after the flow"), ("impostor_ncc_flowed", "another finger, after"),
           ("warp_residual_depth_px", "shift px: depth could"), ("warp_residual_pose_px", "cameras only"),
           ("depth_fitted_ncc", "depth from this pair: its NCC"), ("depth_fitted_ncc_after", "after"),
           ("depth_held_out_ncc", "the other pair's"), ("depth_held_out_ncc_after", "after"))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="+", type=Path, help="reconstruction folders (fs3d fuse / fs3d batch)")
    parser.add_argument("--smooth-periods", type=float, default=SMOOTH_PERIODS,
                        help="smoothing of the depth correction, in ridge periods")
    args = parser.parse_args(argv)
    missing = [str(f) for f in args.folders if not (f / "cameras.json").is_file()]
    if missing:
        raise InputError(f"not a reconstruction folder (no cameras.json): {', '.join(missing)}")
    rows = warp_residual_rows(args.folders, args.smooth_periods)
    print("| reconstruction | A -> B | " + " | ".join(label for _, label in COLUMNS) + " |")
    print("|---|---|" + "---|" * len(COLUMNS))
    for row in rows:
        cells = [f"{row.get(key, float('nan')):.2f}" for key, _ in COLUMNS]
        print(f"| {row['reconstruction']} | {row['view_a']} -> {row['view_b']} | " + " | ".join(cells) + " |")
    groups = {"all": rows}
    for row in rows:
        groups.setdefault("finger " + "_".join(row["reconstruction"].split("_")[:2]), []).append(row)
    for name, members in groups.items():
        values = [[float(r.get(key, np.nan)) for r in members] for key, _ in COLUMNS]
        medians = [np.median([v for v in column if np.isfinite(v)]) if np.isfinite(column).any() else np.nan
                   for column in values]
        print(f"| **median, {name}** ({len(members)} pairs) | | " + " | ".join(f"{m:.2f}" for m in medians) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_script(main))
