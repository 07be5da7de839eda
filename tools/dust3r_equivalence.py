"""Check fingersplat3d's DUSt3R against the upstream implementation, on the same random weights.

    python tools/dust3r_equivalence.py --upstream PATH/TO/dust3r   # a checkout with croco/ inside

For each architecture (linear and DPT heads, a 224 model and a 512 model fed non-square
landscape and portrait inputs), the script builds upstream's ``AsymmetricCroCo3DStereo`` from its
description string, fills every parameter with random values, saves the state dict in the
official checkpoint layout (``{"model": state_dict, "args": Namespace(model=...)}``), loads that
file back with upstream's ``load_model`` and with ours (``strict=True``), runs both on the same
symmetrised batch of image pairs and prints the largest absolute and relative differences of the
pointmaps and confidences. It also compares the preprocessing (upstream ``load_images`` against
:func:`prepare_image`) on PNG files. Exits 1 when any difference exceeds the tolerance.

Upstream needs ``einops`` and ``huggingface_hub`` (and ``torchvision`` for ``load_images``); where
one is missing, a minimal stand-in is inserted for the parts inference does not use
(``huggingface_hub``'s mixin), or for trivial ones (``torchvision``'s ToTensor/Normalize, ``einops.rearrange``
of the one pattern the DPT head uses), and the script says so. Nothing is installed or downloaded.
"""
from __future__ import annotations

import argparse
import io
import math
import sys
import tempfile
import types
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import torch

from fingersplat3d.errors import run_script
from fingersplat3d.pointmaps.dust3r import load_model, prepare_image

TINY = "enc_embed_dim=64, enc_depth=3, enc_num_heads=4, dec_embed_dim=48, dec_depth=10, dec_num_heads=3"
CASES = [
    # (label, description, [(H, W) of the inputs])
    ("224 linear", f"AsymmetricCroCo3DStereo(pos_embed='RoPE100', img_size=(224, 224), head_type='linear', "
                   f"output_mode='pts3d', depth_mode=('exp', -inf, inf), conf_mode=('exp', 1, inf), {TINY})",
     [(224, 224)]),
    ("512 linear", f"AsymmetricCroCo3DStereo(pos_embed='RoPE100', patch_embed_cls='ManyAR_PatchEmbed', "
                   f"img_size=(512, 512), head_type='linear', output_mode='pts3d', depth_mode=('exp', -inf, inf), "
                   f"conf_mode=('exp', 1, inf), {TINY})", [(384, 512), (512, 400)]),
    ("512 dpt", f"AsymmetricCroCo3DStereo(pos_embed='RoPE100', patch_embed_cls='ManyAR_PatchEmbed', "
                f"img_size=(512, 512), head_type='dpt', output_mode='pts3d', depth_mode=('exp', -inf, inf), "
                f"conf_mode=('exp', 1, inf), {TINY})", [(384, 512), (512, 400)]),
    ("224 dpt", f"AsymmetricCroCo3DStereo(pos_embed='RoPE100', img_size=(224, 224), head_type='dpt', "
                f"output_mode='pts3d', depth_mode=('exp', -inf, inf), conf_mode=('exp', 1, inf), {TINY})",
     [(224, 224)]),
]


def _stand_ins() -> list[str]:
    """Insert minimal modules for missing upstream dependencies; returns what was stood in for."""
    notes = []
    try:
        import huggingface_hub  # noqa: F401
    except ImportError:
        hub = types.ModuleType("huggingface_hub")
        hub.__version__ = "0.22.0"

        class PyTorchModelHubMixin:  # only the base class is needed for inference
            def __init_subclass__(cls, **kwargs):
                super().__init_subclass__()

        hub.PyTorchModelHubMixin = PyTorchModelHubMixin
        sys.modules["huggingface_hub"] = hub
        notes.append("huggingface_hub (hub mixin, unused by inference)")
    try:
        import einops  # noqa: F401
    except ImportError:
        einops = types.ModuleType("einops")

        def rearrange(tensor, pattern, **sizes):
            if pattern.replace(" ", "") != "b(nhnw)c->bcnhnw":
                raise NotImplementedError(pattern)
            return tensor.transpose(1, 2).reshape(tensor.shape[0], tensor.shape[2], sizes["nh"], sizes["nw"])

        einops.rearrange = rearrange
        einops.repeat = None
        sys.modules["einops"] = einops
        notes.append("einops (rearrange 'b (nh nw) c -> b c nh nw' only)")
    try:
        import torchvision.transforms  # noqa: F401
    except ImportError:
        vision = types.ModuleType("torchvision")
        transforms = types.ModuleType("torchvision.transforms")

        class Compose:
            def __init__(self, steps):
                self.steps = steps

            def __call__(self, x):
                for step in self.steps:
                    x = step(x)
                return x

        class ToTensor:  # PIL RGB image -> [3, H, W] float in [0, 1]
            def __call__(self, image):
                return torch.from_numpy(np.asarray(image, np.float32) / 255.0).permute(2, 0, 1).contiguous()

        class Normalize:
            def __init__(self, mean, std):
                self.mean, self.std = torch.tensor(mean)[:, None, None], torch.tensor(std)[:, None, None]

            def __call__(self, x):
                return (x - self.mean) / self.std

        transforms.Compose, transforms.ToTensor, transforms.Normalize = Compose, ToTensor, Normalize
        vision.transforms = transforms
        sys.modules["torchvision"], sys.modules["torchvision.transforms"] = vision, transforms
        notes.append("torchvision (ToTensor, Normalize)")
    return notes


