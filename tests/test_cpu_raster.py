"""The compiled CPU rasterizer (numba): early termination, binning, threads, projection twin."""
import math

import numpy as np
import pytest
import torch

from fingersplat3d.splat import rasterize
from fingersplat3d.splat.cpu_raster import depth_order, project_cpu
from fingersplat3d.splat.project import _project
from fingersplat3d.splat.rasterize import MIN_TRANSMITTANCE

from test_rasterize import random_scene, weighted_loss

F64 = torch.float64


def opaque_stack(n=40, seed=0, dtype=F64):
    """Many nearly opaque, wide Gaussians stacked in front of a 32x24 camera: transmittance
    reaches 1e-4 after a few of them at every covered pixel."""
    args, width, height = random_scene(seed, n=n, channels=2, dtype=dtype, width=32, height=24)
    args[0][:, :2] *= 0.3
    args[0][:, 2] = torch.linspace(2.0, 4.0, n, dtype=dtype)
    args[2][:] = 0.4
    args[3][:] = 0.98
    return args, width, height


def test_early_termination_leaves_out_less_than_the_threshold():
    args, width, height = opaque_stack()
    exact = rasterize(*args, width, height, backend="numba", min_transmittance=0.0)
    early = rasterize(*args, width, height, backend="numba")
    assert (1.0 - exact.alpha).min() < 1e-8  # deep stacks: termination really happens
    weight_left_out = (early.alpha - exact.alpha).abs()
    assert weight_left_out.max() > 0 and weight_left_out.max() <= MIN_TRANSMITTANCE
    feature_bound = MIN_TRANSMITTANCE * args[4].abs().max()
    assert (early.color - exact.color).abs().max() <= feature_bound + 1e-12
    # The backward of the truncated sum is the exact backward of what was composited: gradients
    # agree with the exact ones up to what the left-out Gaussians would have contributed.
    leaves = [t.clone().requires_grad_() for t in args]
    grads_early = torch.autograd.grad(weighted_loss(rasterize(*leaves, width, height, backend="numba")), leaves[:5])
    grads_exact = torch.autograd.grad(
        weighted_loss(rasterize(*leaves, width, height, backend="numba", min_transmittance=0.0)), leaves[:5])
    for a, b in zip(grads_early, grads_exact):
        assert torch.isfinite(a).all()
        assert (a - b).abs().max() <= 1e-2 * b.abs().max() + 1e-12  # + rounding where the gradient is ~0


def test_exact_mode_matches_the_torch_backend_on_the_stack():
    args, width, height = opaque_stack(seed=1)
    leaves = [t.clone().requires_grad_() for t in args]
    outs = {b: rasterize(*leaves, width, height, backend=b, min_transmittance=0.0) for b in ("numba", "torch")}
    torch.testing.assert_close(outs["numba"].color, outs["torch"].color, rtol=1e-9, atol=1e-10)
    grads = {b: torch.autograd.grad(weighted_loss(o), leaves) for b, o in outs.items()}
    for a, b in zip(grads["numba"], grads["torch"]):
        torch.testing.assert_close(a, b, rtol=1e-7, atol=1e-9 * max(b.abs().max().item(), 1.0))


@pytest.mark.parametrize("n", [80, 83])
def test_projection_twin_matches_the_tensor_projection(n):
    # Everything the rasterizer uses, culled and clamped Gaussians included, plus the boxes. The kernels work
    # on blocks of LANES Gaussians; 83 leaves a last block with lanes past the end, which must add nothing.
    args, width, height = random_scene(4, n=n)
    args[0][:3, 0] = torch.tensor([9.0, -9.0, 0.0], dtype=F64)  # beyond the frustum clamp
    args[2][:3] = 2.0
    means, quats, scales, opacities, _, world_to_cam, K = [t.clone().requires_grad_() for t in args]
    twin, twin_boxes = project_cpu(means, quats, scales, opacities, world_to_cam, K, width, height, 0.01, 0.3)
    ref, ref_boxes = _project(means, quats, scales, world_to_cam, K, width, height, 0.01, 0.3, opacities)
    assert torch.equal(twin.valid, ref.valid) and torch.equal(twin.radii, ref.radii)
    assert torch.equal(twin_boxes[twin.valid], ref_boxes[ref.valid])
    for name in ("means2d", "conics", "cov2d", "depths"):
        torch.testing.assert_close(getattr(twin, name), getattr(ref, name), rtol=1e-12, atol=1e-12, msg=name)
    g = torch.Generator().manual_seed(0)
    weights = [torch.randn(t.shape, generator=g, dtype=F64) for t in (ref.means2d, ref.conics, ref.depths)]

    def loss(p):
        return sum((t * w).sum() for t, w in zip((p.means2d, p.conics, p.depths), weights))

    leaves = (means, quats, scales, world_to_cam, K)
    for name, a, b in zip(("means", "quats", "scales", "world_to_cam", "K"), torch.autograd.grad(loss(twin), leaves),
                          torch.autograd.grad(loss(ref), leaves)):
        torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-9 * b.abs().max().item(), msg=name)


