"""The focal length a pointmap is consistent with (principal point at the image centre).

Upstream's ``estimate_focal_knowing_depth(..., focal_mode='weiszfeld')``: minimise
``sum_p |p - c - f (x_p, y_p) / z_p|`` over the focal ``f`` by iteratively re-weighted least squares,
started from the least-squares solution. Points behind the camera are left out; an estimate that is
not a positive number, or is far outside plausible cameras, falls back to a 60-degree field of view.
"""
from __future__ import annotations

import math

import torch

__all__ = ["estimate_focal", "default_focal", "FOCAL_RANGE"]

FOCAL_RANGE = (0.1, 50.0)  # accepted focal, in units of default_focal (fields of view ~150 to ~1.4 degrees)
_MAX_PIXELS = 200_000  # enough pixels for a robust estimate; more only costs time


def default_focal(width: int, height: int) -> float:
    """Focal of a 60-degree field of view across the long side (upstream's ``focal_base``)."""
    return max(width, height) / (2.0 * math.tan(math.radians(30.0)))


def estimate_focal(points: torch.Tensor, valid: torch.Tensor, iterations: int = 10) -> float:
    """Focal (pixels) of ``points [H, W, 3]`` on their own pixel grid, over pixels ``valid [H, W]``."""
    height, width = points.shape[:2]
    fallback = default_focal(width, height)
    ys, xs = torch.nonzero(valid & (points[..., 2] > 0), as_tuple=True)
    if ys.numel() < 16:
        return fallback
    if ys.numel() > _MAX_PIXELS:
        step = ys.numel() // _MAX_PIXELS + 1
        ys, xs = ys[::step], xs[::step]
    pts = points[ys, xs].double()
    pixels = torch.stack([xs.double() - (width - 1) / 2.0, ys.double() - (height - 1) / 2.0], dim=-1)  # [M, 2]
    rays = pts[:, :2] / pts[:, 2:3]
    dot_ray_pixel = (rays * pixels).sum(-1)
    dot_ray_ray = rays.square().sum(-1)
    focal = dot_ray_pixel.mean() / dot_ray_ray.mean().clamp_min(1e-300)
    for _ in range(iterations):
        weight = (pixels - focal * rays).norm(dim=-1).clip(min=1e-8).reciprocal()
        focal = (weight * dot_ray_pixel).mean() / (weight * dot_ray_ray).mean().clamp_min(1e-300)
    focal = float(focal)
    if not (math.isfinite(focal) and FOCAL_RANGE[0] * fallback <= focal <= FOCAL_RANGE[1] * fallback):
        return fallback
    return focal
