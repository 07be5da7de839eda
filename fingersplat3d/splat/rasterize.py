"""The differentiable Gaussian-splat rasterizer (pure torch; runs wherever its inputs live).

Pipeline: EWA projection (:mod:`.project`, float64 inside, O(N)) -> tile binning (:mod:`.binning`,
integer work: every Gaussian in each tile its alpha >= 1/255 box touches, front to back) ->
front-to-back compositing of dense per-group blocks (:mod:`.composite`). Gradients flow to all
Gaussian inputs, to ``world_to_cam`` (pose refinement) and to ``K``.

Semantics follow 3DGS: alpha = min(0.99, o exp(-d^T conic d / 2)), pairs with alpha < 1/255
skipped, no early termination (so the result is exactly the reference's, in
:mod:`.reference`), 0.3 px^2 low-pass on the 2D covariance, Gaussians with z < ``near`` culled.
"""
from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from .binning import bin_gaussians
from .config import BACKENDS
from .composite import EAGER_KERNELS, composite_tiles
from .gsplat_backend import rasterize_gsplat, why_not_usable
from .project import _check, _project

__all__ = ["BACKENDS", "RenderOutput", "rasterize", "resolve_backend"]

MIN_TRANSMITTANCE = 1e-4
"""Early termination of the ``numba`` backend: a pixel stops after the Gaussian that brings its
transmittance below this (3DGS and gsplat stop before it), so what it leaves out weighs less than
1e-4 of a feature."""
ALPHA_FOR_DEPTH = 1e-6
"""Expected depth is ``sum(w z) / alpha`` only where alpha exceeds this; 0 elsewhere."""


class RenderOutput(NamedTuple):
    color: Tensor  # [H, W, C] composited colour over `background` (default 0)
    alpha: Tensor  # [H, W] accumulated opacity in [0, 1)
    depth: Tensor  # [H, W] expected camera-z depth sum(w_i z_i) / alpha where alpha > 1e-6, else 0
    means2d: Tensor  # [N, 2] projected centres in pixels, part of the graph (call .retain_grad() on it)
    radii: Tensor  # [N] int32 pixel radius of the 3-sigma footprint, 0 for culled Gaussians
    depths: Tensor  # [N] camera z of each centre


def resolve_backend(backend: str, device: torch.device, means: Tensor | None = None, K: Tensor | None = None) -> str:
    """``auto`` -> ``numba`` for CPU tensors; elsewhere ``gsplat`` where it can render ``means`` and ``K``
    (:func:`.gsplat_backend.why_not_usable`; given both), else ``torch``. ``numba`` needs CPU tensors,
    ``gsplat`` usable inputs."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    gsplat_reason = why_not_usable(means, K) if means is not None and K is not None else "no inputs given"
    if backend == "auto":
        if device.type == "cpu":
            return "numba"
        return "gsplat" if gsplat_reason is None else "torch"
    if backend == "numba" and device.type != "cpu":
        raise ValueError(f"the numba backend runs on the CPU; these tensors are on {device}")
    if backend == "gsplat" and gsplat_reason is not None:
        raise ValueError(f"the gsplat backend cannot render these inputs: {gsplat_reason}")
    return backend


def check_render_inputs(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
                        world_to_cam: Tensor, K: Tensor, width: int, height: int, near: float,
                        background: Tensor | None, low_pass: float) -> None:
    """Shape, dtype and value checks of :func:`rasterize`'s arguments (one ValueError sentence)."""
    _check(means, quats, scales, world_to_cam, K, width, height, near, low_pass)
    n = means.shape[0]
    if not isinstance(opacities, Tensor) or tuple(opacities.shape) != (n,):
        raise ValueError(f"opacities must have shape ({n},), got {tuple(getattr(opacities, 'shape', ()))}")
    if not isinstance(colors, Tensor) or colors.ndim != 2 or colors.shape[0] != n or colors.shape[1] < 1:
        raise ValueError(f"colors must have shape ({n}, C) with C >= 1, got {tuple(getattr(colors, 'shape', ()))}")
    dtypes = {t.dtype for t in (means, quats, scales, opacities, colors)}
    if len(dtypes) != 1:
        raise ValueError(f"means, quats, scales, opacities and colors must share one dtype, got {sorted(map(str, dtypes))}")
    if background is not None and (not isinstance(background, Tensor) or tuple(background.shape) != (colors.shape[1],)):
        raise ValueError(f"background must have shape ({colors.shape[1]},), got {tuple(getattr(background, 'shape', ()))}")


