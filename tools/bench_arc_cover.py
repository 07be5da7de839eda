"""Holes in a model's new views: how much of the rendered finger the arc between the cameras leaves uncovered.

    fs3d fuse PHOTO_A PHOTO_B -o REC/pair --splat-preset fast      (or fs3d batch ... -o REC)
    python3 tools/bench_arc_cover.py REC/* [--count 12] [--width 640]

For each reconstruction with Gaussians: its arc views (``fs3d render``'s, the fitted end cameras left out), and over
their fingers together the share where alpha < 0.5 (holes: the background shows) and < 0.9 (thin skin)
(:mod:`fingersplat3d.experiments.arc_cover`). Prints a markdown table and the medians.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from fingersplat3d.errors import InputError, run_script
from fingersplat3d.experiments.arc_cover import arc_cover


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folders", nargs="+", type=Path, help="reconstruction folders with gaussians.ply")
    parser.add_argument("--count", type=int, default=12, help="views on the arc, its ends included")
    parser.add_argument("--width", type=int, default=640, help="the views' longest side in pixels")
    args = parser.parse_args(argv)
    if args.count < 3 or args.width < 16:
        raise InputError("--count must be at least 3 and --width at least 16")
    missing = [str(f) for f in args.folders if not (f / "gaussians.ply").is_file() or not (f / "cameras.json").is_file()]
    if missing:
        raise InputError(f"not a reconstruction folder with Gaussians (gaussians.ply, cameras.json): {', '.join(missing)}")
    print("| reconstruction | views | alpha < 0.5 | alpha < 0.9 |")
    print("|---|---|---|---|")
    rows = []
    for folder in args.folders:
        row = arc_cover(folder, args.count, args.width)
        rows.append(row)
        print(f"| {folder.name} | {row['views']} | {100 * row['holes']:.2f} % | {100 * row['thin']:.2f} % |", flush=True)
    print(f"| **median** ({len(rows)}) | | {100 * np.median([r['holes'] for r in rows]):.2f} % | "
          f"{100 * np.median([r['thin'] for r in rows]):.2f} % |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_script(main))
