"""Guided matching against true correspondences: its mean offset and spread per patch size (``fs3d synth`` captures).

    python3 tools/bench_guided_bias.py [--seeds 3] [--patch-periods 1.0,1.75,2.5,3.5]

Each pair of a synthetic uwa capture (640x512) is matched through a predictor made of the *true* cameras and depth
maps (:class:`~fingersplat3d.align.correspond.model_predictor.ModelPredictor`), so every match's offset from the true
correspondence is the matcher's own error: its mean over the pair (a bias the global alignment cannot average away)
and the median size of its component across the ridges. Each pair and patch size is matched twice: b's patch
resampled through the predictor's affine map alone (``match_guided(curvature=False)``, before stop 73) and through its
local quadratic map (the default). Prints a markdown table, one row per pair, patch size and warp (seeds pooled: the
mean offset of all matches, the medians of all matches).
"""
from __future__ import annotations

import argparse
import itertools
import sys

import numpy as np

from fingersplat3d.errors import run_script

PAIRS = ((1, 0), (1, 2), (0, 2))  # uwa rig: left, center, right


def ridge_maps(capture) -> tuple[float, list]:
    """The capture's ridge period (from its centre view) and every view's ridge maps, made once for all its pairs."""
    from fingersplat3d.align.correspond.guided import RidgeMaps
    from fingersplat3d.align.correspond.texture import estimate_ridge_period, ridge_texture

    period = estimate_ridge_period(capture.views[1].image, capture.views[1].mask)
    return period, [RidgeMaps(ridge_texture(v.image, v.mask, period), v.mask) for v in capture.views]


def pair_offsets(capture, maps: tuple[float, list], a: int, b: int, patch_periods: float, curvature: bool = True) -> np.ndarray:
    """``[N, 3]`` per match of views ``a -> b``: offset in b's pixels (u, v) and its component across the ridges;
    ``maps``: :func:`ridge_maps` of the capture."""
    from fingersplat3d.align.correspond.guided import match_guided
    from fingersplat3d.align.correspond.model_predictor import OCCLUSION, ModelPredictor

    view_a, view_b = capture.views[a], capture.views[b]
    period, views = maps
    truth = ModelPredictor(view_a.camera, view_b.camera, view_a.depth, view_b.depth,
                           OCCLUSION * float(np.nanmedian(view_b.depth)))
    matches = match_guided(views[a], views[b], truth, period, 0.7 * period, patch_periods=patch_periods, curvature=curvature)
    offset = matches.uv_b - truth(matches.uv_a)[0]
    across = np.linalg.eigh(matches.information_b)[1][:, :, 1]  # the information's strongest direction
    return np.column_stack([offset, np.einsum("ni,ni->n", offset, across)])


def main() -> int:
    from tqdm import tqdm

    from fingersplat3d.eval.machine import machine
    from fingersplat3d.synth import SynthConfig, synthesize

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="synthetic fingers, seeds 0..N-1 (default 3)")
    parser.add_argument("--patch-periods", default="1.0,1.75,2.5,3.5",
                        help="comma-separated patch half-sizes in ridge periods (default 1.0,1.75,2.5,3.5)")
    args = parser.parse_args()
    try:
        sizes = [float(size) for size in args.patch_periods.split(",") if size.strip()]
    except ValueError:
        sizes = []
    if args.seeds < 1 or not sizes or min(sizes) <= 0:
        print("bench_guided_bias: --seeds must be at least 1 and --patch-periods positive numbers", file=sys.stderr)
        return 2
    captures = [synthesize(seed, SynthConfig(size=(640, 512))).capture for seed in range(args.seeds)]
    maps = [ridge_maps(capture) for capture in captures]
    rows = []
    for a, b in tqdm(PAIRS, desc="pairs", unit="pair"):
        for size, curvature in itertools.product(sizes, (False, True)):
            found = np.concatenate([pair_offsets(capture, made, a, b, size, curvature) for capture, made in zip(captures, maps)])
            names = captures[0].names
            rows.append(f"| {names[a]} → {names[b]} | {size:g} | {'quadratic' if curvature else 'affine'} | {len(found)} | {found[:, 0].mean():+.2f} / "
                        f"{found[:, 1].mean():+.2f} | {np.median(np.abs(found[:, 2])):.2f} |")
    info = machine()
    print(f"Machine: {info['cpu']}, {info['cores']} cores; uwa rig 640x512, seeds 0-{args.seeds - 1}, matched through "
          f"the true cameras and depth.\n")
    print("| pair | patch half-size, periods | warp | matches | mean offset u / v px | across the ridges, median abs px |")
    print("|---|---|---|---|---|---|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
