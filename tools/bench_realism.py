"""How close ``fs3d synth`` looks to the real UWA captures: image statistics side by side.

    python3 tools/bench_realism.py [--data ../shared/data/uwa-real-dev] [--seeds 6]

Real: frames 0-2 of every capture in ``--data`` (a portrait frame is turned back to landscape).
Synthetic: ``fs3d synth --rig uwa`` seeds 0..N-1 at 1280x1024, default appearance. Each view's
statistics come from :func:`fingersplat3d.eval.appearance.image_statistics` (the module says what
each one measures); the table gives the median over front views (frame 0 / ``center``) and over
side views, and the synthetic shape parameters' spread. Prints a markdown table.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = {"skin": "skin level", "background": "background", "noise": "noise", "ridge_contrast": "ridge contrast",
           "ridge_period_px": "ridge period (px)", "edge_blur_px": "edge blur (px)", "rim_shading": "rim shading",
           "width_fraction": "finger width / image", "glints": "glint share"}


def main() -> int:
    from fingersplat3d.eval.appearance import image_statistics
    from fingersplat3d.io.datasets import load_uwa
    from fingersplat3d.segment.masks import finger_mask
    from fingersplat3d.synth import SynthConfig, synthesize

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "uwa-real-dev")
    parser.add_argument("--seeds", type=int, default=6)
    args = parser.parse_args()
    groups: dict[str, list[dict]] = {"real, front": [], "real, sides": [], "synth, front": [], "synth, sides": []}
    if args.data.is_dir():
        for capture in load_uwa(args.data):
            for index, view in enumerate(capture.views):
                image = view.image if view.width >= view.height else np.rot90(view.image).copy()
                groups["real, front" if index == 0 else "real, sides"].append(image_statistics(image, finger_mask(image)).as_dict())
    else:
        print(f"bench_realism: {args.data} not found; synthetic rows only", file=sys.stderr)
    shapes = []
    for seed in range(args.seeds):
        result = synthesize(seed, SynthConfig(rig="uwa"))
        shapes.append(result.surface.params)
        for view in result.capture.views:
            groups["synth, front" if view.name == "center" else "synth, sides"].append(image_statistics(view.image, view.mask).as_dict())
    print("| views | " + " | ".join(COLUMNS.values()) + " |")
    print("|---|" + "---|" * len(COLUMNS))
    for name, rows in groups.items():
        if rows:
            print(f"| {name} ({len(rows)}) | " + " | ".join(f"{np.median([r[key] for r in rows]):.3g}" for key in COLUMNS) + " |")
    print(f"\nSynthetic shapes over seeds 0-{args.seeds - 1}: width {min(p.width for p in shapes):.1f}-{max(p.width for p in shapes):.1f} mm, "
          f"section height/width {min(p.height_ratio for p in shapes):.2f}-{max(p.height_ratio for p in shapes):.2f}, "
          f"pad bulge {min(p.pad_bulge for p in shapes):.2f}-{max(p.pad_bulge for p in shapes):.2f}, "
          f"bend {min(p.bend for p in shapes):.1f}-{max(p.bend for p in shapes):.1f} mm.")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
