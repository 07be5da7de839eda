"""The compiled CPU rasterizer: :mod:`.cpu_project` and :mod:`.cpu_composite` behind torch autograd functions.

:func:`project_cpu` is :func:`.project._project` (same outputs, gradients to means, quats, scales,
``world_to_cam`` and ``K``); :func:`composite_cpu` takes the screen-space Gaussians and the
features to composite and returns the ``[H, W, F]`` image, differentiable w.r.t. means2d, conics,
opacities and features, as :func:`.composite.composite_tiles` does. Threads: the project's one
setting, :func:`fingersplat3d.device.numba_threads`.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import Tensor
from torch.autograd.function import once_differentiable

from ..device import numba_threads
from .cpu_composite import (TILE, bin_tiles, composite_backward, composite_forward, gather_pairs, prepare, radix_order,
                            reduce_pairs)
from .cpu_project import project_backward, project_forward
from .project import Projection, near_in_dtype

__all__ = ["composite_cpu", "project_cpu"]


def depth_order(depths: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Indices of the ``valid`` Gaussians front to back, ties in index order (a stable sort). float32 depths
    (positive: drawn Gaussians are beyond the near plane) by their bits in :func:`.cpu_composite.radix_order`;
    others by numpy's stable argsort."""
    visible = np.flatnonzero(valid)
    drawn = depths[visible]  # gathered once (a new, contiguous array): the test and the sort read it
    if depths.dtype != np.float32 or not (drawn > 0).all():
        return visible[np.argsort(drawn, kind="stable")]
    return radix_order(drawn.view(np.uint32), visible.astype(np.int64, copy=False))


def _numpy(t: Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().numpy())


class _CompositeCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d: Tensor, conics: Tensor, opacities: Tensor, feats: Tensor, boxes: Tensor,
                valid: Tensor, depths: Tensor, width: int, height: int, min_transmittance: float) -> Tensor:
        chunks = numba_threads()
        tiles_x, tiles_y = -(-width // TILE), -(-height // TILE)
        order = depth_order(_numpy(depths), _numpy(valid))
        records = prepare(order, _numpy(means2d), _numpy(conics), _numpy(opacities),
                          _numpy(boxes.long()), _numpy(feats))
        starts, ranks, offsets, slots = bin_tiles(records, tiles_x, tiles_y)
        pairs = gather_pairs(records, ranks)
        image, final, consumed = composite_forward(starts, pairs, width, height, tiles_x, float(min_transmittance),
                                                   chunks)
        ctx.state = (starts, pairs, offsets, slots, final, consumed, width, height, tiles_x)
        ctx.order, ctx.num = torch.from_numpy(order), means2d.shape[0]
        return torch.from_numpy(image).to(feats.dtype), torch.from_numpy(1.0 - final).to(feats.dtype)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_image: Tensor, grad_alpha: Tensor):
        starts, pairs, offsets, slots, final, consumed, width, height, tiles_x = ctx.state
        chunks = numba_threads()
        pair_grads = composite_backward(starts, pairs, width, height, tiles_x, final, consumed, _numpy(grad_image),
                                        _numpy(grad_alpha), chunks)
        per_drawn = torch.from_numpy(reduce_pairs(pair_grads, offsets, slots)).to(grad_image.dtype)
        total = grad_image.new_zeros(ctx.num, per_drawn.shape[1]).index_copy_(0, ctx.order, per_drawn)
        return total[:, 0:2], total[:, 2:5], total[:, 5], total[:, 6:], None, None, None, None, None, None


def composite_cpu(means2d: Tensor, conics: Tensor, opacities: Tensor, feats: Tensor, boxes: Tensor, valid: Tensor,
                  depths: Tensor, width: int, height: int, min_transmittance: float) -> tuple[Tensor, Tensor]:
    """Composite the drawn (``valid``) Gaussians front to back into ``(image [H, W, F] = sum_i w_i
    feat_i, alpha [H, W] = sum_i w_i)`` (``means2d`` [N, 2], ``conics`` [N, 3], ``opacities`` [N],
    ``feats`` [N, F], ``boxes`` [N, 4] inclusive pixel boxes, ``depths`` [N] for the order). CPU
    tensors only."""
    if not 0.0 <= min_transmittance < 1.0:
        raise ValueError(f"min_transmittance must be in [0, 1), got {min_transmittance}")
    return _CompositeCPU.apply(means2d, conics, opacities, feats, boxes, valid, depths, int(width), int(height),
                               float(min_transmittance))


