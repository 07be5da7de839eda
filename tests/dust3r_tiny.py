"""Tiny random DUSt3R networks (same architecture, small widths) for the dust3r tests."""
from __future__ import annotations

from pathlib import Path

import torch

from fingersplat3d.pointmaps.dust3r import Dust3rArchitecture, Dust3rNet, save_checkpoint

TINY = dict(img_size=(64, 64), enc_embed_dim=32, enc_depth=2, enc_num_heads=2, dec_embed_dim=16, dec_depth=2,
            dec_num_heads=2)


def tiny_architecture(head_type: str = "linear", **changes) -> Dust3rArchitecture:
    options = {**TINY, "head_type": head_type, **changes}
    if head_type == "dpt":
        options.setdefault("dec_depth", 10)
        options["dec_depth"] = max(options["dec_depth"], 10)  # upstream's DPT needs >= 10 decoder blocks
    return Dust3rArchitecture(**options)


def tiny_model(head_type: str = "linear", seed: int = 0, **changes) -> Dust3rNet:
    """Random weights; the linear head's z bias puts the points in front of the camera (z ~ e^2)."""
    torch.manual_seed(seed)
    model = Dust3rNet(tiny_architecture(head_type, **changes)).eval()
    if head_type == "linear":
        pixels = model.patch_size ** 2
        with torch.no_grad():
            for head in (model.downstream_head1, model.downstream_head2):
                head.proj.bias[2 * pixels:3 * pixels] += 2.0  # channel-major: [x, y, z, conf] x p^2
    return model


def tiny_checkpoint(folder: Path, head_type: str = "linear", seed: int = 0, **changes) -> Path:
    return save_checkpoint(tiny_model(head_type, seed, **changes), Path(folder) / f"tiny_{head_type}_{seed}.pth")
