"""EWA projection of 3D Gaussians into a pinhole camera (Zwicker et al. 2002, as in 3DGS).

Camera convention (docs/conventions.md): OpenCV pinhole, x right, y down, z forward, pixel centres at
integer coordinates, ``world_to_cam`` 4x4; depth is camera z. ``K``'s skew is ignored.

The projection runs in float64 whatever the input dtype: it is O(N), and float32 overflows on the
extremes the rasterizer must survive (a 1e3-wide Gaussian seen with a 1e7-pixel focal length has a
2D covariance of 1e20 px^2 and a determinant of 1e40). The 2D determinant is formed by
Cauchy-Binet (a sum of squared minors, plus the low-pass terms), so it is never negative and has
no cancellation even for needle-thin Gaussians. Outputs come back in the input dtype.

Pure torch, differentiable w.r.t. means, quats, scales, ``world_to_cam`` and ``K``.
"""
from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from ..rotations import quaternion_to_matrix

__all__ = ["ALPHA_MAX", "ALPHA_MIN", "Projection", "footprint_boxes", "project_gaussians"]

ALPHA_MIN = 1.0 / 255.0
"""Gaussian-pixel pairs with a smaller alpha are skipped (3DGS)."""
ALPHA_MAX = 0.99
"""Alpha is clamped here so that transmittance never reaches exactly zero (3DGS)."""
FRUSTUM_MARGIN = 0.3
"""The Jacobian is evaluated with x/z, y/z clamped to the frustum enlarged by this fraction of the
image on each side (3DGS uses 1.3 x tan(fov/2)): far off-screen Gaussians keep a sane footprint."""
_MAX_RADIUS = 2 ** 30  # radii are int32


class Projection(NamedTuple):
    """Screen-space footprints of N Gaussians; entries of culled ones are zeros (``valid`` False)."""

    means2d: Tensor  # [N, 2] projected centres in pixels (u, v)
    cov2d: Tensor  # [N, 3] (xx, xy, yy) 2D covariance in px^2, low-pass included
    conics: Tensor  # [N, 3] (a, b, c): inverse covariance, d^T cov^-1 d = a dx^2 + 2 b dx dy + c dy^2
    depths: Tensor  # [N] camera z of the centres (not culled: behind-camera depths are returned as they are)
    radii: Tensor  # [N] int32 pixel radius of the 3-sigma footprint, 0 for culled Gaussians
    valid: Tensor  # [N] bool: in front of the near plane and the footprint touches the image


def _check(means: Tensor, quats: Tensor, scales: Tensor, world_to_cam: Tensor, K: Tensor,
           width: int, height: int, near: float, low_pass: float) -> None:
    n = means.shape[0] if means.ndim == 2 else -1
    for name, t, shape in (("means", means, (n, 3)), ("quats", quats, (n, 4)), ("scales", scales, (n, 3)),
                           ("world_to_cam", world_to_cam, (4, 4)), ("K", K, (3, 3))):
        if not isinstance(t, Tensor):
            raise ValueError(f"{name} must be a torch.Tensor, got {type(t).__name__}")
        if n < 0 or tuple(t.shape) != shape:
            raise ValueError(f"{name} must have shape {shape if n >= 0 else '[N, 3]'}, got {tuple(t.shape)}")
        if not t.is_floating_point():
            raise ValueError(f"{name} must be a floating-point tensor, got {t.dtype}")
    if int(width) != width or int(height) != height or width < 1 or height < 1:
        raise ValueError(f"width and height must be positive integers, got {width} x {height}")
    if not near > 0:
        raise ValueError(f"near must be positive, got {near}")
    if not low_pass >= 0:
        raise ValueError(f"low_pass must be non-negative, got {low_pass}")


def near_in_dtype(near: float, dtype: torch.dtype) -> float:
    """``near`` rounded to ``dtype``: "on the near plane" means equal in the input dtype."""
    return float(torch.tensor(near, dtype=dtype))


def _project(means: Tensor, quats: Tensor, scales: Tensor, world_to_cam: Tensor, K: Tensor,
             width: int, height: int, near: float, low_pass: float, opacities: Tensor | None,
             compiled: bool = False) -> tuple[Projection, Tensor]:
    """The projection plus the integer footprint boxes ``[N, 4]`` the binning needs."""
    near = near_in_dtype(near, means.dtype)
    core = _compiled_core() if compiled else _project_core
    *fields, boxes = core(means, quats, scales, world_to_cam, K, width, height, near, low_pass, opacities)
    return Projection(*fields), boxes