def _camera_vector(world_to_cam: Tensor, K: Tensor) -> np.ndarray:
    """R (row-major), t, fx, fy, cx, cy as float64 ``[16]``."""
    w2c, k = world_to_cam.detach().double(), K.detach().double()
    return np.concatenate([w2c[:3, :3].reshape(-1).numpy(), w2c[:3, 3].numpy(),
                           np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2]], dtype=np.float64)])


class _ProjectCPU(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, world_to_cam: Tensor, K: Tensor,
                width: int, height: int, near: float, low_pass: float):
        numba_threads()
        camera = _camera_vector(world_to_cam, K)
        arrays = tuple(_numpy(t) for t in (means, quats, scales))
        means2d, conics, cov2d, depths, radii, valid, boxes = project_forward(*arrays, _numpy(opacities), camera, width,
                                                                              height, near, low_pass)
        ctx.state = (arrays, camera, width, height, low_pass, valid)
        ctx.dtypes = (world_to_cam.dtype, K.dtype)
        dtype = means.dtype
        outputs = [torch.from_numpy(a).to(dtype) for a in (means2d, conics, cov2d, depths)]
        extras = [torch.from_numpy(radii), torch.from_numpy(valid), torch.from_numpy(boxes)]
        ctx.mark_non_differentiable(outputs[2], *extras)
        return (*outputs, *extras)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_means2d, grad_conics, grad_cov2d, grad_depths, *_):
        arrays, camera, width, height, low_pass, valid = ctx.state
        numba_threads()
        chunks = 64  # camera gradient partial sums: a fixed count, so any thread count gives the same sums
        zeros = lambda t, shape: np.zeros(shape) if t is None else _numpy(t)  # noqa: E731
        n = arrays[0].shape[0]
        camera_grad = bool(ctx.needs_input_grad[4] or ctx.needs_input_grad[5])  # a fixed camera: no sums for it
        g_means, g_quats, g_scales, g_camera = project_backward(
            *arrays, camera, width, height, low_pass, valid, zeros(grad_means2d, (n, 2)),
            zeros(grad_conics, (n, 3)), zeros(grad_depths, (n,)), chunks, camera_grad)
        dtype = grad_means2d.dtype if grad_means2d is not None else torch.float64
        g_camera = torch.from_numpy(g_camera.sum(0))
        w2c_dtype, k_dtype = ctx.dtypes
        g_w2c = torch.zeros(4, 4, dtype=torch.float64)
        g_w2c[:3, :3] = g_camera[:9].view(3, 3)
        g_w2c[:3, 3] = g_camera[9:12]
        g_K = torch.zeros(3, 3, dtype=torch.float64)
        g_K[0, 0], g_K[1, 1], g_K[0, 2], g_K[1, 2] = g_camera[12:16]
        return (torch.from_numpy(g_means).to(dtype), torch.from_numpy(g_quats).to(dtype),
                torch.from_numpy(g_scales).to(dtype), None, g_w2c.to(w2c_dtype) if ctx.needs_input_grad[4] else None,
                g_K.to(k_dtype) if ctx.needs_input_grad[5] else None, None, None, None, None)


def project_cpu(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, world_to_cam: Tensor, K: Tensor,
                width: int, height: int, near: float, low_pass: float) -> tuple[Projection, Tensor]:
    """:func:`.project._project` on the CPU kernels (opacities given): ``(Projection, boxes [N, 4])``."""
    near = near_in_dtype(near, means.dtype)
    means2d, conics, cov2d, depths, radii, valid, boxes = _ProjectCPU.apply(
        means, quats, scales, opacities, world_to_cam, K, int(width), int(height), near, float(low_pass))
    return Projection(means2d, cov2d, conics, depths, radii, valid), boxes
