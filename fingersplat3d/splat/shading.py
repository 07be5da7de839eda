"""Skin darker where a camera sees it at a slant: the one view-dependent term of the Gaussian model.

A skin point's brightness in a photo depends on the angle at which that camera sees it. Measured on
the real dev captures (every skin point two cameras see, its brightness in each, blurred past the
ridges, against the cosine ``mu`` between the surface normal and the direction to each camera):
``log(I_a / I_b)`` follows ``k log(mu_a / mu_b)`` with a correlation of 0.83-0.97 and ``k`` 0.38-0.52
on one finger, 0.21-0.35 on the other, 0.09-0.25 on ``fs3d synth`` fingers; plus an exposure offset
between the cameras (up to 12 %). With one colour per Gaussian (SH degree 0, the paper's model) the
fit averages a point's bright frontal and dark slanted looks, and a view left out is rendered with the
wrong shading: on the real captures that low-frequency error was most of the held-out views' error.

So the colour a camera sees of Gaussian ``i`` is ``albedo_i * mu_i ** k``: the SH DC colour is the
albedo (the skin seen face on) and ``k`` (``Gaussians.facing_exponent``) one number per capture,
estimated from the registered geometry before the fit (:mod:`.shading_estimate`) and kept by it.
``mu_i`` is taken about the Gaussian's shortest axis, the normal of the flat discs the model is made
of (as normal-aware splatting methods take it), from the model's current geometry and without a
gradient: the shading explains brightness, it does not move the surface. The cameras' exposures are
not modelled: fitted per photo (with ``k`` learned along) they moved the held-out synthetic views by
-1.1 to +0.7 dB, where the fixed ``k`` alone moved them by -0.6 to +1.6 dB; on the real captures they
added 0.1-0.5 dB.

One number per capture where SH degree 1 would add nine per Gaussian; a model with ``k = 0`` renders
exactly as the plain SH degree 0 model. Pure torch; on the CPU the cosines come from one compiled pass
(:mod:`.cpu_shading`), the same formula.
"""
from __future__ import annotations

import torch

from ..rotations import quaternion_to_matrix

__all__ = ["MIN_FACING", "MAX_EXPONENT", "facing_cosines", "shade"]

MIN_FACING = 0.05
"""Cosines below this count as this: a Gaussian seen edge-on keeps a finite, non-zero colour (and gradient)."""
MAX_EXPONENT = 4.0
"""The exponent is held in ``[0, MAX_EXPONENT]`` (measured ones are under 0.6)."""


def facing_cosines(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                   world_to_cam: torch.Tensor) -> torch.Tensor:
    """``[N]`` ``|n . d|`` in ``[MIN_FACING, 1]``: ``n`` each Gaussian's shortest axis, ``d`` the unit direction
    from its centre to the camera; no gradient (see the module docstring)."""
    with torch.no_grad():
        count = means.shape[0]
        if count == 0:
            return means.new_zeros(0)
        rotation_wc, translation = world_to_cam[:3, :3], world_to_cam[:3, 3]
        centre = -(rotation_wc.transpose(0, 1) @ translation)
        if means.device.type == "cpu" and means.dtype in (torch.float32, torch.float64):
            from .cpu_shading import facing_cosines_cpu

            arrays = (t.detach().numpy() for t in (means, quats, log_scales, centre.double()))
            return torch.from_numpy(facing_cosines_cpu(*arrays, MIN_FACING)).to(means.dtype)
        return _facing_cosines_torch(means, quats, log_scales, centre)


def _facing_cosines_torch(means: torch.Tensor, quats: torch.Tensor, log_scales: torch.Tensor,
                          centre: torch.Tensor) -> torch.Tensor:
    """:func:`facing_cosines` in tensor operations (any device; the CPU's compiled pass is checked against it)."""
    with torch.no_grad():
        count = means.shape[0]
        rotation = quaternion_to_matrix(quats)  # [N, 3, 3], columns = principal axes; zero quaternion = identity
        normals = rotation[torch.arange(count, device=means.device), :, log_scales.argmin(dim=1)]
        towards = centre.to(means.dtype)[None] - means
        length = torch.linalg.vector_norm(towards, dim=1)
        cosine = (normals * towards).sum(dim=1).abs() / length.clamp_min(torch.finfo(means.dtype).tiny)
        cosine = torch.where(torch.isfinite(cosine), cosine, torch.ones_like(cosine))
        return cosine.clamp(MIN_FACING, 1.0)


def shade(colors: torch.Tensor, cosines: torch.Tensor, exponent: torch.Tensor | float) -> torch.Tensor:
    """``[N, C]`` colours seen by one camera: ``colors * cosines ** exponent`` (exponent held in
    ``[0, MAX_EXPONENT]``; differentiable in ``colors`` and ``exponent``)."""
    exponent = torch.as_tensor(exponent, dtype=colors.dtype, device=colors.device).clamp(0.0, MAX_EXPONENT)
    return colors * torch.exp(exponent * torch.log(cosines.to(colors.dtype)))[:, None]