def test_a_fixed_camera_gets_no_gradient_and_leaves_the_others_as_they_were():
    """With the pose and K not requiring grad, the backward skips their sums (project_backward's ``camera_grad``):
    they get none, and the means', quats' and scales' gradients are the same to the bit."""
    args, width, height = random_scene(4, n=80)
    means, quats, scales, opacities, _, world_to_cam, K = args
    free = [t.clone().requires_grad_() for t in (means, quats, scales, world_to_cam, K)]
    fixed = [t.clone().requires_grad_() for t in (means, quats, scales)] + [world_to_cam.clone(), K.clone()]
    grads = []
    for leaves in (free, fixed):
        projection, _ = project_cpu(*leaves[:3], opacities, *leaves[3:], width, height, 0.01, 0.3)
        loss = (projection.means2d.sum() + projection.conics.square().sum() + projection.depths.sum())
        loss.backward()
        grads.append([t.grad for t in leaves])
    assert all(g is not None for g in grads[0]) and grads[1][3] is None and grads[1][4] is None
    for a, b in zip(grads[0][:3], grads[1][:3]):
        assert torch.equal(a, b)


def test_thread_count_does_not_change_the_result(monkeypatch):
    args, width, height = random_scene(6, n=300, dtype=torch.float32, width=70, height=50)
    results = []
    for threads in ("1", "2"):
        monkeypatch.setenv("FS3D_THREADS", threads)
        leaves = [t.clone().requires_grad_() for t in args]  # the pose and K included
        out = rasterize(*leaves, width, height, backend="numba")
        results.append((out.color, torch.autograd.grad(weighted_loss(out), leaves)))
    assert torch.equal(results[0][0], results[1][0])
    for a, b in zip(results[0][1], results[1][1]):
        assert torch.equal(a, b)  # no atomics, no per-thread partial sums: bitwise the same


@pytest.mark.parametrize("channels", [1, 3])
def test_kernels_compiled_for_a_feature_count_equal_the_general_ones(monkeypatch, channels):
    from fingersplat3d.splat import cpu_composite

    args, width, height = random_scene(7, n=300, channels=channels, dtype=torch.float32, width=70, height=50)
    results = []
    for kernels in (dict(cpu_composite._KERNELS), {0: cpu_composite._KERNELS[0]}):  # specialised, then general
        monkeypatch.setattr(cpu_composite, "_KERNELS", kernels)
        leaves = [t.clone().requires_grad_() for t in args]
        out = rasterize(*leaves, width, height, backend="numba")
        results.append((out.color, out.depth, torch.autograd.grad(weighted_loss(out), leaves[:5])))
    assert torch.equal(results[0][0], results[1][0]) and torch.equal(results[0][1], results[1][1])
    for a, b in zip(results[0][2], results[1][2]):
        assert torch.allclose(a, b, rtol=1e-5, atol=1e-7)  # the same sums, fused multiply-adds placed apart


