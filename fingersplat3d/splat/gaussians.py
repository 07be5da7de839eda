"""The Gaussian-splat model: raw (optimised) parameters and their activations.

Parameters are stored as 3DGS stores them, so the PLY export is a copy: ``log_scales`` (natural
log of the standard deviations), ``opacity_logits`` (logit of the opacity), ``quats`` (wxyz, any
norm) and ``sh_dc`` (the SH degree-0 coefficient, ``colour = 0.5 + SH_C0 * sh_dc``). Grayscale
models have one colour channel, RGB models three. The one view-dependent term is the capture's
``facing_exponent``: a camera sees each colour darkened by the cosine at which it sees the Gaussian to
that power (:mod:`.shading`; 0 = none, the plain SH degree 0 model), so ``sh_dc`` is the skin seen face on.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from ..rotations import normalize_quaternions, quaternion_to_matrix
from .shading import MAX_EXPONENT

__all__ = ["Gaussians", "SH_C0", "rgb_to_sh", "sh_to_rgb", "covariance_3d"]

SH_C0 = 0.28209479177387814
"""The degree-0 real spherical harmonic, ``1 / (2 sqrt(pi))``."""


def rgb_to_sh(colour: torch.Tensor) -> torch.Tensor:
    return (colour - 0.5) / SH_C0


def sh_to_rgb(sh_dc: torch.Tensor) -> torch.Tensor:
    return 0.5 + SH_C0 * sh_dc


@dataclass(frozen=True, eq=False)
class Gaussians:
    """N Gaussians in world coordinates (raw parameters, as optimised and as written to PLY)."""

    means: torch.Tensor  # [N, 3] world
    quats: torch.Tensor  # [N, 4] wxyz, any norm
    log_scales: torch.Tensor  # [N, 3] log standard deviations along the rotated axes
    opacity_logits: torch.Tensor  # [N]
    sh_dc: torch.Tensor  # [N, C] C = 1 (grayscale) or 3 (RGB)
    facing_exponent: float = 0.0  # the capture's shading exponent (module docstring); 0 = no view-dependent term

    def __post_init__(self) -> None:
        exponent = self.facing_exponent
        if isinstance(exponent, bool) or not isinstance(exponent, (int, float)) or not 0.0 <= exponent <= MAX_EXPONENT:
            raise ValueError(f"Gaussians.facing_exponent must be a number in [0, {MAX_EXPONENT:g}], got {exponent!r}")
        n = self.means.shape[0]
        expected = {"means": (n, 3), "quats": (n, 4), "log_scales": (n, 3), "opacity_logits": (n,)}
        for name, shape in expected.items():
            if tuple(getattr(self, name).shape) != shape:
                raise ValueError(f"Gaussians.{name} must have shape {shape}, got {tuple(getattr(self, name).shape)}")
        if self.sh_dc.ndim != 2 or self.sh_dc.shape[0] != n or self.sh_dc.shape[1] not in (1, 3):
            raise ValueError(f"Gaussians.sh_dc must be [N, 1] or [N, 3], got {tuple(self.sh_dc.shape)}")

    def __len__(self) -> int:
        return self.means.shape[0]

    @property
    def channels(self) -> int:
        return self.sh_dc.shape[1]

    @property
    def scales(self) -> torch.Tensor:
        """``[N, 3]`` standard deviations."""
        return torch.exp(self.log_scales)

    @property
    def opacities(self) -> torch.Tensor:
        """``[N]`` in (0, 1)."""
        return torch.sigmoid(self.opacity_logits)

    @property
    def colors(self) -> torch.Tensor:
        """``[N, C]`` colour in [0, 1] (clamped) from the SH DC coefficient."""
        return sh_to_rgb(self.sh_dc).clamp(0.0, 1.0)

    @property
    def rotations(self) -> torch.Tensor:
        """``[N, 4]`` unit wxyz quaternions."""
        return normalize_quaternions(self.quats)

    def subset(self, keep: torch.Tensor) -> "Gaussians":
        """The Gaussians selected by a boolean mask or an index tensor."""
        return Gaussians(self.means[keep], self.quats[keep], self.log_scales[keep], self.opacity_logits[keep],
                         self.sh_dc[keep], self.facing_exponent)

    def detach(self) -> "Gaussians":
        return Gaussians(*(t.detach() for t in self.tensors()), self.facing_exponent)

    def to(self, device: torch.device | str, dtype: torch.dtype | None = None) -> "Gaussians":
        return Gaussians(*(t.to(device=device, dtype=dtype) for t in self.tensors()), self.facing_exponent)

    def tensors(self) -> tuple[torch.Tensor, ...]:
        return self.means, self.quats, self.log_scales, self.opacity_logits, self.sh_dc

    @staticmethod
    def concat(parts: list["Gaussians"]) -> "Gaussians":
        """One model of ``parts`` (their shading exponents must agree: they are one capture's)."""
        exponents = {p.facing_exponent for p in parts}
        if len(exponents) > 1:
            raise ValueError(f"Gaussians.concat: the parts' facing exponents differ ({sorted(exponents)})")
        return Gaussians(*(torch.cat(group) for group in zip(*(p.tensors() for p in parts))),
                         exponents.pop() if exponents else 0.0)

    def with_(self, **changes) -> "Gaussians":
        return replace(self, **changes)


def covariance_3d(quats: torch.Tensor, scales: torch.Tensor) -> torch.Tensor:
    """``Sigma = R S S R^T`` from ``[N, 4]`` wxyz quaternions and ``[N, 3]`` standard deviations."""
    rotation_scale = quaternion_to_matrix(quats) * scales[..., None, :]
    return rotation_scale @ rotation_scale.transpose(-1, -2)
