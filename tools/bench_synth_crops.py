"""Synthetic fingers cut straight across at both ends, and with flatter sections than the generator draws.

    python3 tools/bench_synth_crops.py [--seeds 3] [--height-ratio 0.45] [--keep 0.1,0.85] [--frame]

Another group's crops (docs/measurements.md) show no fingertip and a flat section; this checks the same conditions on
``fs3d synth`` fingers, where the truth is known. Per seed, a ring capture (-45 / 0 / +45 fused) is made with the
finger's section height over width set to ``--height-ratio`` (the generator draws 0.68-0.95; 0 keeps its draw), then
every view is cut by the same two planes across the finger axis, at the shares ``--keep`` of the front view's
silhouette along it (the tip cap and the crease fall outside with the default), and fused from images and masks alone.
With ``--frame`` the views are instead cropped there, the way datasets publish normalised crops: the frame itself cuts
the finger at both ends (the same image columns in every view, the cameras' principal points moved with the crop).
Prints rotation and depth errors per seed (:func:`~fingersplat3d.experiments.geometry.score_geometry`).
"""
from __future__ import annotations

import argparse
import pickle
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from fingersplat3d.errors import run_script


def cut_across(capture, keep: tuple[float, float]):
    """``capture`` with every view cut by two planes across the finger (world x, the ring rig's finger axis), at the
    shares ``keep`` of the front view's silhouette along it: outside them the mask is off and the image dark."""
    from fingersplat3d.scene import Capture

    front = capture["v2"]
    cols = np.nonzero(front.mask.any(0))[0]
    ends = [cols.min() + share * (cols.max() - cols.min()) for share in keep]
    row = int(np.median(np.nonzero(front.mask[:, int(np.mean(ends))])[0]))
    xs = sorted(front.camera.unproject(np.array([[c, row]], float), np.array([front.depth[row, int(c)]]))[0][0] for c in ends)
    views = []
    for view in capture.views:
        rows, cols = np.nonzero(np.isfinite(view.depth))
        points = view.camera.unproject(np.stack([cols, rows], 1).astype(float), view.depth[rows, cols])
        inside = np.zeros_like(view.mask)
        inside[rows, cols] = (points[:, 0] >= xs[0]) & (points[:, 0] <= xs[1])
        mask = view.mask & inside
        image = np.where(mask if view.image.ndim == 2 else mask[..., None], view.image, 0.02).astype(view.image.dtype)
        views.append(view.with_(image=image, mask=mask, depth=np.where(mask, view.depth, np.nan).astype(view.depth.dtype)))
    return Capture(tuple(views), capture.metadata)


def crop_frame(capture, keep: tuple[float, float]):
    """``capture`` with every view cropped to the image columns at the shares ``keep`` of the front view's silhouette
    along the finger (the ring rig's finger runs along the image rows): the frame cuts the finger at both ends."""
    from fingersplat3d.experiments.geometry import columns_cropped

    cols = np.nonzero(capture["v2"].mask.any(0))[0]
    first, last = (int(round(cols.min() + share * (cols.max() - cols.min()))) for share in keep)
    return columns_cropped(capture, first, last)


def main() -> int:
    import fingersplat3d.synth.generate as generate
    from fingersplat3d.experiments.geometry import RING_ANGLES, GeometryCase, _measure_case
    from fingersplat3d.pipeline import FuseConfig
    from fingersplat3d.synth import SynthConfig, synthesize

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--height-ratio", type=float, default=0.45, help="section height over width (0: the generator's)")
    parser.add_argument("--keep", default="0.1,0.85", help="the cut planes, as shares of the front silhouette's length")
    parser.add_argument("--frame", action="store_true", help="crop the views there instead (the frame cuts the finger)")
    args = parser.parse_args()
    keep = tuple(float(x) for x in args.keep.split(","))
    drawn = generate.random_finger_params
    if args.height_ratio > 0:
        generate.random_finger_params = lambda rng, *shapes: replace(drawn(rng, *shapes), height_ratio=args.height_ratio)
    with tempfile.TemporaryDirectory() as folder:
        paths = []
        for seed in range(args.seeds):
            capture = synthesize(seed, SynthConfig(rig="ring", size=(640, 512), angles=RING_ANGLES)).capture
            path = Path(folder) / f"crop-{seed}.pkl"
            path.write_bytes(pickle.dumps((crop_frame if args.frame else cut_across)(capture, keep)))
            paths.append(str(path))
        rows = _measure_case(GeometryCase("ring", 3), paths, FuseConfig(splat=None))
    print(f"height ratio {args.height_ratio:g} (0: drawn), {'cropped' if args.frame else 'cut'} at {keep}:")
    for r in rows:
        if r["status"] != "done":
            print(f"seed {r['seed']}: failed, {r['reason']}")
            continue
        print(f"seed {r['seed']}: all views registered {r['registered_all']}, rotation {r['rotation_error_deg']:.2f}° "
              f"(max {r['rotation_max_deg']:.2f}), depth {r['depth_mae_mm']:.3f} mm (worst view {r['depth_worst_view_mm']:.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
