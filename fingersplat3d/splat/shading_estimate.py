"""The capture's shading exponent and each photo's exposure, from the registered geometry (:mod:`.shading`).

Every skin point two cameras see gives one equation: its brightness in each photo, blurred past the
ridges, is ``albedo * mu ** k * exp(g)``, so the albedo drops out of the ratio,

    log I_a - log I_b = k (log mu_a - log mu_b) + g_a - g_b,

with ``mu`` the cosine between the surface normal (from view ``a``'s depth map) and the direction to
each camera. One linear least-squares problem over all pairs gives ``k`` and the log exposures ``g``
(the first view's 0), refitted once without the points more than three robust deviations off (glints,
the pointmap's errors at the rims). The fit then starts from these values: learned from scratch by
the photometric loss, the exponent stayed at 0.14-0.45 on one real capture's three two-view fits,
where these equations give 0.38-0.52, because each Gaussian's own colour takes up the mean look first.

Pure numpy and OpenCV (the blur).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..align.correspond.texture import as_gray
from ..structure_tensor import masked_blur
from ..robust import robust_sigma
from ..sampling import sample_nearest
from ..scene import Camera
from .shading import MAX_EXPONENT

__all__ = ["ShadingEstimate", "estimate_shading", "MIN_POINTS"]

MIN_POINTS = 200
"""Fewer point pairs than this (views that share little skin): no estimate, the shading starts at none."""
MIN_COSINE = 0.15  # points seen more slanted than ~81 degrees by either camera are left out (the normals' error)
SATURATED = 0.98  # brightness (of 1) at which a photo may be clipped: such points say nothing of the ratio
DEPTH_AGREEMENT = 0.01  # a point is seen by b when b's depth there is within this share of b's median depth
STRIDE = 4  # sample every 4th pixel of each view, both ways
OUTLIER_DEVIATIONS = 3.0


@dataclass(frozen=True)
class ShadingEstimate:
    exponent: float  # in [0, MAX_EXPONENT]
    log_gains: list[float]  # one per view, the first 0
    points: int  # point pairs the estimate rests on (0: none made)

    @classmethod
    def none(cls, views: int) -> "ShadingEstimate":
        """No estimate: no shading, every exposure 1."""
        return cls(0.0, [0.0] * views, 0)

    def gains(self, among: Sequence[int] | None = None) -> np.ndarray:
        """Each view's exposure against the geometric mean of the views ``among`` (all by default): the factor a
        render at that mean exposure is multiplied by to look like the view's photo."""
        logs = np.asarray(self.log_gains, np.float64)
        reference = logs[list(among)].mean() if among is not None else logs.mean()
        return np.exp(logs - reference)


