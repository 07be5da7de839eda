"""Transformer blocks of the DUSt3R encoder and decoder (ViT blocks with 2D RoPE, cross-attention).

Module and attribute names follow the official checkpoints' state-dict keys
(``attn.qkv``, ``cross_attn.projq``, ``mlp.fc1``, ``norm_y``...), so weights load with ``strict=True``.
Attention runs through :func:`torch.nn.functional.scaled_dot_product_attention` (no ``N x N``
matrix kept on CPU; the same maths as softmax(q k^T / sqrt(d)) v up to float rounding).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .rope import RoPE2D, patch_positions

__all__ = ["LAYER_NORM_EPS", "PatchEmbed", "Mlp", "SelfAttention", "CrossAttention", "EncoderBlock", "DecoderBlock"]

LAYER_NORM_EPS = 1e-6  # every LayerNorm of CroCo / DUSt3R


class PatchEmbed(nn.Module):
    """Non-overlapping ``patch x patch`` convolution: ``[B, 3, H, W]`` -> tokens ``[B, N, C]`` and positions."""

    def __init__(self, patch_size: int, embed_dim: int) -> None:
        super().__init__()
        self.patch_size = patch_size
        self.proj = nn.Conv2d(3, embed_dim, kernel_size=patch_size, stride=patch_size)

    def forward(self, images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        batch, _, height, width = images.shape
        if height % self.patch_size or width % self.patch_size:
            raise ValueError(f"image size {width}x{height} is not a multiple of the patch size {self.patch_size}")
        features = self.proj(images)  # [B, C, H/p, W/p]
        positions = patch_positions(batch, features.shape[2], features.shape[3], images.device)
        return features.flatten(2).transpose(1, 2), positions


class Mlp(nn.Module):
    def __init__(self, dim: int, hidden: int) -> None:
        super().__init__()
        self.fc1 = nn.Linear(dim, hidden)
        self.act = nn.GELU()
        self.fc2 = nn.Linear(hidden, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.fc2(self.act(self.fc1(x)))


def _heads(x: torch.Tensor, num_heads: int) -> torch.Tensor:
    """``[B, N, C]`` -> ``[B, heads, N, C / heads]``."""
    batch, tokens, channels = x.shape
    return x.reshape(batch, tokens, num_heads, channels // num_heads).transpose(1, 2)


def _merge(x: torch.Tensor) -> torch.Tensor:
    """``[B, heads, N, d]`` -> ``[B, N, heads * d]``."""
    batch, heads, tokens, dim = x.shape
    return x.transpose(1, 2).reshape(batch, tokens, heads * dim)


class SelfAttention(nn.Module):
    def __init__(self, dim: int, num_heads: int, rope: RoPE2D) -> None:
        super().__init__()
        self.num_heads = num_heads
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)
        self.rope = rope

    def forward(self, x: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
        batch, tokens, channels = x.shape
        qkv = self.qkv(x).reshape(batch, tokens, 3, self.num_heads, channels // self.num_heads)
        q, k, v = qkv.permute(2, 0, 3, 1, 4)  # each [B, heads, N, d]
        q, k = self.rope(q, positions), self.rope(k, positions)
        return self.proj(_merge(F.scaled_dot_product_attention(q, k, v)))


class CrossAttention(nn.Module):
    def __init__(self, dim: int, num_heads: int, rope: RoPE2D) -> None:
        super().__init__()
        self.num_heads = num_heads
        self.projq = nn.Linear(dim, dim)
        self.projk = nn.Linear(dim, dim)
        self.projv = nn.Linear(dim, dim)
        self.proj = nn.Linear(dim, dim)
        self.rope = rope

    def forward(self, query: torch.Tensor, memory: torch.Tensor, query_positions: torch.Tensor,
                memory_positions: torch.Tensor) -> torch.Tensor:
        q = self.rope(_heads(self.projq(query), self.num_heads), query_positions)
        k = self.rope(_heads(self.projk(memory), self.num_heads), memory_positions)
        v = _heads(self.projv(memory), self.num_heads)
        return self.proj(_merge(F.scaled_dot_product_attention(q, k, v)))


class EncoderBlock(nn.Module):
    """Pre-norm ViT block: self-attention and MLP, each with a residual."""

    def __init__(self, dim: int, num_heads: int, mlp_ratio: float, rope: RoPE2D) -> None:
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=LAYER_NORM_EPS)
        self.attn = SelfAttention(dim, num_heads, rope)
        self.norm2 = nn.LayerNorm(dim, eps=LAYER_NORM_EPS)
        self.mlp = Mlp(dim, int(dim * mlp_ratio))

    def forward(self, x: torch.Tensor, positions: torch.Tensor) -> torch.Tensor:
        x = x + self.attn(self.norm1(x), positions)
        return x + self.mlp(self.norm2(x))


class DecoderBlock(nn.Module):
    """Self-attention over one view's tokens, cross-attention to the other view's, then MLP."""

    def __init__(self, dim: int, num_heads: int, mlp_ratio: float, rope: RoPE2D, norm_memory: bool = True) -> None:
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=LAYER_NORM_EPS)
        self.attn = SelfAttention(dim, num_heads, rope)
        self.cross_attn = CrossAttention(dim, num_heads, rope)
        self.norm2 = nn.LayerNorm(dim, eps=LAYER_NORM_EPS)
        self.norm3 = nn.LayerNorm(dim, eps=LAYER_NORM_EPS)
        self.mlp = Mlp(dim, int(dim * mlp_ratio))
        self.norm_y = nn.LayerNorm(dim, eps=LAYER_NORM_EPS) if norm_memory else nn.Identity()

    def forward(self, x: torch.Tensor, other: torch.Tensor, positions: torch.Tensor,
                other_positions: torch.Tensor) -> torch.Tensor:
        """``x [B, N, C]`` (this view), ``other [B, M, C]`` (the other view, previous layer) -> ``[B, N, C]``."""
        x = x + self.attn(self.norm1(x), positions)
        memory = self.norm_y(other)
        x = x + self.cross_attn(self.norm2(x), memory, positions, other_positions)
        return x + self.mlp(self.norm3(x))
