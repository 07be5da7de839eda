"""2D rotary position embedding (RoPE) of CroCo / DUSt3R, and the patch positions it rotates by.

Each attention head's features are split in two halves: the first is rotated by the token's
row (y), the second by its column (x). Within a half of ``D`` features, the pair
``(f[k], f[k + D/2])`` turns by the angle ``position * F0 / base^(2k / D)`` (the "rotate half"
layout). Relative positions are then what the dot product between a query and a key sees.
"""
from __future__ import annotations

import torch
from torch import nn

__all__ = ["RoPE2D", "patch_positions"]


def patch_positions(batch: int, rows: int, cols: int, device: torch.device | str | None = None) -> torch.Tensor:
    """``[batch, rows * cols, 2]`` int64 ``(y, x)`` grid positions of the patches, row-major."""
    y = torch.arange(rows, device=device)
    x = torch.arange(cols, device=device)
    grid = torch.cartesian_prod(y, x)  # [rows * cols, 2]
    return grid[None].expand(batch, -1, -1)


class RoPE2D(nn.Module):
    """Rotary embedding over ``(y, x)`` positions; no parameters (nothing in the state dict)."""

    def __init__(self, base: float = 100.0, f0: float = 1.0) -> None:
        super().__init__()
        self.base = float(base)
        self.f0 = float(f0)

    def _rotate(self, features: torch.Tensor, position: torch.Tensor) -> torch.Tensor:
        """Rotate ``features [B, heads, N, D]`` by integer positions ``[B, N]`` (1D RoPE)."""
        dim = features.shape[-1]
        inv_freq = self.f0 / (self.base ** (torch.arange(0, dim, 2, device=features.device).float() / dim))  # [D/2]
        angles = position.to(inv_freq.dtype)[..., None] * inv_freq  # [B, N, D/2], float32 like upstream
        angles = torch.cat((angles, angles), dim=-1).to(features.dtype)[:, None]  # [B, 1, N, D]
        first, second = features.chunk(2, dim=-1)
        rotated_half = torch.cat((-second, first), dim=-1)
        return features * angles.cos() + rotated_half * angles.sin()

    def forward(self, tokens: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
        """``tokens [B, heads, N, head_dim]``, ``positions [B, N, 2]`` (y, x) -> rotated tokens."""
        if tokens.shape[-1] % 4:
            raise ValueError(f"RoPE2D needs a head dimension divisible by 4, got {tokens.shape[-1]}")
        y_part, x_part = tokens.chunk(2, dim=-1)
        return torch.cat((self._rotate(y_part, positions[..., 0]), self._rotate(x_part, positions[..., 1])), dim=-1)
