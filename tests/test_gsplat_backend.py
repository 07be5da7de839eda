"""gsplat's CUDA kernels behind rasterize(): chosen only where they can render, and equal to the reference
within gsplat's documented differences (alpha cap 0.999, early termination at 1e-4). The comparisons need a
CUDA device with gsplat installed and are skipped elsewhere; the choice of backend is checked everywhere."""
import pytest
import torch

from fingersplat3d.splat import rasterize, reference_rasterize
from fingersplat3d.splat import gsplat_backend
from fingersplat3d.splat.rasterize import resolve_backend

from test_rasterize import random_scene, weighted_loss

needs_gsplat = pytest.mark.skipif(not (torch.cuda.is_available() and gsplat_backend.installed()),
                                  reason="needs a CUDA device and gsplat")


def test_auto_never_picks_gsplat_on_the_cpu_and_gsplat_refuses_cpu_tensors():
    args, width, height = random_scene(0, dtype=torch.float32)
    means, K = args[0], args[6]
    assert resolve_backend("auto", means.device, means, K) == "numba"
    with pytest.raises(ValueError, match="gsplat runs on CUDA"):
        rasterize(*args, width, height, backend="gsplat")


def test_reasons_gsplat_cannot_render():
    means = torch.zeros(3, 3)
    K = torch.eye(3)
    assert "CUDA" in gsplat_backend.why_not_usable(means, K)
    if torch.cuda.is_available():
        assert "float32" in gsplat_backend.why_not_usable(means.double().cuda(), K.cuda())
        assert "gradient to K" in gsplat_backend.why_not_usable(means.cuda(), K.cuda().requires_grad_())


def test_gsplat_is_handed_the_references_quaternions_and_shifted_pixel_centres(monkeypatch):
    """What rasterize_gsplat passes to gsplat's projection (a stand-in module records it, so no GPU is needed):
    (near-)zero quaternions as the identity, the rest unit, and K's principal point half a pixel on."""
    import sys
    import types

    seen = {}

    class Stop(Exception):
        pass

    def projection(means, covars, quats, scales, viewmats, Ks, *args, **kwargs):
        seen.update(quats=quats, K=Ks[0])
        raise Stop

    fake = types.ModuleType("gsplat.cuda._wrapper")
    fake.fully_fused_projection = projection
    fake.isect_offset_encode = fake.isect_tiles = fake.rasterize_to_pixels = None
    monkeypatch.setitem(sys.modules, "gsplat", types.ModuleType("gsplat"))
    monkeypatch.setitem(sys.modules, "gsplat.cuda", types.ModuleType("gsplat.cuda"))
    monkeypatch.setitem(sys.modules, "gsplat.cuda._wrapper", fake)
    quats = torch.tensor([[0.0, 0.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0]])
    K = torch.tensor([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])
    with pytest.raises(Stop):
        gsplat_backend.rasterize_gsplat(torch.zeros(2, 3), quats, torch.ones(2, 3), torch.ones(2), torch.ones(2, 1),
                                        torch.eye(4), K, 64, 48, 0.01, 0.3)
    assert seen["quats"].tolist() == [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]]
    assert seen["K"][0, 2] == 32.0 and seen["K"][1, 2] == 24.0 and K[0, 2] == 31.5  # the caller's K is left alone


def _cuda_scene(seed, channels=3, n=80, width=64, height=48):
    """Gaussians inside the view, as in a fit. Off to the side, gsplat (as 3DGS) clamps the projection's
    Jacobian at 1.3 times the field of view, which the reference does not; and opacities stay below 0.98,
    so that gsplat's alpha cap (0.999) and the reference's (0.99) are not what is compared."""
    g = torch.Generator().manual_seed(seed)
    dtype = torch.float64
    means = (torch.rand(n, 3, generator=g, dtype=dtype) - 0.5) * torch.tensor([1.2, 0.9, 1.0], dtype=dtype)
    means[:, 2] += 3.0
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=dtype) * 0.4 - 3.0)
    opacities = torch.rand(n, generator=g, dtype=dtype) * 0.9 + 0.05
    colors = torch.rand(n, channels, generator=g, dtype=dtype)
    world_to_cam = torch.eye(4, dtype=dtype)
    world_to_cam[:3, 3] = torch.tensor([0.02, -0.03, 0.1], dtype=dtype)
    K = torch.tensor([[120.0, 0, (width - 1) / 2 + 0.3], [0, 118.0, (height - 1) / 2 - 0.2], [0, 0, 1]], dtype=dtype)
    return [means, quats, scales, opacities, colors, world_to_cam, K], width, height


@needs_gsplat
@pytest.mark.parametrize("seed,channels", [(0, 3), (1, 1), (3, 2)])
def test_gsplat_matches_the_reference_outputs_and_gradients(seed, channels):
    # Opacities below 0.98 keep gsplat's 0.999 cap and the reference's 0.99 apart from the comparison.
    args, width, height = _cuda_scene(seed, channels)
    ref = reference_rasterize(*[t.clone().requires_grad_() for t in args], width, height)
    leaves = [t.float().cuda().requires_grad_() for t in args[:6]] + [args[6].float().cuda()]
    out = rasterize(*leaves, width, height, backend="gsplat")
    assert resolve_backend("auto", leaves[0].device, leaves[0], leaves[6]) == "gsplat"
    for name in ("color", "alpha", "depth"):
        torch.testing.assert_close(getattr(out, name).double().cpu(), getattr(ref, name), atol=2e-3, rtol=1e-3,
                                   msg=name)
    seen = (ref.radii > 0) & (out.radii.cpu() > 0)
    assert seen.sum() >= 0.9 * len(seen)  # gsplat culls by its x/y radii, the reference by the alpha box
    torch.testing.assert_close(out.means2d.double().cpu()[seen], ref.means2d[seen], atol=1e-3, rtol=0)
    ref_leaves = [t.clone().requires_grad_() for t in args[:6]] + [args[6]]
    ref = reference_rasterize(*ref_leaves, width, height)
    grads_ref = torch.autograd.grad(weighted_loss(ref), ref_leaves[:6])
    out = rasterize(*leaves, width, height, backend="gsplat")
    weights = torch.Generator().manual_seed(123)
    loss = sum((t * torch.randn(t.shape, generator=weights, dtype=torch.float64).float().cuda()).sum()
               for t in (out.color, out.alpha, out.depth))
    grads = torch.autograd.grad(loss, leaves[:6])
    for name, a, b in zip(["means", "quats", "scales", "opacities", "colors", "world_to_cam"], grads, grads_ref):
        scale = b.abs().max().item()
        assert scale > 0, name
        torch.testing.assert_close(a.double().cpu(), b, atol=3e-3 * scale, rtol=1e-2, msg=name)


@needs_gsplat
def test_gsplat_keeps_means2d_in_the_graph_and_stays_finite_at_extremes():
    args, width, height = _cuda_scene(4)
    leaves = [t.float().cuda().requires_grad_() for t in args[:5]] + [args[5].float().cuda(), args[6].float().cuda()]
    leaves[1].data[:5] = 0.0  # zero quaternions
    leaves[2].data[5:10] = 1e-8  # vanishing scales
    leaves[3].data[10:15] = 1.0  # opaque
    out = rasterize(*leaves, width, height)
    out.means2d.retain_grad()
    (out.color.sum() + out.depth.sum()).backward()
    assert out.means2d.grad is not None and out.means2d.grad.abs().sum() > 0
    for t in [out.color, out.alpha, out.depth] + [leaf.grad for leaf in leaves[:5]]:
        assert torch.isfinite(t).all()
