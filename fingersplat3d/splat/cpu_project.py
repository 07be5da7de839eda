"""The CPU rasterizer's EWA projection (numba), forward and hand-written backward.

The same function as :func:`.project._project_core` (read its docstring for the formulas: float64
inside, Cauchy-Binet determinant, Jacobian at the frustum-clamped point, alpha-footprint boxes),
one Gaussian per loop iteration instead of one tensor operation per formula: at 200k Gaussians
the tensor version spends ~0.1 s in allocation and memory passes. The backward is the chain rule
written out (derivation in the comments) and checked against the tensor version and by float64
gradcheck; gradients reach means, quats, scales and, summed per thread chunk, the pose and K.
Pure numpy in, numpy out.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .project import ALPHA_MIN, FRUSTUM_MARGIN

__all__ = ["project_forward", "project_backward"]

_TINY_QUAT = 1e-12  # squared norm below which a quaternion is the identity (rotations.normalize_quaternions)
_MAX_RADIUS = 2 ** 30


@njit(cache=True, inline="always")
def _unit_quaternion(quats, g):
    w, x, y, z = float(quats[g, 0]), float(quats[g, 1]), float(quats[g, 2]), float(quats[g, 3])
    norm2 = w * w + x * x + y * y + z * z
    if norm2 < _TINY_QUAT:
        return 1.0, 0.0, 0.0, 0.0, 0.0
    norm = math.sqrt(norm2)
    return w / norm, x / norm, y / norm, z / norm, norm


@njit(cache=True, inline="always")
def _quaternion_matrix(w, x, y, z, rq):
    rq[0, 0], rq[0, 1], rq[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    rq[1, 0], rq[1, 1], rq[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    rq[2, 0], rq[2, 1], rq[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)


@njit(cache=True, inline="always")
def _limits(camera, width, height):
    fx, fy, cx, cy = camera[12], camera[13], camera[14], camera[15]
    return ((cx + FRUSTUM_MARGIN * width) / fx, (width - cx + FRUSTUM_MARGIN * width) / fx,
            (cy + FRUSTUM_MARGIN * height) / fy, (height - cy + FRUSTUM_MARGIN * height) / fy)


@njit(cache=True, inline="always")
def _axes(camera, quats, scales, g, m, rq):
    """M = R_wc R_q S (rows: the Gaussian's scaled axes seen from the camera) into ``m``, R_q into ``rq``."""
    w, x, y, z, _ = _unit_quaternion(quats, g)
    _quaternion_matrix(w, x, y, z, rq)
    for i in range(3):
        for j in range(3):
            m[i, j] = (camera[3 * i] * rq[0, j] + camera[3 * i + 1] * rq[1, j] + camera[3 * i + 2] * rq[2, j]) \
                * float(scales[g, j])


@njit(cache=True, inline="always")
def _camera_point(camera, means, g, p):
    """Gaussian ``g``'s centre in the camera frame, into ``p``: R m + t."""
    for i in range(3):
        p[i] = (camera[3 * i] * float(means[g, 0]) + camera[3 * i + 1] * float(means[g, 1])
                + camera[3 * i + 2] * float(means[g, 2]) + camera[9 + i])


@njit(cache=True, inline="always")
def _screen_covariance(camera, quats, scales, g, z, tx, ty, low_pass, m, rq, t0, t1):
    """The 2D covariance ``(a, b, c)`` and its determinant (Cauchy-Binet, not clamped) of Gaussian
    ``g`` at depth ``z`` with the clamped tangents ``tx, ty``; fills ``m``, ``rq`` (:func:`_axes`)
    and the Jacobian rows ``t0 = (fx/z)(M0 - tx M2)``, ``t1 = (fy/z)(M1 - ty M2)``."""
    fx, fy = camera[12], camera[13]
    _axes(camera, quats, scales, g, m, rq)
    for j in range(3):
        t0[j] = fx / z * (m[0, j] - tx * m[2, j])
        t1[j] = fy / z * (m[1, j] - ty * m[2, j])
    a = t0[0] * t0[0] + t0[1] * t0[1] + t0[2] * t0[2] + low_pass
    b = t0[0] * t1[0] + t0[1] * t1[1] + t0[2] * t1[2]
    c = t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2] + low_pass
    m01, m02 = t0[0] * t1[1] - t0[1] * t1[0], t0[0] * t1[2] - t0[2] * t1[0]
    m12 = t0[1] * t1[2] - t0[2] * t1[1]
    return a, b, c, m01 * m01 + m02 * m02 + m12 * m12 + low_pass * (a + c - low_pass)  # det = a c - b^2