def _kernel_inputs(channels, seed=8, width=70, height=50):
    """The compositing kernels' inputs for a float64 scene whose tiles are cut by the image's right and bottom
    edges, with one long thin diagonal Gaussian whose box corners lie far outside its ellipse, so that its falloff
    is evaluated per pixel (record column EA = 0) instead of by products."""
    from fingersplat3d.splat import cpu_composite

    args, width, height = random_scene(seed, n=300, channels=channels, width=width, height=height)
    means, quats, scales, opacities, colors, world_to_cam, K = args
    scales[0] = torch.tensor([1.5, 0.002, 0.002], dtype=F64)  # one wide, thin Gaussian ...
    quats[0] = torch.tensor([math.cos(math.pi / 8), 0.0, 0.0, math.sin(math.pi / 8)], dtype=F64)  # ... turned 45 deg
    means[0] = torch.tensor([0.0, 0.0, 3.0], dtype=F64)
    opacities[0] = 0.9
    projection, boxes = project_cpu(means, quats, scales, opacities, world_to_cam, K, width, height, 0.01, 0.3)
    feats = torch.cat([colors, projection.depths[:, None]], 1).numpy()
    order = depth_order(projection.depths.numpy(), projection.valid.numpy())
    records = cpu_composite.prepare(order, projection.means2d.numpy(), projection.conics.numpy(), opacities.numpy(),
                                    boxes.numpy(), feats)
    tiles_x, tiles_y = -(-width // cpu_composite.TILE), -(-height // cpu_composite.TILE)
    starts, ranks, _, _ = cpu_composite.bin_tiles(records, tiles_x, tiles_y)
    pairs = cpu_composite.gather_pairs(records, ranks)
    return starts, pairs, width, height, tiles_x, records


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("min_transmittance", [0.0, MIN_TRANSMITTANCE])
def test_vectorised_kernels_equal_the_general_ones_in_float64(channels, min_transmittance):
    from fingersplat3d.splat import cpu_composite
    from fingersplat3d.splat.cpu_tile_math import EA

    starts, pairs, width, height, tiles_x, records = _kernel_inputs(channels)
    assert (records[:, EA] == 0.0).any()  # the per-pixel falloff is exercised
    lanes, general = cpu_composite._KERNELS[channels + 1], cpu_composite._KERNELS[0]
    assert lanes is not general
    outputs = [kernels[0](starts, pairs, width, height, tiles_x, min_transmittance, 2) for kernels in (lanes, general)]
    (image, final, consumed), (image_ref, final_ref, consumed_ref) = outputs
    np.testing.assert_allclose(image, image_ref, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(final, final_ref, rtol=1e-12, atol=1e-14)
    assert np.array_equal(consumed, consumed_ref)
    g = np.random.default_rng(0)
    upstream, upstream_alpha = g.standard_normal(image.shape), g.standard_normal(final.shape)
    grads = [kernels[1](starts, pairs, width, height, tiles_x, final_ref, consumed_ref, upstream, upstream_alpha, 2)
             for kernels in (lanes, general)]
    scale = np.abs(grads[1]).max(0)
    assert np.isfinite(grads[0]).all() and (scale > 0).all()
    np.testing.assert_allclose(grads[0], grads[1], rtol=0, atol=1e-11 * scale.max())
    assert (np.abs(grads[0] - grads[1]) <= 1e-11 * scale).all()  # every column to rounding, not only the largest


def test_depth_order_is_a_stable_sort_with_ties_in_index_order():
    depths = np.array([3.0, 1.0, 2.0, 1.0, -1.0, 2.0, 1.0], np.float32)
    valid = np.array([True, True, True, True, False, True, True])
    assert depth_order(depths, valid).tolist() == [1, 3, 6, 2, 5, 0]
    rng = np.random.default_rng(0)
    many = rng.integers(1, 50, 5000).astype(np.float32) * np.float32(0.25)
    keep = rng.random(5000) > 0.1
    expected = np.flatnonzero(keep)[np.argsort(many[keep], kind="stable")]
    assert np.array_equal(depth_order(many, keep), expected)
    assert np.array_equal(depth_order(many.astype(np.float64), keep), expected)


def test_radix_order_is_numpys_stable_sort_over_every_positive_float():
    """The radix sort of float32 bits orders as numpy's stable argsort of the floats: across the whole positive range
    (subnormals to the largest float, each bit group of the key used) and with many ties."""
    from fingersplat3d.splat.cpu_composite import radix_order

    rng = np.random.default_rng(3)
    spread = rng.integers(1, 0x7F7FFFFF, 20000, dtype=np.uint32).view(np.float32)  # any positive finite float
    tied = rng.choice(np.array([1e-40, 0.5, 0.5000001, 3.0, 7e30], np.float32), 20000)
    for depths in (spread, tied, np.concatenate([spread, tied])):
        index = rng.permutation(depths.shape[0]).astype(np.int64)  # any order of indices, kept among ties
        expected = index[np.argsort(depths, kind="stable")]
        assert np.array_equal(radix_order(depths.view(np.uint32), index), expected)
    assert radix_order(np.zeros(0, np.uint32), np.zeros(0, np.int64)).shape == (0,)


def test_numba_backend_refuses_other_devices_and_unknown_names():
    args, width, height = random_scene(0, n=5)
    with pytest.raises(ValueError, match="backend must be one of"):
        rasterize(*args, width, height, backend="gsplat-cpu")
    with pytest.raises(ValueError, match="min_transmittance"):
        rasterize(*args, width, height, backend="numba", min_transmittance=1.0)
    with pytest.raises(ValueError, match="runs on the CPU"):
        rasterize(*[t.to("meta") for t in args], width, height, backend="numba")
