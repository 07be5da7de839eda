"""The DPT head (Ranftl et al. 2021) as DUSt3R configures it: four token layers fused into a dense map.

The head hooks four of the layer outputs (the encoder's and decoder layers ``D/2, 3D/4, D`` for
``D`` decoder blocks), reassembles each into an image at 4x, 2x, 1x and 1/2x the patch grid,
projects them to 256 features and fuses them coarse-to-fine with residual convolution units,
each fusion step doubling the resolution; a small convolutional output stage doubles it once more
to the input size. Attribute names (``dpt.scratch.refinenet1.resConfUnit1``, ``dpt.act_postprocess``,
the aliased ``scratch.layer1_rn`` / ``scratch.layer_rn.0``) follow the official state dict.
"""
from __future__ import annotations

from typing import Sequence

import torch
import torch.nn.functional as F
from torch import nn

from .heads import HeadOutput, head_output

__all__ = ["DPTHead", "DPT_FEATURES", "DPT_LAYER_DIMS", "dpt_hooks"]

DPT_FEATURES = 256  # fused feature width
DPT_LAST_DIM = DPT_FEATURES // 2  # width of the output stage
DPT_LAYER_DIMS = (96, 192, 384, 768)  # reassembled widths at 4x, 2x, 1x, 1/2x the patch grid


def dpt_hooks(dec_depth: int) -> tuple[int, int, int, int]:
    """Indices into ``[encoder output, decoder layer 1, ..., decoder layer D]`` that the head reads."""
    return (0, dec_depth * 2 // 4, dec_depth * 3 // 4, dec_depth)


class ResidualConvUnit(nn.Module):
    """``x + conv(relu(conv(relu(x))))`` (3x3 convolutions with bias)."""

    def __init__(self, features: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(features, features, 3, padding=1)
        self.conv2 = nn.Conv2d(features, features, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv2(F.relu(self.conv1(F.relu(x))))


class FusionBlock(nn.Module):
    """Add the (refined) skip input, refine, upsample 2x (bilinear, corners aligned), 1x1 projection."""

    def __init__(self, features: int) -> None:
        super().__init__()
        self.out_conv = nn.Conv2d(features, features, 1)
        self.resConfUnit1 = ResidualConvUnit(features)  # refines the skip input (unused by the coarsest block)
        self.resConfUnit2 = ResidualConvUnit(features)

    def forward(self, x: torch.Tensor, skip: torch.Tensor | None = None) -> torch.Tensor:
        if skip is not None:
            x = x + self.resConfUnit1(skip)
        x = self.resConfUnit2(x)
        x = F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=True)
        return self.out_conv(x)


class _Scratch(nn.Module):
    """Per-layer 3x3 projections to the fused width and the four fusion blocks."""

    def __init__(self, features: int) -> None:
        super().__init__()
        for index, width in enumerate(DPT_LAYER_DIMS, start=1):
            setattr(self, f"layer{index}_rn", nn.Conv2d(width, features, 3, padding=1, bias=False))
        # The same four convolutions again under a list: the official state dict holds both names.
        self.layer_rn = nn.ModuleList([self.layer1_rn, self.layer2_rn, self.layer3_rn, self.layer4_rn])
        for index in range(1, 5):
            setattr(self, f"refinenet{index}", FusionBlock(features))


class _Upsample2x(nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=True)


class _DPT(nn.Module):
    def __init__(self, token_dims: Sequence[int], out_channels: int, patch_size: int) -> None:
        super().__init__()
        self.patch_size = patch_size
        a, b, c, d = DPT_LAYER_DIMS
        self.scratch = _Scratch(DPT_FEATURES)
        self.head = nn.Sequential(
            nn.Conv2d(DPT_FEATURES, DPT_FEATURES // 2, 3, padding=1),
            _Upsample2x(),
            nn.Conv2d(DPT_FEATURES // 2, DPT_LAST_DIM, 3, padding=1),
            nn.ReLU(),
            nn.Conv2d(DPT_LAST_DIM, out_channels, 1),
        )
        self.act_postprocess = nn.ModuleList([
            nn.Sequential(nn.Conv2d(token_dims[0], a, 1), nn.ConvTranspose2d(a, a, 4, stride=4)),  # 4x
            nn.Sequential(nn.Conv2d(token_dims[1], b, 1), nn.ConvTranspose2d(b, b, 2, stride=2)),  # 2x
            nn.Sequential(nn.Conv2d(token_dims[2], c, 1)),  # 1x
            nn.Sequential(nn.Conv2d(token_dims[3], d, 1), nn.Conv2d(d, d, 3, stride=2, padding=1)),  # 1/2x
        ])

    def forward(self, layers: Sequence[torch.Tensor], image_size: tuple[int, int]) -> torch.Tensor:
        """Four token layers ``[B, N, C_k]`` -> raw channels ``[B, out, H, W]``."""
        rows, cols = image_size[0] // self.patch_size, image_size[1] // self.patch_size
        maps = []
        for index, tokens in enumerate(layers):
            grid = tokens.transpose(1, 2).reshape(tokens.shape[0], tokens.shape[2], rows, cols)  # [B, C, h, w]
            maps.append(self.scratch.layer_rn[index](self.act_postprocess[index](grid)))
        coarse = self.scratch.refinenet4(maps[3])[:, :, :maps[2].shape[2], :maps[2].shape[3]]  # odd grids round up
        fused = self.scratch.refinenet3(coarse, maps[2])
        fused = self.scratch.refinenet2(fused, maps[1])
        fused = self.scratch.refinenet1(fused, maps[0])
        return self.head(fused)


class DPTHead(nn.Module):
    """DPT head of one view: hooks four layers, outputs points (+ confidence) at the input resolution."""

    def __init__(self, enc_embed_dim: int, dec_embed_dim: int, dec_depth: int, patch_size: int,
                 depth_mode, conf_mode) -> None:
        super().__init__()
        self.hooks = dpt_hooks(dec_depth)
        self.depth_mode = depth_mode
        self.conf_mode = conf_mode
        self.dpt = _DPT((enc_embed_dim, dec_embed_dim, dec_embed_dim, dec_embed_dim), 3 + (conf_mode is not None),
                        patch_size)

    def forward(self, layers: Sequence[torch.Tensor], image_size: tuple[int, int]) -> HeadOutput:
        return head_output(self.dpt([layers[k] for k in self.hooks], image_size), self.depth_mode, self.conf_mode)
