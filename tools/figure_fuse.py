"""Picture of ``fs3d fuse`` on a shipped sample against its ground truth (for the README).

    python tools/figure_fuse.py data_samples/uwa_seed0 docs/images/fuse_uwa_seed0.png

One row per view: the photo, the ground-truth depth, the fused depth (after least-squares scale
and shift to the ground truth) and the absolute error in mm on a fixed 0-1 mm colour scale.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

from fingersplat3d.errors import run_script
from fingersplat3d.eval import align_scale_shift, depth_errors
from fingersplat3d.io import depth_colormap, read_capture, write_image
from fingersplat3d.pipeline import FuseConfig, fuse


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    tile = np.ascontiguousarray(tile)
    cv2.putText(tile, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 0), 1, cv2.LINE_AA)
    return tile


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("capture", type=Path)
    parser.add_argument("output", type=Path)
    parser.add_argument("--tile-width", type=int, default=300)
    args = parser.parse_args(argv)
    capture = read_capture(args.capture)
    blind = capture.__class__(tuple(v.with_(camera=None, depth=None) for v in capture.views), capture.metadata)
    result = fuse(blind, FuseConfig(splat=None))
    rows = []
    for view, depth in zip(capture.views, result.depths):
        scale, shift = align_scale_shift(depth, view.depth, view.mask)
        fitted = scale * depth + shift
        error = np.abs(fitted - view.depth)
        mae = depth_errors(depth, view.depth, view.mask).mae
        lo, hi = np.nanmin(view.depth), np.nanmax(view.depth)
        photo = np.round(np.clip(np.atleast_3d(view.image) * np.ones((1, 1, 3)), 0, 1) * 255).astype(np.uint8)
        span = np.where(np.isfinite(fitted), np.clip(fitted, lo, hi), np.nan)
        err8 = np.where(np.isfinite(error), np.clip(error, 0, 1.0) * 255, 0).astype(np.uint8)
        err_rgb = cv2.applyColorMap(err8, cv2.COLORMAP_INFERNO)[..., ::-1].copy()
        err_rgb[~np.isfinite(error)] = 0
        tiles = [_label(photo, view.name), _label(depth_colormap(view.depth), "ground truth"),
                 _label(depth_colormap(span), "fused"), _label(err_rgb, f"|error| 0-1 mm, MAE {mae:.2f} mm")]
        size = (args.tile_width, round(view.height * args.tile_width / view.width))
        rows.append(np.concatenate([cv2.resize(t, size, interpolation=cv2.INTER_AREA) for t in tiles], axis=1))
    sheet = np.concatenate(rows, axis=0)
    write_image(args.output, sheet.astype(np.float32) / 255.0)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
