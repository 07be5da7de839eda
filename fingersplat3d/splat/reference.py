"""A slow, obviously-correct rasterizer: the yardstick for :func:`~.rasterize.rasterize`.

No cleverness: the projection is written with 3x3 / 2x3 matrices and ``torch.linalg.inv``; every
Gaussian is evaluated at every pixel (an ``[N, H*W]`` alpha matrix), Gaussians are sorted by depth
and composited with an explicit ``cumprod``. Memory is O(N H W): small scenes only (tests).
Same arguments and same :class:`~.rasterize.RenderOutput` as the fast rasterizer.
"""
from __future__ import annotations

import torch
from torch import Tensor

from .gaussians import covariance_3d
from .rasterize import RenderOutput, check_render_inputs

__all__ = ["reference_project", "reference_rasterize"]


def reference_project(means: Tensor, quats: Tensor, scales: Tensor, world_to_cam: Tensor, K: Tensor,
                      width: int, height: int, near: float = 0.01, low_pass: float = 0.3):
    """``(means2d [N, 2], cov2d [N, 2, 2], conics [N, 2, 2], depths [N], in_front [N])`` in float64.

    cov2d = J W Sigma W^T J^T + low_pass I, with J the Jacobian of the pinhole projection at the
    camera-frame centre, its x/z and y/z clamped to the frustum enlarged by 30 % on each side."""
    f64 = torch.float64
    rotation, translation = world_to_cam[:3, :3].to(f64), world_to_cam[:3, 3].to(f64)
    fx, fy, cx, cy = K[0, 0].to(f64), K[1, 1].to(f64), K[0, 2].to(f64), K[1, 2].to(f64)
    p_cam = means.to(f64) @ rotation.T + translation
    z = p_cam[:, 2]
    in_front = z >= float(torch.tensor(near, dtype=means.dtype))
    z1 = torch.where(in_front, z, torch.ones_like(z))
    x_over_z = p_cam[:, 0] / z1
    y_over_z = p_cam[:, 1] / z1
    means2d = torch.stack([fx * x_over_z + cx, fy * y_over_z + cy], -1)
    x_clamped = torch.minimum(torch.maximum(x_over_z, -(cx + 0.3 * width) / fx), (1.3 * width - cx) / fx) * z1
    y_clamped = torch.minimum(torch.maximum(y_over_z, -(cy + 0.3 * height) / fy), (1.3 * height - cy) / fy) * z1
    jacobian = torch.zeros(len(z), 2, 3, dtype=f64, device=means.device)
    jacobian[:, 0, 0] = fx / z1
    jacobian[:, 0, 2] = -fx * x_clamped / (z1 * z1)
    jacobian[:, 1, 1] = fy / z1
    jacobian[:, 1, 2] = -fy * y_clamped / (z1 * z1)
    sigma = covariance_3d(quats.to(f64), scales.to(f64))  # [N, 3, 3]
    jw = jacobian @ rotation
    cov2d = jw @ sigma @ jw.transpose(1, 2) + low_pass * torch.eye(2, dtype=f64, device=means.device)
    conics = torch.linalg.inv(cov2d)
    return means2d, cov2d, conics, z, in_front


def reference_rasterize(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
                        world_to_cam: Tensor, K: Tensor, width: int, height: int, *, near: float = 0.01,
                        background: Tensor | None = None, low_pass: float = 0.3) -> RenderOutput:
    check_render_inputs(means, quats, scales, opacities, colors, world_to_cam, K, width, height, near,
                        background, low_pass)
    dtype = means.dtype
    means2d, cov2d, conics, z, in_front = reference_project(means, quats, scales, world_to_cam, K, width,
                                                            height, near, low_pass)
    means2d, conics, z_out = means2d.to(dtype), conics.to(dtype), z.to(dtype)

    # Every pixel (x, y), row-major: [P, 2].
    ys, xs = torch.meshgrid(torch.arange(height, device=means.device), torch.arange(width, device=means.device),
                            indexing="ij")
    pixels = torch.stack([xs.reshape(-1), ys.reshape(-1)], -1).to(dtype)

    drawn = torch.nonzero(in_front).squeeze(1)
    drawn = drawn[torch.argsort(z[drawn], stable=True)]  # front to back
    offset = pixels[None, :, :] - means2d[drawn][:, None, :]  # [V, P, 2]
    q = torch.einsum("vpi,vij,vpj->vp", offset, conics[drawn], offset)
    raw = opacities[drawn][:, None] * torch.exp(-0.5 * q.clamp_min(0.0))
    alpha = torch.where(raw >= 1.0 / 255.0, raw.clamp_max(0.99), 0.0)  # [V, P]
    before = torch.cat([torch.ones_like(alpha[:1]), 1.0 - alpha[:-1]])
    weights = alpha * torch.cumprod(before, 0)  # [V, P]
    color = (weights[:, :, None] * colors[drawn][:, None, :]).sum(0).reshape(height, width, -1)
    accumulated = weights.sum(0).reshape(height, width)
    depth_sum = (weights * z_out[drawn][:, None]).sum(0).reshape(height, width)
    if background is not None:
        color = color + (1.0 - accumulated)[..., None] * background.to(dtype)
    covered = accumulated > 1e-6
    depth = torch.where(covered, depth_sum / torch.where(covered, accumulated, torch.ones_like(accumulated)), 0.0)

    # Radius of the 3-sigma circle; 0 unless in front and some pixel of the image lies in the box
    # that bounds where alpha can reach 1/255.
    with torch.no_grad():
        eigen = torch.linalg.eigvalsh(cov2d)  # [N, 2] ascending
        radii = torch.ceil(3.0 * torch.sqrt(eigen[:, 1]))
        q_max = 2.0 * torch.log((opacities.double() * 255.0).clamp_min(1e-30))
        ext = torch.sqrt(q_max.clamp_min(0)[:, None] * torch.diagonal(cov2d, dim1=1, dim2=2))  # [N, 2]
        nearest = torch.stack([means2d[:, 0].double().round().clamp(0, width - 1),
                               means2d[:, 1].double().round().clamp(0, height - 1)], -1)
        touches = ((nearest - means2d.double()).abs() <= ext).all(-1) & (q_max > 0)
        shown = in_front & touches
        radii = torch.where(shown, radii, torch.zeros_like(radii)).to(torch.int32)
    means2d = torch.where(shown[:, None], means2d, 0.0)
    return RenderOutput(color, accumulated, depth, means2d, radii, z_out)

