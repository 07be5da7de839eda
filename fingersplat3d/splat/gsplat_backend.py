"""gsplat's CUDA kernels (nerfstudio-project/gsplat) behind :func:`~fingersplat3d.splat.rasterize.rasterize`.

On a GPU the project's own ``torch`` backend launches many small kernels and gathers per tile; it ran
slower on an H100 than the ``numba`` kernels on two CPU cores (docs/measurements.md, rasterizer). gsplat
is the well-kept CUDA rasterizer of the 3DGS field, so it is used when it is installed (``pip install
gsplat``; it compiles its kernels on first use) rather than a kernel of the project's own.

Called through gsplat's low-level functions (projection, tile intersection, compositing), not its
``rasterization`` wrapper, so that the projected centres handed back are the tensor the compositor
consumed: ``means2d.retain_grad()`` then gets the densification statistics, as with the other backends.

Differences from the reference (:mod:`.reference`), all gsplat's design:

- alpha is capped at 0.999 (3DGS and the reference: 0.99), and a pixel stops once its transmittance
  falls below 1e-4 (the ``numba`` backend's default too);
- no gradient reaches ``K`` (the fit never asks for one); float32 only.

:func:`why_not_usable` says when ``auto`` may pick it; ``rasterize(..., backend="gsplat")`` outside those
conditions is a ValueError.
"""
from __future__ import annotations

import importlib.util
import math
from typing import NamedTuple

import torch
from torch import Tensor

from ..rotations import normalize_quaternions

__all__ = ["GsplatRender", "installed", "why_not_usable", "rasterize_gsplat"]


class GsplatRender(NamedTuple):
    features: Tensor  # [H, W, C + 1] composited colour channels then camera-z depth (not divided by alpha)
    alpha: Tensor  # [H, W]
    means2d: Tensor  # [N, 2] projected centres in pixels, in the graph
    radii: Tensor  # [N] int32, 0 = culled
    depths: Tensor  # [N] camera z of each centre


def installed() -> bool:
    """gsplat can be imported (its kernels may still need their first compile)."""
    return importlib.util.find_spec("gsplat") is not None


def why_not_usable(means: Tensor, K: Tensor) -> str | None:
    """None when gsplat can render these inputs, else the reason in a few words."""
    if means.device.type != "cuda":
        return f"gsplat runs on CUDA; these tensors are on {means.device}"
    if means.dtype != torch.float32:
        return f"gsplat renders float32; these tensors are {means.dtype}"
    if K.requires_grad:
        return "gsplat gives no gradient to K"
    if not installed():
        return "gsplat is not installed (pip install gsplat)"
    return None


def rasterize_gsplat(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
                     world_to_cam: Tensor, K: Tensor, width: int, height: int, near: float, low_pass: float,
                     tile_size: int = 16) -> GsplatRender:
    """One view through gsplat (inputs as :func:`~fingersplat3d.splat.rasterize.rasterize`, checked there)."""
    from gsplat.cuda._wrapper import fully_fused_projection, isect_offset_encode, isect_tiles, rasterize_to_pixels

    # gsplat samples pixel (i, j) at (i + 0.5, j + 0.5); the project's pixels are centred at integers (OpenCV).
    shifted_K = K.detach().clone()
    shifted_K[:2, 2] += 0.5
    radii, means2d_batch, depths, conics, _ = fully_fused_projection(
        means, None, normalize_quaternions(quats), scales, world_to_cam[None], shifted_K[None], width, height,
        eps2d=low_pass, near_plane=near, packed=False)  # [1, N, ...]
    means2d = means2d_batch[0] - 0.5  # in the project's pixels; the compositor reads it, so a retained grad arrives
    gsplat_means2d = (means2d + 0.5)[None]
    tiles_x, tiles_y = math.ceil(width / tile_size), math.ceil(height / tile_size)
    _, isect_ids, flatten_ids = isect_tiles(gsplat_means2d.detach(), radii, depths, tile_size, tiles_x, tiles_y)
    offsets = isect_offset_encode(isect_ids, 1, tiles_x, tiles_y).reshape(1, tiles_y, tiles_x)
    features = torch.cat([colors, depths[0][:, None]], 1)[None]  # depth composited like a colour
    image, alpha = rasterize_to_pixels(gsplat_means2d, conics, features, opacities[None], width, height, tile_size,
                                       offsets, flatten_ids)
    radius = radii[0].amax(-1) if radii.ndim == 3 else radii[0]  # gsplat >= 1.5 gives x and y radii
    return GsplatRender(image[0], alpha[0, ..., 0], means2d, radius.to(torch.int32), depths[0])