def _randomise(model: torch.nn.Module, generator: torch.Generator) -> None:
    """Every parameter random (upstream's init zeroes the biases, which would hide mistakes)."""
    with torch.no_grad():
        for name, parameter in model.named_parameters():
            noise = torch.randn(parameter.shape, generator=generator)
            if parameter.ndim == 1 and ("norm" in name):
                parameter.copy_((1.0 if name.endswith("weight") else 0.0) + 0.1 * noise)
            elif parameter.ndim == 1:
                parameter.copy_(0.05 * noise)
            else:
                fan_in = parameter[0].numel() if parameter.ndim > 1 else 1
                if "ConvTranspose" in type(_owner(model, name)).__name__:
                    fan_in = parameter.shape[0] * parameter[0, 0].numel()
                parameter.copy_(noise / math.sqrt(fan_in))


def _owner(model: torch.nn.Module, name: str) -> torch.nn.Module:
    return model.get_submodule(name.rsplit(".", 1)[0]) if "." in name else model


def _differences(ours: torch.Tensor, reference: torch.Tensor) -> tuple[float, float]:
    """Largest absolute difference, and largest difference relative to the reference's magnitude."""
    diff = (ours.double() - reference.double()).abs()
    scale = reference.double().abs().clamp_min(1e-3 * float(reference.double().abs().max()) + 1e-12)
    return float(diff.max()), float((diff / scale).max())


def compare_networks(upstream_load, case, generator, tolerance: float, tolerance_64: float) -> bool:
    label, description, shapes = case
    import dust3r.model as upstream_model

    net = eval(description, vars(upstream_model))  # upstream's own way of building it (trusted: our string)
    _randomise(net, generator)
    ok = True
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "random.pth"
        torch.save({"model": net.state_dict(), "args": argparse.Namespace(model=description)}, path)
        log = io.StringIO()
        # Upstream calls torch.load with torch's default, weights_only=True since torch 2.6, which refuses
        # the Namespace of official checkpoints; allow that one class, as fingersplat3d does.
        with redirect_stdout(log), torch.serialization.safe_globals([argparse.Namespace]):
            reference_net = upstream_load(str(path), "cpu").eval()
        if "<All keys matched successfully>" not in log.getvalue():
            print(f"  {label}: upstream load_model did not match all keys:\n{log.getvalue()}")
            ok = False
        ours = load_model(path, "cpu")  # strict: raises on any key or shape mismatch
    for height, width in shapes:
        images = torch.rand((2, 3, height, width), generator=generator) * 2 - 1
        for precision, limit in (("float32", tolerance), ("float64", tolerance_64)):
            theirs = _upstream_outputs(reference_net, images, precision)
            mine = _our_outputs(ours, images, precision)
            for name, a, b in zip(("pts3d 1", "conf 1", "pts3d 2", "conf 2"), mine, theirs):
                if a.shape != b.shape:
                    print(f"  {label} {width}x{height} {name}: shape {tuple(a.shape)} vs upstream {tuple(b.shape)}")
                    ok = False
                    continue
                absolute, relative = _differences(a, b)
                ok &= relative <= limit
                print(f"  {label:10s} {width}x{height} {precision} {name:8s} max |ref| {float(b.abs().max()):9.3g}  "
                      f"max abs diff {absolute:9.2e}  max rel diff {relative:9.2e}  {'ok' if relative <= limit else 'MISMATCH'}")
    return ok


