"""The DUSt3R network: a shared ViT encoder, two cross-attending decoders and two heads.

Given images ``I1`` and ``I2``, the encoder turns each into patch tokens independently; decoder 1
refines ``I1``'s tokens while attending to ``I2``'s, decoder 2 the other way round (block ``k`` of
each reads both sides' block ``k - 1`` outputs); head 1 predicts ``I1``'s points in ``I1``'s camera
frame (``X^{1,1}``), head 2 predicts ``I2``'s points *in the same frame* (``X^{2,1}``), each with a
confidence. The encoder is separate from the decoder here (:meth:`Dust3rNet.encode`,
:meth:`Dust3rNet.decode`) so a view is encoded once however many pairs it is in.

Parameter names are those of the official checkpoints (``enc_blocks``, ``dec_blocks2``,
``downstream_head1``...), see :mod:`.checkpoint`.
"""
from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from .blocks import LAYER_NORM_EPS, DecoderBlock, EncoderBlock, PatchEmbed
from .config import Dust3rArchitecture
from .dpt import DPTHead
from .heads import HeadOutput, LinearHead
from .rope import RoPE2D

__all__ = ["Dust3rNet", "Encoded", "PairPrediction"]


class Encoded(NamedTuple):
    """Encoder output of a batch of same-sized images."""

    tokens: torch.Tensor  # [B, N, enc_embed_dim], after the final LayerNorm
    positions: torch.Tensor  # [B, N, 2] int64 (y, x) patch positions
    image_size: tuple[int, int]  # (H, W) of the images


class PairPrediction(NamedTuple):
    """Both views' pointmaps in view 1's camera frame."""

    points1: torch.Tensor  # [B, H1, W1, 3]  X^{1,1}
    confidence1: torch.Tensor  # [B, H1, W1] (ones when the model has no confidence)
    points2: torch.Tensor  # [B, H2, W2, 3]  X^{2,1}
    confidence2: torch.Tensor  # [B, H2, W2]


def _head(arch: Dust3rArchitecture) -> nn.Module:
    if arch.head_type == "dpt":
        return DPTHead(arch.enc_embed_dim, arch.dec_embed_dim, arch.dec_depth, arch.patch_size, arch.depth_mode,
                       arch.conf_mode)
    return LinearHead(arch.dec_embed_dim, arch.patch_size, arch.depth_mode, arch.conf_mode)


class Dust3rNet(nn.Module):
    """DUSt3R (``AsymmetricCroCo3DStereo``) for inference; build it from a :class:`Dust3rArchitecture`."""

    def __init__(self, architecture: Dust3rArchitecture) -> None:
        super().__init__()
        arch = self.architecture = architecture
        rope = RoPE2D(arch.rope_base)
        self.patch_embed = PatchEmbed(arch.patch_size, arch.enc_embed_dim)
        # CroCo's pretraining mask token: unused by DUSt3R, present in every checkpoint.
        self.mask_token = nn.Parameter(torch.zeros(1, 1, arch.dec_embed_dim))
        self.enc_blocks = nn.ModuleList([EncoderBlock(arch.enc_embed_dim, arch.enc_num_heads, arch.mlp_ratio, rope)
                                         for _ in range(arch.enc_depth)])
        self.enc_norm = nn.LayerNorm(arch.enc_embed_dim, eps=LAYER_NORM_EPS)
        self.decoder_embed = nn.Linear(arch.enc_embed_dim, arch.dec_embed_dim)

        def decoder() -> nn.ModuleList:
            return nn.ModuleList([DecoderBlock(arch.dec_embed_dim, arch.dec_num_heads, arch.mlp_ratio, rope,
                                               arch.norm_im2_in_dec) for _ in range(arch.dec_depth)])

        self.dec_blocks = decoder()
        self.dec_blocks2 = decoder()
        self.dec_norm = nn.LayerNorm(arch.dec_embed_dim, eps=LAYER_NORM_EPS)
        self.downstream_head1 = _head(arch)
        self.downstream_head2 = _head(arch)

    @property
    def patch_size(self) -> int:
        return self.architecture.patch_size

    def encode(self, images: torch.Tensor) -> Encoded:
        """``images [B, 3, H, W]`` normalised to [-1, 1], H and W multiples of the patch size."""
        tokens, positions = self.patch_embed(images)
        for block in self.enc_blocks:
            tokens = block(tokens, positions)
        return Encoded(self.enc_norm(tokens), positions, (int(images.shape[2]), int(images.shape[3])))

    def decode(self, view1: Encoded, view2: Encoded) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Both decoders; returns each side's ``[encoder tokens, layer 1, ..., layer D (normalised)]``."""
        x1, x2 = self.decoder_embed(view1.tokens), self.decoder_embed(view2.tokens)
        layers1, layers2 = [view1.tokens], [view2.tokens]
        for block1, block2 in zip(self.dec_blocks, self.dec_blocks2):
            x1, x2 = block1(x1, x2, view1.positions, view2.positions), block2(x2, x1, view2.positions, view1.positions)
            layers1.append(x1)
            layers2.append(x2)
        layers1[-1], layers2[-1] = self.dec_norm(layers1[-1]), self.dec_norm(layers2[-1])
        return layers1, layers2

    def head(self, which: int, layers: list[torch.Tensor], image_size: tuple[int, int]) -> tuple[torch.Tensor, torch.Tensor]:
        """Head 1 or 2 on one side's decoder layers: points ``[B, H, W, 3]`` and confidence ``[B, H, W]``."""
        module = self.downstream_head1 if which == 1 else self.downstream_head2
        dtype = next(module.parameters()).dtype  # heads run in their own precision
        out: HeadOutput = module([t.to(dtype) for t in layers], image_size)
        confidence = out.confidence if out.confidence is not None else torch.ones_like(out.points[..., 0])
        return out.points, confidence

    def predict(self, view1: Encoded, view2: Encoded) -> PairPrediction:
        """Pointmaps of an encoded pair (batches of equal size)."""
        layers1, layers2 = self.decode(view1, view2)
        return PairPrediction(*self.head(1, layers1, view1.image_size), *self.head(2, layers2, view2.image_size))

    def forward(self, images1: torch.Tensor, images2: torch.Tensor) -> PairPrediction:
        """``images1 [B, 3, H1, W1]``, ``images2 [B, 3, H2, W2]`` -> :class:`PairPrediction`."""
        if images1.shape[2:] == images2.shape[2:]:
            both = self.encode(torch.cat((images1, images2)))
            batch = images1.shape[0]
            view1 = Encoded(both.tokens[:batch], both.positions[:batch], both.image_size)
            view2 = Encoded(both.tokens[batch:], both.positions[batch:], both.image_size)
        else:
            view1, view2 = self.encode(images1), self.encode(images2)
        return self.predict(view1, view2)
