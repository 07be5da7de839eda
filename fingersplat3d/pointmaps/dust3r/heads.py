"""The linear prediction head and the mapping of raw head outputs to points and confidences.

A head turns decoder tokens into ``3 (+1)`` channels per pixel; :func:`regress_points` and
:func:`regress_confidence` then apply the checkpoint's ``depth_mode`` / ``conf_mode``:
``exp`` scales the raw xyz to the norm ``expm1(|xyz|)`` (points can lie at any distance), the
confidence is ``vmin + exp(raw)`` (>= 1 for the official ``('exp', 1, inf)``).
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["HeadOutput", "regress_points", "regress_confidence", "head_output", "LinearHead"]


class HeadOutput(NamedTuple):
    points: torch.Tensor  # [B, H, W, 3]
    confidence: torch.Tensor | None  # [B, H, W], None when the model has no confidence channel


def regress_points(raw: torch.Tensor, mode: tuple[str, float, float]) -> torch.Tensor:
    """``raw [..., 3]`` -> points ``[..., 3]`` (unbounded modes only, as upstream)."""
    kind = mode[0]
    if kind == "linear":
        return raw
    norm = raw.norm(dim=-1, keepdim=True)
    direction = raw / norm.clip(min=1e-8)
    if kind == "square":
        return direction * norm.square()
    if kind == "exp":
        return direction * torch.expm1(norm)
    raise ValueError(f"unknown depth mode {kind!r}")


def regress_confidence(raw: torch.Tensor, mode: tuple[str, float, float]) -> torch.Tensor:
    """``raw [...]`` -> confidence ``[...]`` in ``[vmin, vmax]``."""
    kind, low, high = mode
    if kind == "exp":
        return low + raw.exp().clip(max=high - low)
    if kind == "sigmoid":
        return (high - low) * torch.sigmoid(raw) + low
    raise ValueError(f"unknown confidence mode {kind!r}")


def head_output(channels: torch.Tensor, depth_mode, conf_mode) -> HeadOutput:
    """``channels [B, 3 (+1), H, W]`` -> :class:`HeadOutput`."""
    fmap = channels.permute(0, 2, 3, 1)  # [B, H, W, C]
    points = regress_points(fmap[..., :3], depth_mode)
    confidence = regress_confidence(fmap[..., 3], conf_mode) if conf_mode is not None else None
    return HeadOutput(points, confidence)


class LinearHead(nn.Module):
    """Each final decoder token predicts its ``patch x patch`` pixels' raw channels with one linear map."""

    def __init__(self, dec_embed_dim: int, patch_size: int, depth_mode, conf_mode) -> None:
        super().__init__()
        self.patch_size = patch_size
        self.depth_mode = depth_mode
        self.conf_mode = conf_mode
        self.channels = 3 + (conf_mode is not None)
        self.proj = nn.Linear(dec_embed_dim, self.channels * patch_size ** 2)

    def forward(self, layers: Sequence[torch.Tensor], image_size: tuple[int, int]) -> HeadOutput:
        """``layers``: encoder output then every decoder layer's tokens ``[B, N, C]``; only the last is used."""
        height, width = image_size
        tokens = layers[-1]
        batch = tokens.shape[0]
        features = self.proj(tokens).transpose(-1, -2)  # [B, channels * p^2, N]
        features = features.reshape(batch, -1, height // self.patch_size, width // self.patch_size)
        return head_output(F.pixel_shuffle(features, self.patch_size), self.depth_mode, self.conf_mode)