@njit(cache=True, parallel=True)
def project_forward(means, quats, scales, opacities, camera, width, height, near, low_pass):
    """``camera`` [16] float64: R (row-major 9), t (3), fx, fy, cx, cy. Returns float64 ``means2d
    [N, 2], conics [N, 3], cov2d [N, 3], depths [N]``, int32 ``radii [N]``, bool ``valid [N]``,
    int64 ``boxes [N, 4]``, exactly as :func:`.project._project_core` (culled: zeros, valid False)."""
    n = means.shape[0]
    means2d, conics, cov2d = np.zeros((n, 2)), np.zeros((n, 3)), np.zeros((n, 3))
    depths, radii = np.zeros(n), np.zeros(n, np.int32)
    valid, boxes = np.zeros(n, np.bool_), np.zeros((n, 4), np.int64)
    lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos = _limits(camera, width, height)
    chunks = max(1, min(n, 64))  # contiguous blocks, scratch arrays allocated once per block
    for chunk in prange(chunks):
        p, t0, t1 = np.empty(3), np.empty(3), np.empty(3)
        m, rq = np.empty((3, 3)), np.empty((3, 3))
        for g in range(chunk * n // chunks, (chunk + 1) * n // chunks):
            _project_one(means, quats, scales, opacities, camera, width, height, near, low_pass, g, p, t0, t1, m, rq,
                         lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos, means2d, conics, cov2d, depths, radii, valid, boxes)
    return means2d, conics, cov2d, depths, radii, valid, boxes


@njit(cache=True, inline="always")
def _project_one(means, quats, scales, opacities, camera, width, height, near, low_pass, g, p, t0, t1, m, rq,
                 lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos, means2d, conics, cov2d, depths, radii, valid, boxes):
    """Gaussian ``g`` of :func:`project_forward` (scratch arrays p, t0, t1, m, rq)."""
    fx, fy, cx, cy = camera[12], camera[13], camera[14], camera[15]
    _camera_point(camera, means, g, p)
    depths[g] = p[2]
    if not (p[2] >= near and math.isfinite(p[0]) and math.isfinite(p[1]) and math.isfinite(p[2])):
        return
    z = p[2]
    u, v = fx * p[0] / z + cx, fy * p[1] / z + cy
    tx = max(min(p[0] / z, lim_x_pos), -lim_x_neg)
    ty = max(min(p[1] / z, lim_y_pos), -lim_y_neg)
    a, b, c, det = _screen_covariance(camera, quats, scales, g, z, tx, ty, low_pass, m, rq, t0, t1)
    det = max(det, 1e-300)
    # Footprint box (project.footprint_boxes, opacities given).
    o = float(opacities[g])
    ratio = o / ALPHA_MIN
    q_max = 2.0 * math.log(ratio if ratio > 1e-30 else 1e-30)
    if not q_max > 0.0:
        return
    q_max = q_max * (1.0 + 1e-4) + 1e-4
    ext_x, ext_y = math.sqrt(q_max * max(a, 0.0)), math.sqrt(q_max * max(c, 0.0))
    if not (math.isfinite(u) and math.isfinite(v) and math.isfinite(ext_x) and math.isfinite(ext_y)
            and math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        return
    x0 = max(math.ceil(min(max(u - ext_x, -1.0), width)), 0.0)
    x1 = min(math.floor(min(max(u + ext_x, -1.0), width)), width - 1.0)
    y0 = max(math.ceil(min(max(v - ext_y, -1.0), height)), 0.0)
    y1 = min(math.floor(min(max(v + ext_y, -1.0), height)), height - 1.0)
    if x0 > x1 or y0 > y1:
        return
    valid[g] = True
    boxes[g, 0], boxes[g, 1], boxes[g, 2], boxes[g, 3] = int(x0), int(y0), int(x1), int(y1)
    means2d[g, 0], means2d[g, 1] = u, v
    cov2d[g, 0], cov2d[g, 1], cov2d[g, 2] = a, b, c
    conics[g, 0], conics[g, 1], conics[g, 2] = c / det, -b / det, a / det
    lambda_max = 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)
    radii[g] = int(min(math.ceil(3.0 * math.sqrt(lambda_max)), _MAX_RADIUS))


@njit(cache=True, parallel=True)
def project_backward(means, quats, scales, camera, width, height, low_pass, valid, grad_means2d, grad_conics,
                     grad_depths, chunks, camera_grad):
    """Gradients of ``sum(means2d * g2d) + sum(conics * gc) + sum(depths * gz)`` w.r.t. means [N, 3],
    quats [N, 4], scales [N, 3] and the camera ``[chunks, 16]`` (partial sums over ``chunks``
    contiguous blocks of Gaussians: R, t, fx, fy, cx, cy). A fixed ``chunks`` (not the thread
    count) keeps the sums the same whatever the threads. ``camera_grad`` False: the camera's are left
    at zero (a camera held fixed: ~50 sums per Gaussian spared)."""
    n = means.shape[0]
    g_means, g_quats, g_scales = np.zeros((n, 3)), np.zeros((n, 4)), np.zeros((n, 3))
    g_camera = np.zeros((chunks, 16))
    fx, fy = camera[12], camera[13]
    lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos = _limits(camera, width, height)
    for chunk in prange(chunks):
        gc = g_camera[chunk]
        p, g_p = np.empty(3), np.empty(3)
        t0, t1, g_t0, g_t1 = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
        g_m, g_rq, m, rq = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
        for g in range(chunk * n // chunks, (chunk + 1) * n // chunks):
            _camera_point(camera, means, g, p)
            g_p[0], g_p[1], g_p[2] = 0.0, 0.0, float(grad_depths[g])
            if valid[g]:
                z = p[2]
                xz, yz = p[0] / z, p[1] / z
                tx, ty = max(min(xz, lim_x_pos), -lim_x_neg), max(min(yz, lim_y_pos), -lim_y_neg)
                a, b, c, det = _screen_covariance(camera, quats, scales, g, z, tx, ty, low_pass, m, rq, t0, t1)
                # conic = (c, -b, a) / det with det = a c - b^2 (clamped at 1e-300: no gradient there).
                gA, gB, gC = float(grad_conics[g, 0]), float(grad_conics[g, 1]), float(grad_conics[g, 2])
                g_det = -(gA * c - gB * b + gC * a) / (det * det) if det > 1e-300 else 0.0
                det = max(det, 1e-300)
                g_a = gC / det + g_det * c
                g_b = -gB / det - 2.0 * g_det * b
                g_c = gA / det + g_det * a
                # a = t0.t0 + lp, b = t0.t1, c = t1.t1 + lp; t0 = (fx/z)(M0 - tx M2), t1 = (fy/z)(M1 - ty M2).
                g_s0 = g_s1 = g_tx = g_ty = 0.0
                for j in range(3):
                    g_t0[j] = 2.0 * g_a * t0[j] + g_b * t1[j]
                    g_t1[j] = 2.0 * g_c * t1[j] + g_b * t0[j]
                    g_m[0, j] = fx / z * g_t0[j]
                    g_m[1, j] = fy / z * g_t1[j]
                    g_m[2, j] = -tx * fx / z * g_t0[j] - ty * fy / z * g_t1[j]
                    g_tx -= fx / z * g_t0[j] * m[2, j]
                    g_ty -= fy / z * g_t1[j] * m[2, j]
                    g_s0 += g_t0[j] * (m[0, j] - tx * m[2, j])
                    g_s1 += g_t1[j] * (m[1, j] - ty * m[2, j])
                # s0 = fx / z, s1 = fy / z.
                if camera_grad:
                    gc[12] += g_s0 / z
                    gc[13] += g_s1 / z
                g_p[2] -= (g_s0 * fx + g_s1 * fy) / (z * z)
                # tx = clamp(x / z, -lim_x_neg, lim_x_pos); the limits depend on fx, cx.
                if -lim_x_neg < xz < lim_x_pos:
                    g_p[0] += g_tx / z
                    g_p[2] -= g_tx * xz / z
                elif camera_grad:  # clamped: tx depends on fx and cx only
                    if xz >= lim_x_pos:  # tx = (width - cx + m width) / fx
                        gc[14] -= g_tx / fx
                        gc[12] -= g_tx * lim_x_pos / fx
                    else:  # tx = -(cx + m width) / fx
                        gc[14] -= g_tx / fx
                        gc[12] += g_tx * lim_x_neg / fx
                if -lim_y_neg < yz < lim_y_pos:
                    g_p[1] += g_ty / z
                    g_p[2] -= g_ty * yz / z
                elif camera_grad:
                    if yz >= lim_y_pos:
                        gc[15] -= g_ty / fy
                        gc[13] -= g_ty * lim_y_pos / fy
                    else:
                        gc[15] -= g_ty / fy
                        gc[13] += g_ty * lim_y_neg / fy
                # u = fx x / z + cx, v = fy y / z + cy.
                gu, gv = float(grad_means2d[g, 0]), float(grad_means2d[g, 1])
                if camera_grad:
                    gc[12] += gu * xz
                    gc[13] += gv * yz
                    gc[14] += gu
                    gc[15] += gv
                g_p[0] += gu * fx / z
                g_p[1] += gv * fy / z
                g_p[2] -= (gu * fx * xz + gv * fy * yz) / z
                # M[i, j] = sum_k R[i, k] Rq[k, j] s_j.
                g_rq[:] = 0.0
                for j in range(3):
                    s = float(scales[g, j])
                    for i in range(3):
                        for k in range(3):
                            if camera_grad:
                                gc[3 * i + k] += g_m[i, j] * rq[k, j] * s
                            g_rq[k, j] += camera[3 * i + k] * g_m[i, j] * s
                    g_scales[g, j] = _scale_gradient(camera, rq, g_m, j)
                # Rq of the unit quaternion (w, x, y, z), then the normalisation q / |q|.
                w, x, y, zq, norm = _unit_quaternion(quats, g)
                gw = 2.0 * (-zq * g_rq[0, 1] + y * g_rq[0, 2] + zq * g_rq[1, 0] - x * g_rq[1, 2] - y * g_rq[2, 0]
                            + x * g_rq[2, 1])
                gx = 2.0 * (y * g_rq[0, 1] + zq * g_rq[0, 2] + y * g_rq[1, 0] - 2.0 * x * g_rq[1, 1] - w * g_rq[1, 2]
                            + zq * g_rq[2, 0] + w * g_rq[2, 1] - 2.0 * x * g_rq[2, 2])
                gy = 2.0 * (-2.0 * y * g_rq[0, 0] + x * g_rq[0, 1] + w * g_rq[0, 2] + x * g_rq[1, 0] + zq * g_rq[1, 2]
                            - w * g_rq[2, 0] + zq * g_rq[2, 1] - 2.0 * y * g_rq[2, 2])
                gz = 2.0 * (-2.0 * zq * g_rq[0, 0] - w * g_rq[0, 1] + x * g_rq[0, 2] + w * g_rq[1, 0]
                            - 2.0 * zq * g_rq[1, 1] + y * g_rq[1, 2] + x * g_rq[2, 0] + y * g_rq[2, 1])
                if norm > 0.0:
                    radial = w * gw + x * gx + y * gy + zq * gz
                    g_quats[g, 0] = (gw - w * radial) / norm
                    g_quats[g, 1] = (gx - x * radial) / norm
                    g_quats[g, 2] = (gy - y * radial) / norm
                    g_quats[g, 3] = (gz - zq * radial) / norm
            # p = R m + t.
            if camera_grad:
                for i in range(3):
                    gc[9 + i] += g_p[i]
                    for k in range(3):
                        gc[3 * i + k] += g_p[i] * float(means[g, k])
            for k in range(3):
                g_means[g, k] = camera[k] * g_p[0] + camera[3 + k] * g_p[1] + camera[6 + k] * g_p[2]
    return g_means, g_quats, g_scales, g_camera


@njit(cache=True, inline="always")
def _scale_gradient(camera, rq, g_m, j):
    """dL/ds_j = sum_i g_M[i, j] (R Rq)[i, j] (not g_M . M / s_j: s_j may be 0)."""
    total = 0.0
    for i in range(3):
        total += g_m[i, j] * (camera[3 * i] * rq[0, j] + camera[3 * i + 1] * rq[1, j] + camera[3 * i + 2] * rq[2, j])
    return total
