"""How good is the alignment chain when the pointmaps are exact? (an upper bound for any backend)

    python tools/bench_alignment_bound.py --seeds 5

Runs ``fuse`` on synthetic ``uwa`` captures (640x512, 3 views) twice: with the default ``prior``
backend, and with a backend that returns the ground-truth depth as its pointmaps (registered here
only, as ``exact``). Matching, pairwise registration and global alignment are the same. Prints the
relative rotation error and depth error (scale-and-shift MAE, mm) medians as a markdown table.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from fingersplat3d.errors import run_script
from fingersplat3d.eval import depth_errors, relative_rotation_errors
from fingersplat3d.pipeline import FuseConfig, fuse
from fingersplat3d.pointmaps.base import Pointmap, register_backend
from fingersplat3d.scene import Capture
from fingersplat3d.synth import SynthConfig, synthesize


class ExactBackend:
    """Ground-truth depth as pointmaps (own camera frame, true focal): no backend can do better."""

    name = "exact"

    def __init__(self, truth: Capture | None = None) -> None:
        self.truth = truth

    def predict_views(self, views):
        maps = []
        for index, view in enumerate(self.truth.views):
            points = view.camera.world_to_camera(view.camera.depth_to_points(view.depth)).astype(np.float32)
            maps.append(Pointmap(index, points, view.mask.astype(np.float32), float(view.camera.K[0, 0])))
        return maps


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args(argv)
    rows = {}
    start = time.perf_counter()
    for seed in range(args.seeds):
        truth = synthesize(seed, SynthConfig(size=(640, 512))).capture
        blind = Capture(tuple(v.with_(camera=None, depth=None) for v in truth.views), truth.metadata)
        register_backend("exact", lambda: ExactBackend(truth))
        for backend in ("prior", "exact"):
            result = fuse(blind, FuseConfig(backend=backend, splat=None))
            rotation = relative_rotation_errors([c.world_to_cam for c in result.cameras],
                                                [v.camera.world_to_cam for v in truth.views])
            depth = [depth_errors(d, v.depth, v.mask).mae for d, v in zip(result.depths, truth.views)]
            rows.setdefault(backend, {"rot": [], "adjacent": [], "depth": []})
            rows[backend]["rot"] += list(rotation)
            rows[backend]["adjacent"] += [rotation[0], rotation[2]]  # left-center, center-right
            rows[backend]["depth"] += depth
    print(f"Machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; uwa 640x512, 3 views, seeds 0..{args.seeds - 1}; "
          f"{time.perf_counter() - start:.0f} s\n")
    print("| pointmaps | rotation error median, all pairs (deg) | adjacent 45-deg pairs (deg) | depth MAE median (mm) |")
    print("|---|---|---|---|")
    for backend, row in rows.items():
        print(f"| {backend} | {np.median(row['rot']):.2f} | {np.median(row['adjacent']):.2f} | {np.median(row['depth']):.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