_COMPILED_CORE = None


def _compiled_core():
    """:func:`_project_core` through ``torch.compile`` (N dynamic), compiled on first use."""
    global _COMPILED_CORE
    if _COMPILED_CORE is None:
        _COMPILED_CORE = torch.compile(_project_core, dynamic=True)
    return _COMPILED_CORE


def _project_core(means: Tensor, quats: Tensor, scales: Tensor, world_to_cam: Tensor, K: Tensor,
                  width: int, height: int, near: float, low_pass: float, opacities: Tensor | None):
    """Projection fields and boxes as a tuple, float64 inside (see the module docstring)."""
    dtype = means.dtype
    f64 = torch.float64
    rotation = world_to_cam[:3, :3].to(f64)  # [3, 3]
    p_cam = means.to(f64) @ rotation.T + world_to_cam[:3, 3].to(f64)  # [N, 3]
    x, y, z = p_cam.unbind(-1)
    in_front = (z >= near) & torch.isfinite(p_cam).all(-1)
    z_safe = torch.where(in_front, z, torch.ones_like(z))  # no division by ~0 anywhere, even in masked lanes
    fx, fy, cx, cy = K[0, 0].to(f64), K[1, 1].to(f64), K[0, 2].to(f64), K[1, 2].to(f64)
    u = torch.where(in_front, fx * x / z_safe + cx, torch.zeros_like(z))
    v = torch.where(in_front, fy * y / z_safe + cy, torch.zeros_like(z))

    # cov2d = T T^T with T = J R_wc R_q S ([N, 2, 3], PSD by construction) and J the Jacobian of
    # (fx x/z + cx, fy y/z + cy) at the clamped point, J = [[fx/z, 0, -fx tx/z], [0, fy/z, -fy ty/z]]
    # with tx, ty the clamped x/z, y/z.
    # Written out per row: batched 3x3 matmuls over N are slow on CPU.
    lim_x_neg, lim_x_pos = (cx + FRUSTUM_MARGIN * width) / fx, (width - cx + FRUSTUM_MARGIN * width) / fx
    lim_y_neg, lim_y_pos = (cy + FRUSTUM_MARGIN * height) / fy, (height - cy + FRUSTUM_MARGIN * height) / fy
    tx = torch.maximum(torch.minimum(x / z_safe, lim_x_pos), -lim_x_neg)
    ty = torch.maximum(torch.minimum(y / z_safe, lim_y_pos), -lim_y_neg)
    rot_scale = quaternion_to_matrix(quats.to(f64)) * scales.to(f64)[:, None, :]  # [N, 3, 3]
    n = rot_scale.shape[0]
    world_axes = (rotation @ rot_scale.permute(1, 0, 2).reshape(3, n * 3)).reshape(3, n, 3)  # rows of R_wc R_q S
    fx_z, fy_z = (fx / z_safe)[:, None], (fy / z_safe)[:, None]
    t0 = fx_z * (world_axes[0] - tx[:, None] * world_axes[2])  # [N, 3]
    t1 = fy_z * (world_axes[1] - ty[:, None] * world_axes[2])
    a = (t0 * t0).sum(-1) + low_pass
    b = (t0 * t1).sum(-1)
    c = (t1 * t1).sum(-1) + low_pass
    minors = torch.stack([t0[:, 0] * t1[:, 1] - t0[:, 1] * t1[:, 0], t0[:, 0] * t1[:, 2] - t0[:, 2] * t1[:, 0],
                          t0[:, 1] * t1[:, 2] - t0[:, 2] * t1[:, 1]], -1)  # [N, 3] 2x2 minors of T
    det = (minors * minors).sum(-1) + low_pass * (a + c - low_pass)  # = a c - b^2, without cancellation
    det = det.clamp_min(1e-300)  # only reachable with low_pass = 0 and a degenerate Gaussian
    conics = torch.stack([c / det, -b / det, a / det], -1)
    cov2d = torch.stack([a, b, c], -1)

    with torch.no_grad():
        lambda_max = 0.5 * (a + c) + torch.sqrt(0.25 * (a - c) ** 2 + b * b)
        radii = torch.ceil(3.0 * torch.sqrt(lambda_max)).clamp(0, _MAX_RADIUS)
        boxes, on_image = footprint_boxes(torch.stack([u, v], -1), cov2d, opacities, width, height)
        valid = in_front & on_image & torch.isfinite(cov2d).all(-1)
        radii = torch.where(valid, radii, torch.zeros_like(radii)).to(torch.int32)

    keep = valid[:, None]
    return (torch.where(keep, torch.stack([u, v], -1), 0.0).to(dtype), torch.where(keep, cov2d, 0.0).to(dtype),
            torch.where(keep, conics, 0.0).to(dtype), z.to(dtype), radii, valid, boxes)


