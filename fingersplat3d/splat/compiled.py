"""Optional ``torch.compile`` (inductor) versions of the per-group compositing kernels.

Same contract and formulas as :func:`.composite.forward_group` / :func:`.composite.backward_group`,
written for fusion rather than for eager speed: the small products over feature channels and the
pixel sums of the backward are explicit broadcast-and-sum expressions, which inductor fuses into
the elementwise chains (eagerly they would materialise ``[G, L, S, F]`` tensors), and the pixel
sums are taken directly instead of through moments. Only the prefix product (forward) and sum
(backward) stay ATen calls (inductor's CPU backend has no scan). Off by default; the first call
compiles (tens of seconds, then cached on disk by inductor); G and L are dynamic so tile groups of
any size reuse the kernels. Measured on the 2-core machine (single thread, 200k-Gaussian finger
scene, ~21M evaluated pairs): forward ~3.6 ns and backward ~6.6 ns per evaluated pair, against
~14 and ~22 ns eagerly.
"""
from __future__ import annotations

import torch
from torch import Tensor

from .composite import GroupKernels, pair_alpha
from .project import ALPHA_MAX

__all__ = ["compiled_kernels"]


def _dot_features(feats: Tensor, grad_pixels: Tensor) -> Tensor:
    """``[G, L, F] . [G, F, S] -> [G, L, S]``, unrolled over the few channels."""
    total = feats[:, :, 0, None] * grad_pixels[:, None, 0, :]
    for f in range(1, feats.shape[2]):
        total = total + feats[:, :, f, None] * grad_pixels[:, None, f, :]
    return total


def forward_group_fused(params: Tensor, params_again: Tensor, feats: Tensor, grid: Tensor) -> tuple[Tensor, Tensor]:
    """:func:`.composite.forward_group` for inductor. ``params_again`` is a copy of ``params``:
    alpha is recomputed after the prefix sum from it instead of being shared, because inductor
    would otherwise write the shared ``[G, L, S]`` values to memory and read them back, which
    costs more than the few flops of recomputing them."""
    alpha = pair_alpha(params, grid)[0]  # [G, L, S]
    kept = torch.cumprod(1.0 - alpha, 1)  # inclusive; 1 - alpha >= 0.01, so the division below is safe
    alpha = pair_alpha(params_again, grid)[0]
    transmittance = kept / (1.0 - alpha)
    weights = alpha * transmittance
    # One reduction per feature channel (not one over a [G, F, L, S] broadcast): inductor then
    # computes the weights once per pair for all channels instead of once per channel.
    pixels = torch.stack([(weights * feats[:, :, f, None]).sum(1) for f in range(feats.shape[2])], 1)  # [G, F, S]
    return pixels, transmittance


def backward_group_fused(params: Tensor, params_again: Tensor, feats: Tensor, feats_again: Tensor, grid: Tensor,
                         transmittance: Tensor, pixels: Tensor, grad_pixels: Tensor) -> Tensor:
    """:func:`.composite.backward_group` for inductor (copies of the inputs as in the forward)."""
    alpha = pair_alpha(params, grid)[0]
    per_pair = _dot_features(feats, grad_pixels)  # [G, L, S]
    prefix = torch.cumsum(alpha * transmittance * per_pair, 1)
    alpha, raw, falloff, dx, dy = pair_alpha(params_again, grid)
    per_pair = _dot_features(feats_again, grad_pixels)
    weights = alpha * transmittance
    total = (pixels * grad_pixels).sum(1)  # [G, S]
    behind = total[:, None, :] - prefix
    grad_alpha = transmittance * per_pair - behind / (1.0 - alpha)
    grad_raw = torch.where((alpha > 0) & (raw < ALPHA_MAX), grad_alpha, 0.0)
    grad_q = -0.5 * grad_raw * raw
    a, b, c = (params_again[..., k:k + 1] for k in (2, 3, 4))
    grad_params = torch.stack([
        (-2.0 * grad_q * (a * dx + b * dy)).sum(-1), (-2.0 * grad_q * (b * dx + c * dy)).sum(-1),
        (grad_q * dx * dx).sum(-1), (2.0 * grad_q * dx * dy).sum(-1), (grad_q * dy * dy).sum(-1),
        (grad_raw * falloff).sum(-1)], -1)  # [G, L, 6]
    grad_feats = [(weights * grad_pixels[:, None, f, :]).sum(-1) for f in range(feats.shape[2])]
    return torch.cat([grad_params, torch.stack(grad_feats, -1)], -1)  # [G, L, 6 + F]


_KERNELS: GroupKernels | None = None


def _compile(function, dynamic_inputs: tuple[int, ...]):
    """Compile ``function`` with the group (G) and list (L) sizes of its ``[G, L, ...]`` inputs
    dynamic and everything else (pixels per tile, feature channels) static, so that the pixel loop
    is a fixed-width vector loop and tile groups of any size reuse the same kernels."""
    compiled = torch.compile(function, dynamic=False)

    def call(*tensors: Tensor):
        for t in tensors:
            if t.ndim == 3:
                torch._dynamo.mark_dynamic(t, 0)
        for i in dynamic_inputs:
            torch._dynamo.mark_dynamic(tensors[i], 1)
        return compiled(*tensors)

    return call


def _forward(compiled):
    def forward(params: Tensor, feats: Tensor, grid: Tensor, moments_basis: Tensor):
        return compiled(params, params.clone(), feats, grid)
    return forward


def _backward(compiled):
    def backward(params: Tensor, feats: Tensor, grid: Tensor, moments_basis: Tensor, transmittance: Tensor,
                 pixels: Tensor, grad_pixels: Tensor):
        return compiled(params, params.clone(), feats, feats.clone(), grid, transmittance, pixels, grad_pixels)
    return backward


def compiled_kernels() -> GroupKernels:
    """The fused kernels, compiled once per process (lazily, on first use)."""
    global _KERNELS
    if _KERNELS is None:
        _KERNELS = GroupKernels(_forward(_compile(forward_group_fused, (0, 1, 2))),
                                _backward(_compile(backward_group_fused, (0, 1, 2, 3, 5))))
    return _KERNELS
