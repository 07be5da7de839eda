"""Registration of close-up photos whose finger sides are out of focus (a phone's shallow depth of field).

    python3 tools/bench_defocus.py [--seeds 3] [--sigmas 0,2,4,6] [--distance-mm 50] [--find-masks]

Per seed, an ``fs3d synth`` uwa capture (three cameras at -45 / 0 / +45, 640x512) framed from ``--distance-mm`` (50:
a phone's close-up); every view blurred by :func:`~fingersplat3d.experiments.defocus.defocused`, sharp at its nearest
skin and ``sigma`` px at its farthest; fused from the images (and the true masks, or with ``--find-masks`` none),
geometry only. Prints per sigma the views registered, rotation error and depth error
(:func:`~fingersplat3d.experiments.geometry.score_geometry`) and the fuse's warnings of views with no ridges.
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from fingersplat3d.errors import run_script


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--sigmas", default="0,2,4,6", help="blur at the farthest skin, px (comma-separated)")
    parser.add_argument("--distance-mm", type=float, default=50.0)
    parser.add_argument("--find-masks", action="store_true", help="fuse the images alone (the masks found)")
    args = parser.parse_args()
    sigmas = [float(s) for s in args.sigmas.split(",")]
    if args.seeds < 1 or any(not np.isfinite(s) or s < 0 for s in sigmas):
        print("bench_defocus: --seeds must be 1 or more and every --sigmas value a number of pixels >= 0",
              file=sys.stderr)
        return 2

    from fingersplat3d.eval.machine import machine
    from fingersplat3d.experiments.defocus import defocused
    from fingersplat3d.experiments.geometry import score_geometry
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.scene import Capture
    from fingersplat3d.synth import SynthConfig, synthesize

    captures = [synthesize(seed, SynthConfig(rig="uwa", size=(640, 512), distance_mm=args.distance_mm)).capture
                for seed in range(args.seeds)]
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores, load {info['load'][0]:.2f}; uwa 640x512 at "
          f"{args.distance_mm:g} mm, {args.seeds} seeds, masks {'found' if args.find_masks else 'given'}\n")
    print("| sigma at the rim px | captures with every view registered | rotation error ° median (max) | "
          "depth MAE mm | views warned of no ridges | s per capture |")
    print("|---|---|---|---|---|---|")
    for sigma in sigmas:
        scores, warned, seconds = [], 0, []
        for capture in captures:
            truth = {view.name: view for view in capture.views}
            blind = Capture(tuple(defocused(view, sigma).with_(camera=None, depth=None,
                                                               mask=None if args.find_masks else view.mask)
                                  for view in capture.views), capture.metadata)
            started = time.perf_counter()
            result = fuse(blind, FuseConfig(splat=None))
            seconds.append(time.perf_counter() - started)
            scores.append(score_geometry(result, truth))
            warned += sum("no ridges" in str(w) for w in result.report.get("warnings", []))
        whole = sum(s["registered_all"] for s in scores)
        rotation = [s["rotation_error_deg"] for s in scores]
        worst = max(s["rotation_max_deg"] for s in scores)
        depth = float(np.median([s["depth_mae_mm"] for s in scores]))
        print(f"| {sigma:g} | {whole} of {len(scores)} | {np.median(rotation):.2f} ({worst:.2f}) | {depth:.3f} | "
              f"{warned} | {np.median(seconds):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