def _upstream_outputs(net, images: torch.Tensor, precision: str) -> list[torch.Tensor]:
    """Upstream on a symmetrised batch ``(I1, I2), (I2, I1)``: its ``forward`` in float32; in float64 the
    same steps through its own methods (its forward casts the decoder tokens to float32)."""
    height, width = images.shape[2:]
    shape = torch.tensor([[height, width]] * 2)
    view1 = {"img": images, "true_shape": shape, "instance": ["a", "b"]}
    view2 = {"img": images.flip(0), "true_shape": shape, "instance": ["b", "a"]}
    with torch.no_grad():
        if precision == "float32":
            res1, res2 = net.float()(view1, view2)
        else:
            net = net.double()
            view1["img"], view2["img"] = view1["img"].double(), view2["img"].double()
            (shape1, shape2), (feat1, feat2), (pos1, pos2) = net._encode_symmetrized(view1, view2)
            dec1, dec2 = net._decoder(feat1, pos1, feat2, pos2)
            res1 = net._downstream_head(1, list(dec1), shape1)
            res2 = net._downstream_head(2, list(dec2), shape2)
            res2["pts3d_in_other_view"] = res2.pop("pts3d")
            net.float()
    return [res1["pts3d"], res1["conf"], res2["pts3d_in_other_view"], res2["conf"]]


def _our_outputs(model, images: torch.Tensor, precision: str) -> list[torch.Tensor]:
    dtype = torch.float32 if precision == "float32" else torch.float64
    with torch.no_grad():
        model = model.to(dtype)
        prediction = model(images.to(dtype), images.flip(0).to(dtype))
        model.float()
    return list(prediction)


def compare_preprocessing(upstream_images) -> bool:
    """Upstream ``load_images`` (PIL, 8-bit) against :func:`prepare_image` (float) on PNG files."""
    import PIL.Image

    ok = True
    rng = np.random.default_rng(1)
    with tempfile.TemporaryDirectory() as folder:
        for width, height in ((1280, 1024), (1024, 1280), (600, 600), (300, 170)):
            y, x = np.mgrid[:height, :width]
            image = 0.5 + 0.4 * np.sin(x / 9.0 + 3 * np.sin(y / 23.0))[..., None] * np.array([1.0, 0.8, 0.6])
            image = np.clip(image + 0.05 * rng.standard_normal(image.shape), 0, 1)
            pixels = np.round(image * 255).astype(np.uint8)
            path = Path(folder) / f"im_{width}x{height}.png"
            PIL.Image.fromarray(pixels).save(path)
            for size in (224, 512):
                with redirect_stdout(io.StringIO()):
                    reference = upstream_images([str(path)], size=size, verbose=False)[0]["img"][0]
                ours = prepare_image(pixels.astype(np.float32) / 255.0, size).tensor
                if ours.shape != reference.shape:
                    print(f"  preprocessing {width}x{height} -> {size}: shape {tuple(ours.shape)} vs {tuple(reference.shape)}")
                    ok = False
                    continue
                diff = (ours - reference).abs() * 127.5  # in 8-bit levels
                good = float(diff.max()) <= 2.5  # PIL rounds each pass to 8 bits; ours stays in float
                ok &= good
                print(f"  preprocessing {width}x{height} -> {size}: {tuple(ours.shape[1:])} max diff "
                      f"{float(diff.max()):.2f} levels, mean {float(diff.mean()):.3f}  {'ok' if good else 'MISMATCH'}")
    return ok


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--upstream", type=Path, required=True, help="dust3r checkout (with its croco submodule)")
    parser.add_argument("--tolerance", type=float, default=1e-3,
                        help="largest accepted relative difference in float32 (default 1e-3: the exp depth mode turns "
                             "float32 rounding of the raw point norm, ~1e-5 per unit, into relative error, and these "
                             "random weights reach raw norms ~10)")
    parser.add_argument("--tolerance-64", type=float, default=1e-9, help="the same in float64")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    args = parser.parse_args()
    if not (args.upstream / "dust3r" / "model.py").is_file() or not (args.upstream / "croco" / "models").is_dir():
        print(f"{args.upstream}: not a dust3r checkout with its croco submodule", file=sys.stderr)
        return 2
    if args.threads:
        torch.set_num_threads(args.threads)
    notes = _stand_ins()
    sys.path.insert(0, str(args.upstream))
    with redirect_stdout(io.StringIO()):
        from dust3r.model import load_model as upstream_load
        from dust3r.utils.image import load_images as upstream_images
    if notes:
        print("stand-ins for missing upstream dependencies: " + "; ".join(notes))
    generator = torch.Generator().manual_seed(args.seed)
    ok = compare_preprocessing(upstream_images)
    for case in CASES:
        ok &= compare_networks(upstream_load, case, generator, args.tolerance, args.tolerance_64)
    print("EQUIVALENT" if ok else "NOT EQUIVALENT")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(run_script(main))