def footprint_boxes(means2d: Tensor, cov2d: Tensor, opacities: Tensor | None, width: int, height: int):
    """Inclusive integer pixel boxes ``[N, 4]`` (x0, y0, x1, y1), clipped to the image, that hold
    every pixel where a Gaussian's alpha can reach ``ALPHA_MIN`` (``opacities`` given) or its
    3-sigma ellipse (``opacities`` None); and ``[N]`` bool: the box holds at least one pixel.

    The axis-aligned box of the ellipse ``d^T cov^-1 d <= q`` is ``|dx| <= sqrt(q cov_xx)``,
    ``|dy| <= sqrt(q cov_yy)``; alpha = o exp(-q/2) >= 1/255 gives q <= 2 ln(255 o).
    """
    with torch.no_grad():
        means2d, cov2d = means2d.detach().double(), cov2d.detach().double()
        if opacities is None:
            q_max = torch.full_like(cov2d[:, 0], 9.0)
        else:
            q_max = 2.0 * torch.log((opacities.detach().double() / ALPHA_MIN).clamp_min(1e-30))
        usable = q_max > 0
        q_max = q_max.clamp_min(0) * (1.0 + 1e-4) + 1e-4  # a hair wider: never miss a pixel by rounding
        ext_x = torch.sqrt(q_max * cov2d[:, 0].clamp_min(0))
        ext_y = torch.sqrt(q_max * cov2d[:, 2].clamp_min(0))
        u, v = means2d.unbind(-1)
        x0 = torch.ceil((u - ext_x).clamp(-1.0, width)).clamp_min(0)
        x1 = torch.floor((u + ext_x).clamp(-1.0, width)).clamp_max(width - 1)
        y0 = torch.ceil((v - ext_y).clamp(-1.0, height)).clamp_min(0)
        y1 = torch.floor((v + ext_y).clamp(-1.0, height)).clamp_max(height - 1)
        finite = torch.isfinite(means2d).all(-1) & torch.isfinite(ext_x) & torch.isfinite(ext_y)
        on_image = usable & finite & (x0 <= x1) & (y0 <= y1)
        boxes = torch.stack([x0, y0, x1, y1], -1).nan_to_num(0.0).long()
    return boxes, on_image


def project_gaussians(means: Tensor, quats: Tensor, scales: Tensor, world_to_cam: Tensor, K: Tensor,
                      width: int, height: int, *, near: float = 0.01, low_pass: float = 0.3,
                      opacities: Tensor | None = None) -> Projection:
    """Project N Gaussians (``means`` [N, 3] world, ``quats`` [N, 4] wxyz any norm, ``scales``
    [N, 3] standard deviations) into a ``width`` x ``height`` view (``world_to_cam`` [4, 4], ``K``
    [3, 3]).

    Gaussians with camera z < ``near`` are culled (radii 0, ``valid`` False, zero means2d, cov2d
    and conics), as are those whose footprint misses the image. The footprint is the 3-sigma
    ellipse, or, if ``opacities`` [N] are given, the region where alpha >= 1/255 (what the
    rasterizer draws). ``low_pass`` px^2 is added to the 2D covariance diagonal (anti-aliasing).
    """
    _check(means, quats, scales, world_to_cam, K, width, height, near, low_pass)
    if opacities is not None and tuple(opacities.shape) != (means.shape[0],):
        raise ValueError(f"opacities must have shape ({means.shape[0]},), got {tuple(opacities.shape)}")
    return _project(means, quats, scales, world_to_cam, K, int(width), int(height), float(near),
                    float(low_pass), opacities)[0]