def finish_render(color: Tensor, alpha: Tensor, depth_sum: Tensor, background: Tensor | None) -> tuple[Tensor, Tensor]:
    """Colour over the background and expected depth, from composited sums (finite gradients)."""
    if background is not None:
        color = color + (1.0 - alpha)[..., None] * background.to(color.dtype)
    covered = alpha > ALPHA_FOR_DEPTH
    depth = torch.where(covered, depth_sum / torch.where(covered, alpha, torch.ones_like(alpha)), 0.0)
    return color, depth


def rasterize(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
              world_to_cam: Tensor, K: Tensor, width: int, height: int, *, near: float = 0.01,
              background: Tensor | None = None, low_pass: float = 0.3, tile_size: int = 4,
              compiled: bool = False, backend: str = "auto",
              min_transmittance: float = MIN_TRANSMITTANCE) -> RenderOutput:
    """Render N Gaussians into one ``width`` x ``height`` view.

    means [N, 3] world; quats [N, 4] wxyz, any norm (zero = identity); scales [N, 3] standard
    deviations; opacities [N] in [0, 1]; colors [N, C] (any C); world_to_cam [4, 4]; K [3, 3];
    background [C] or None (= 0). ``tile_size`` only trades speed, never changes the result.
    ``compiled=True`` runs the projection and the compositing through ``torch.compile`` kernels
    (:mod:`.compiled`): faster after a one-off compile of tens of seconds (then cached by
    inductor on disk), same results to float rounding.

    ``backend``: ``numba`` composites with the compiled CPU kernels (:mod:`.cpu_composite`: exact
    ellipse-tile overlap, early termination at ``min_transmittance``; 0 gives the exact sum),
    ``torch`` with the tensor kernels (any device, exact sum, ``tile_size``/``compiled`` apply),
    ``gsplat`` with gsplat's CUDA kernels (:mod:`.gsplat_backend`: alpha capped at 0.999, early
    termination at 1e-4, no gradient to ``K``, float32), ``auto`` = ``numba`` for CPU tensors, on a GPU
    ``gsplat`` when it is installed and can render the inputs, else ``torch``.
    """
    check_render_inputs(means, quats, scales, opacities, colors, world_to_cam, K, width, height, near,
                        background, low_pass)
    if int(tile_size) != tile_size or tile_size < 1:
        raise ValueError(f"tile_size must be a positive integer, got {tile_size}")
    backend = resolve_backend(backend, means.device, means, K)
    width, height = int(width), int(height)
    channels = colors.shape[1]
    if backend == "gsplat":
        out = rasterize_gsplat(means, quats, scales, opacities, colors, world_to_cam, K, width, height, float(near),
                               float(low_pass))
        color, depth = finish_render(out.features[..., :channels], out.alpha, out.features[..., channels], background)
        return RenderOutput(color, out.alpha, depth, out.means2d, out.radii, out.depths)
    if backend == "numba":
        from .cpu_raster import composite_cpu, project_cpu

        projection, boxes = project_cpu(means, quats, scales, opacities, world_to_cam, K, width, height, float(near),
                                        float(low_pass))
        feats = torch.cat([colors, projection.depths[:, None]], 1)  # [N, C + 1]; alpha is 1 - final transmittance
        image, alpha = composite_cpu(projection.means2d, projection.conics, opacities, feats, boxes, projection.valid,
                                     projection.depths, width, height, min_transmittance)
        color, depth = finish_render(image[..., :channels], alpha, image[..., channels], background)
        return RenderOutput(color, alpha, depth, projection.means2d, projection.radii, projection.depths)
    projection, boxes = _project(means, quats, scales, world_to_cam, K, width, height, float(near),
                                 float(low_pass), opacities, compiled)
    feats = torch.cat([colors, torch.ones_like(colors[:, :1]), projection.depths[:, None]], 1)  # [N, C + 2]
    bins = bin_gaussians(boxes, projection.valid, projection.depths, width, height, tile_size)
    kernels = EAGER_KERNELS
    if compiled:
        from .compiled import compiled_kernels  # torch.compile machinery only when asked for

        kernels = compiled_kernels()
    image = composite_tiles(bins, projection.means2d, projection.conics, opacities, feats, width, height, kernels)
    color, alpha, depth_sum = image[..., :channels], image[..., channels], image[..., channels + 1]
    color, depth = finish_render(color, alpha, depth_sum, background)
    return RenderOutput(color, alpha, depth, projection.means2d, projection.radii, projection.depths)
