"""Where the warp check's shortfall lies: geometry or appearance, depth or cameras (``tools/bench_warp_residual.py``).

For each reconstruction folder and its default pairs (the middle camera B, each other camera A):

* the warp check and what a smooth flow leaves of it (:func:`~fingersplat3d.experiments.register.warp_check`,
  :mod:`~fingersplat3d.eval.ridge_flow`);
* a control: the same flow from *another finger's* photo carried into B (a folder whose name starts with another
  subject or finger), which says how far the flow lifts a correlation by itself;
* a held-out test of the flow as depth: B's depth corrected so that one pair's flow across the ridges is taken up
  by B's depth alone (each pixel's shift divided by how far a unit of depth moves A's texture across B's ridges,
  smoothed over ``smooth_periods`` ridge periods, weighted by that reach), then both pairs' warp checks again. A
  truer surface raises the pair it was not fitted to as well; a correction that only fits its own pair lowers it.

Numpy/OpenCV on reconstruction folders; no fitting of the model itself.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..eval.ridge_flow import across_ridges, flow_residual, ncc, smooth_flow
from ..io.reconstruction_folder import ReconstructionFolder
from .register import default_pairs, pair_textures, warp_check

__all__ = ["depth_from_flow", "warp_residual_rows"]

SMOOTH_PERIODS = 2.0
"""Smoothing of the depth correction, in ridge periods."""
_MIN_REACH = 0.3  # |cos| between a unit of depth's motion and the across-ridge direction below which a pixel is not used


def depth_from_flow(rec: ReconstructionFolder, view_a: str, view_b: str, smooth_periods: float = SMOOTH_PERIODS) -> np.ndarray:
    """B's depth corrected so that the smooth flow of the pair ``A -> B`` across B's ridges is taken up by depth."""
    texture_a, texture_b, both, period = pair_textures(rec, view_a, view_b)
    if not np.isfinite(period):  # the views share too little: nothing to correct
        return rec.depth(view_b)
    flow = smooth_flow(texture_a, texture_b, both, period)
    camera_a, camera_b = rec.cameras.cameras[view_a], rec.cameras.cameras[view_b]
    depth = rec.depth(view_b)
    h, w = depth.shape
    grid = camera_b.pixel_grid().reshape(-1, 2).astype(np.float64)
    z = depth.reshape(-1).astype(np.float64)
    z = np.where(np.isfinite(z), z, np.nanmedian(z))

    def into_a(pixels, depths):
        return camera_a.project(camera_b.unproject(pixels, depths))[0]

    step = 1e-3 * float(np.median(z))
    at = into_a(grid, z)
    by_depth = (into_a(grid, z + step) - at) / step  # A's pixel per unit of B's depth
    jacobian = np.stack([into_a(grid + [1.0, 0.0], z) - at, into_a(grid + [0.0, 1.0], z) - at], -1)  # A's per B's
    usable = np.abs(np.linalg.det(jacobian)) > 1e-3
    reach = np.zeros_like(by_depth)  # B's pixels that a unit of depth moves A's texture by
    reach[usable] = np.linalg.solve(jacobian[usable], by_depth[usable][:, :, None])[:, :, 0]
    reach = reach.reshape(h, w, 2)
    direction, _ = across_ridges(texture_b, period)
    reach_across = (reach * direction).sum(-1)
    shift_across = (flow * direction).sum(-1)
    use = (both & usable.reshape(h, w) & (np.abs(reach_across) > _MIN_REACH * np.linalg.norm(reach, axis=-1))
           & (np.abs(shift_across) < 0.5 * period))
    change = np.where(use, shift_across / np.where(use, reach_across, 1.0), 0.0)
    weight = np.where(use, reach_across ** 2, 0.0)
    sigma = smooth_periods * period
    total = cv2.GaussianBlur(weight, (0, 0), sigma)
    smooth = cv2.GaussianBlur(weight * change, (0, 0), sigma) / np.maximum(total, 1e-30)
    return depth + np.where(total > 1e-3 * total.max(), smooth, 0.0).astype(depth.dtype)


def _other_finger(rec: ReconstructionFolder, records: list[ReconstructionFolder]) -> ReconstructionFolder | None:
    """A reconstruction of another finger (its folder name's first two fields differ), the same view names."""
    key = rec.folder.name.split("_")[:2]
    for other in records:
        if other.folder.name.split("_")[:2] != key and set(other.cameras.names) == set(rec.cameras.names):
            return other
    return None


def warp_residual_rows(folders: list[Path], smooth_periods: float = SMOOTH_PERIODS) -> list[dict]:
    """One row per reconstruction and default pair (see the module docstring)."""
    records = [ReconstructionFolder(Path(f)) for f in folders]
    rows = []
    for rec in records:
        pairs = default_pairs(rec.cameras)
        other = _other_finger(rec, records)
        checks = {a: warp_check(rec.photo(a), rec.photo(b), rec, a, b) for b, a in pairs}  # each pair's, made once
        for b, a in pairs:
            row = {"reconstruction": rec.folder.name, "view_a": a, "view_b": b, **checks[a],
                   "impostor_ncc": float("nan"), "impostor_ncc_flowed": float("nan")}
            if other is not None:
                texture_a, texture_b, both, period = pair_textures(rec, a, b, photo_a=other.photo(a))
                if np.isfinite(period):
                    control = flow_residual(texture_a, texture_b, both, period)
                    row.update(impostor_ncc=control["ncc"], impostor_ncc_flowed=control["ncc_flowed"])
            if len(pairs) >= 2:
                held = next(x for _, x in pairs if x != a)
                depth = depth_from_flow(rec, a, b, smooth_periods)
                for key, view in (("fitted", a), ("held_out", held)):
                    row[f"depth_{key}_ncc"] = checks[view]["warp_ncc"]  # the warp check's own textures and depth
                    row[f"depth_{key}_ncc_after"] = ncc(*pair_textures(rec, view, b, depth_b=depth)[:3])
            rows.append(row)
    return rows
