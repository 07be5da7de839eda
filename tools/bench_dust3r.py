"""Time and peak memory per image pair of the dust3r backend, for the official architectures.

    python tools/bench_dust3r.py                      # 224 linear, 512 linear, 512 dpt; batch 1 and 2
    python tools/bench_dust3r.py --cases 512_dpt --batches 1 2 4 --device cuda

Each case builds the real network (ViT-Large encoder, ViT-Base decoder, as the official
``DUSt3R_ViTLarge_BaseDecoder_*`` checkpoints) with random weights (timing does not depend on the
values) and runs the backend exactly as ``fs3d fuse`` does on two 1280x1024 grayscale views (the
UWA camera size): ``predict_views`` (each image with itself: 2 passes) then ``predict_pairs``
(the symmetrised pair: 2 passes, encoder outputs reused). Reported per pass ("pair" = one ordered
image pair through decoder and heads, ``seconds_per_pair``) and the peak memory the call added on top
of the loaded weights (RSS on CPU, allocated on CUDA). Prints a Markdown table and the machine.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from fingersplat3d.errors import run_script
from fingersplat3d.eval.machine import machine
from fingersplat3d.pointmaps.dust3r import Dust3rBackend, Dust3rNet, parse_model_description
from fingersplat3d.scene import View  # noqa: E402

LARGE = ("enc_embed_dim=1024, enc_depth=24, enc_num_heads=16, dec_embed_dim=768, dec_depth=12, dec_num_heads=12, "
         "output_mode='pts3d', depth_mode=('exp', -inf, inf), conf_mode=('exp', 1, inf), pos_embed='RoPE100'")
CASES = {
    "224_linear": f"AsymmetricCroCo3DStereo(img_size=(224, 224), head_type='linear', {LARGE})",
    "512_linear": f"AsymmetricCroCo3DStereo(patch_embed_cls='ManyAR_PatchEmbed', img_size=(512, 512), head_type='linear', {LARGE})",
    "512_dpt": f"AsymmetricCroCo3DStereo(patch_embed_cls='ManyAR_PatchEmbed', img_size=(512, 512), head_type='dpt', {LARGE})",
}


def random_network(description: str, device: torch.device) -> Dust3rNet:
    """The architecture with N(0, 0.02) weights and unit norms, allocated directly (no slow init)."""
    with torch.device("meta"):
        model = Dust3rNet(parse_model_description(description))
    model = model.to_empty(device=device)
    generator = torch.Generator(device=device).manual_seed(0)
    with torch.no_grad():
        for name, parameter in model.named_parameters():
            if "norm" in name and parameter.ndim == 1:
                parameter.fill_(1.0 if name.endswith("weight") else 0.0)
            else:
                parameter.normal_(0.0, 0.02, generator=generator)
    return model.eval()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--batches", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--size", default="1280x1024", help="input image size WxH")
    parser.add_argument("--json", type=Path, help="also write the records here")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    rng = np.random.default_rng(0)
    views = [View(f"v{k}", rng.random((height, width)).astype(np.float32)) for k in range(2)]
    device = torch.device(args.device)
    info = machine()
    print(f"machine: {info['cpu']}, {info['cores']} cores, load {tuple(round(x, 2) for x in info['load'])}, "
          f"torch {info['torch']} ({torch.get_num_threads()} threads), device {device}")
    records = []
    print("| model | network input | batch | s / pair (views) | s / pair (pairs) | peak MB (views) | peak MB (pairs) |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for case in args.cases:
        started = time.perf_counter()
        model = random_network(CASES[case], device)
        build = time.perf_counter() - started
        parameters = sum(p.numel() for p in model.parameters())
        for batch in args.batches:
            backend = Dust3rBackend(model=model, device=str(device), batch_size=batch)
            backend.predict_views(views)
            backend.predict_pairs(views)
            mono, pair = backend.stats
            record = {"case": case, "parameters": parameters, "build_s": round(build, 1), "batch": batch,
                      "views": mono.__dict__, "pairs": pair.__dict__}
            records.append(record)
            w, h = mono.network_size
            print(f"| {case} | {w}x{h} | {batch} | {mono.seconds_per_pair:.2f} | {pair.seconds_per_pair:.2f} | "
                  f"{mono.peak_memory_mb:.0f} | {pair.peak_memory_mb:.0f} |", flush=True)
        del model, backend
    if args.json:
        args.json.write_text(json.dumps({"machine": info, "records": records}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(run_script(main))