def _points_and_normals(camera: Camera, depth: np.ndarray, stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every ``stride``-th pixel's ``(pixels [h, w, 2], points [h, w, 3], normals [h, w, 3])``; NaN off the depth
    map and next to its edge (the normals from the neighbours on that grid)."""
    v, u = np.mgrid[0:depth.shape[0]:stride, 0:depth.shape[1]:stride]
    pixels = np.stack([u, v], -1)
    points = camera.unproject(pixels.reshape(-1, 2), depth[::stride, ::stride].reshape(-1)).reshape(*u.shape, 3)
    normals = np.cross(np.gradient(points, axis=1), np.gradient(points, axis=0)) if min(u.shape) > 1 \
        else np.full(points.shape, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    return pixels, points, normals


def _cosines(points: np.ndarray, normals: np.ndarray, centre: np.ndarray) -> np.ndarray:
    towards = centre[None] - points
    return np.abs((towards * normals).sum(1)) / np.linalg.norm(towards, axis=1)


def estimate_shading(images: Sequence[np.ndarray], masks: Sequence[np.ndarray], cameras: Sequence[Camera],
                     depths: Sequence[np.ndarray], blur_px: float | None = None, stride: int = STRIDE) -> ShadingEstimate:
    """``k`` and each view's log exposure from the views' photos, masks, cameras and depth maps (module docstring).
    ``blur_px``: the blur past the ridges (default: the image width / 160, about a ridge period); ``stride``: every
    how many pixels of each view a point is taken."""
    count = len(images)
    none = ShadingEstimate.none(count)
    if count < 2:
        return none
    masks = [np.asarray(mask, bool) for mask in masks]
    depths = [np.where(mask, depth, np.nan) for mask, depth in zip(masks, depths)]  # the finger's skin only
    # blurred over the finger only: the dark background must not darken the rims, where the slant is read
    blurred = [masked_blur(as_gray(image), mask.astype(np.float32), (image.shape[1] / 160.0) if blur_px is None else blur_px)
               for image, mask in zip(images, masks)]
    geometry = [_points_and_normals(camera, depth, max(1, int(stride))) for camera, depth in zip(cameras, depths)]
    medians = [float(np.nanmedian(depth)) if np.isfinite(depth).any() else np.nan for depth in depths]
    rows_x, rows_y, pairs = [], [], []
    for a in range(count):
        pixels, points, normals = geometry[a]
        keep = np.isfinite(points).all(-1) & np.isfinite(normals).all(-1)
        if not keep.any():
            continue
        p, n = points[keep], normals[keep]
        brightness_a = blurred[a][pixels[keep][:, 1], pixels[keep][:, 0]]
        cos_a = _cosines(p, n, cameras[a].center)
        for b in range(count):
            if b == a or not np.isfinite(medians[b]):
                continue
            uv, z = cameras[b].project(p)
            with np.errstate(invalid="ignore"):  # NaN where b has no skin there
                seen = np.abs(sample_nearest(depths[b], uv) - z) < DEPTH_AGREEMENT * medians[b]
            cos_b = _cosines(p, n, cameras[b].center)
            brightness_b = np.where(seen, sample_nearest(blurred[b], uv), 0.0).astype(np.float32)
            use = (seen & (cos_a > MIN_COSINE) & (cos_b > MIN_COSINE) & (brightness_a > 1e-3) & (brightness_b > 1e-3)
                   & (brightness_a < SATURATED) & (brightness_b < SATURATED))
            if not use.any():
                continue
            rows_x.append(np.log(cos_a[use] / cos_b[use]))
            rows_y.append(np.log(brightness_a[use] / brightness_b[use]))
            pairs.append(np.broadcast_to(np.array([a, b]), (int(use.sum()), 2)))
    if not rows_x or sum(len(x) for x in rows_x) < MIN_POINTS:
        return none
    x, y, pair = np.concatenate(rows_x), np.concatenate(rows_y).astype(np.float64), np.concatenate(pairs)
    design = np.zeros((len(x), count))  # columns: k, then g_1 .. g_{n-1} (g_0 = 0)
    design[:, 0] = x
    for column, sign in ((0, 1.0), (1, -1.0)):
        view = pair[:, column]
        rows = np.nonzero(view > 0)[0]
        design[rows, view[rows]] += sign
    residual = y - design @ np.linalg.lstsq(design, y, rcond=None)[0]
    spread = robust_sigma(residual)
    used = np.abs(residual) <= OUTLIER_DEVIATIONS * max(spread, 1e-6)
    if used.sum() < MIN_POINTS:
        return none
    solution = np.linalg.lstsq(design[used], y[used], rcond=None)[0]
    if solution[0] < 0:  # no darkening with the slant: the exposures alone
        solution = np.concatenate([[0.0], np.linalg.lstsq(design[used][:, 1:], y[used], rcond=None)[0]])
    if not np.all(np.isfinite(solution)):
        return none
    return ShadingEstimate(float(np.clip(solution[0], 0.0, MAX_EXPONENT)), [0.0] + [float(g) for g in solution[1:]],
                           int(used.sum()))
