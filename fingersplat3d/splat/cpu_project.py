"""The CPU rasterizer's EWA projection (numba), forward and hand-written backward.

The same function as :func:`.project._project_core` (read its docstring for the formulas: float64
inside, Cauchy-Binet determinant, Jacobian at the frustum-clamped point, alpha-footprint boxes),
written per Gaussian instead of one tensor operation per formula: at 200k Gaussians the tensor
version spends ~0.1 s in allocation and memory passes. The Gaussians go through in blocks of
:data:`LANES`, computed together in SIMD lanes (below). The backward is the chain rule written out
(derivation in the comments) and checked against the tensor version and by float64 gradcheck;
gradients reach means, quats, scales and, summed per lane and chunk, the pose and K.
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
LANES = 8
"""Gaussians per block: one float64 lane each of an AVX-512 register (two blocks' halves with AVX2)."""
_CHUNKS = 64
"""Contiguous blocks of Gaussians, one parallel task each; a fixed count (not the thread count) keeps the
camera gradient's partial sums the same whatever the threads."""
_INF = math.inf


def alpha_q_max(opacities: np.ndarray) -> np.ndarray:
    """Per Gaussian, the largest q = d^T conic d at which ``o exp(-q/2)`` still reaches ``ALPHA_MIN``, a
    hair wider (as :func:`.project.footprint_boxes`); -1 where it never does. float64 ``[N]``, by numpy's
    vectorised logarithm (numba's is a scalar call per Gaussian, and stops the kernels' vectorising)."""
    o = np.asarray(opacities, np.float64)
    reaches = o > ALPHA_MIN
    with np.errstate(divide="ignore", invalid="ignore"):
        q_max = 2.0 * np.log(np.where(reaches, o, 1.0) / ALPHA_MIN) * (1.0 + 1e-4) + 1e-4
    return np.where(reaches, q_max, -1.0)


# The kernels work on blocks of LANES Gaussians: a block's inputs are copied into a flat scratch buffer,
# one row of LANES per quantity (row k at [k * LANES, (k + 1) * LANES)), so that the loop over a block's
# lanes reads and writes slices at constant offsets and LLVM's loop vectoriser computes all lanes at once;
# every condition is a select, never a branch. The per-Gaussian formulas are the helpers below, on scalars.
# Rows of the buffer: inputs, then outputs, then (backward) the camera gradient's per-lane sums, all in one
# array (separate arrays might overlap as far as the compiler knows, and it would not vectorise).
_MEANS, _SCALES, _QUATS, _EXTRA = 0, 3, 6, 10
_FORWARD_OUT = 11  # 15 rows: depth, u, v, cov2d (3), conic (3), box (4), radius, valid
_BACKWARD_OUT = 17  # 10 rows: means (3), quats (4), scales (3) gradients
_CAMERA = 27  # 16 rows


@njit(cache=True, inline="always")
def _finite(x):
    return abs(x) < _INF  # False for inf and NaN, and vectorises (math.isfinite does not)


@njit(cache=True, inline="always")
def _unit_quaternion(w, x, y, z):
    """``(w, x, y, z, norm)`` of the unit quaternion; the identity and norm 0 below ``_TINY_QUAT``."""
    norm2 = w * w + x * x + y * y + z * z
    small = norm2 < _TINY_QUAT
    norm = math.sqrt(1.0 if small else norm2)
    return (1.0 if small else w / norm, 0.0 if small else x / norm, 0.0 if small else y / norm,
            0.0 if small else z / norm, 0.0 if small else norm)


@njit(cache=True, inline="always")
def _quaternion_matrix(w, x, y, z):
    """R_q of a unit quaternion, row-major 9 scalars."""
    return (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))


@njit(cache=True, inline="always")
def _limits(camera, width, height):
    fx, fy, cx, cy = camera[12], camera[13], camera[14], camera[15]
    return ((cx + FRUSTUM_MARGIN * width) / fx, (width - cx + FRUSTUM_MARGIN * width) / fx,
            (cy + FRUSTUM_MARGIN * height) / fy, (height - cy + FRUSTUM_MARGIN * height) / fy)


@njit(cache=True, inline="always")
def _as_tuple(camera):
    return (camera[0], camera[1], camera[2], camera[3], camera[4], camera[5], camera[6], camera[7], camera[8],
            camera[9], camera[10], camera[11], camera[12], camera[13], camera[14], camera[15])


@njit(cache=True, inline="always")
def _rotated(camera, i, q0, q1, q2):
    """Row i of R_wc times the column (q0, q1, q2)."""
    return camera[3 * i] * q0 + camera[3 * i + 1] * q1 + camera[3 * i + 2] * q2


@njit(cache=True, inline="always")
def _rotated_t(camera, k, g0, g1, g2):
    """Column k of R_wc (row k of its transpose) times (g0, g1, g2)."""
    return camera[k] * g0 + camera[3 + k] * g1 + camera[6 + k] * g2


@njit(cache=True, inline="always")
def _load_block(buf, g0, count, means, scales, quats, extra):
    """Copy Gaussians ``g0 .. g0 + count`` into ``buf``'s input rows (:data:`_MEANS`, :data:`_SCALES`,
    :data:`_QUATS`, then one row per column of ``extra`` ``[N, E]`` from :data:`_EXTRA`); lanes past
    ``count`` repeat the block's first Gaussian (their results are not used)."""
    for l in range(LANES):
        g = g0 + l if l < count else g0
        for k in range(3):
            buf[(_MEANS + k) * LANES + l] = means[g, k]
            buf[(_SCALES + k) * LANES + l] = scales[g, k]
        for k in range(4):
            buf[(_QUATS + k) * LANES + l] = quats[g, k]
        for k in range(extra.shape[1]):
            buf[(_EXTRA + k) * LANES + l] = extra[g, k]


@njit(cache=True, error_model="numpy")
def _forward_lanes(buf, camera, width, height, near, low_pass):
    """:func:`project_forward` of one block's lanes in ``buf``, inputs to outputs (a function of its own:
    numba's parallel analysis of the caller trips on its tuples, and LLVM vectorises it whole)."""
    cam = _as_tuple(camera)  # scalars in registers: the array could overlap buf as far as LLVM knows
    lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos = _limits(cam, width, height)
    fx, fy, cx, cy = cam[12], cam[13], cam[14], cam[15]
    for l in range(LANES):
        m0, m1, m2 = buf[_MEANS * LANES + l], buf[(_MEANS + 1) * LANES + l], buf[(_MEANS + 2) * LANES + l]
        p0 = _rotated(cam, 0, m0, m1, m2) + cam[9]
        p1 = _rotated(cam, 1, m0, m1, m2) + cam[10]
        p2 = _rotated(cam, 2, m0, m1, m2) + cam[11]
        in_front = (p2 >= near) & _finite(p0) & _finite(p1) & _finite(p2)
        z = p2 if in_front else 1.0
        u, v = fx * p0 / z + cx, fy * p1 / z + cy
        tx = max(min(p0 / z, lim_x_pos), -lim_x_neg)
        ty = max(min(p1 / z, lim_y_pos), -lim_y_neg)
        a, b, c, det = _screen_covariance(cam, buf, l, z, tx, ty, low_pass)[:4]
        det = max(det, 1e-300)
        reach = buf[_EXTRA * LANES + l]
        ext_x, ext_y = math.sqrt(max(reach, 0.0) * max(a, 0.0)), math.sqrt(max(reach, 0.0) * max(c, 0.0))
        # np.ceil / np.floor stay float (math's return ints, a conversion that does not vectorise).
        x0 = max(np.ceil(min(max(u - ext_x, -1.0), width)), 0.0)
        x1 = min(np.floor(min(max(u + ext_x, -1.0), width)), width - 1.0)
        y0 = max(np.ceil(min(max(v - ext_y, -1.0), height)), 0.0)
        y1 = min(np.floor(min(max(v + ext_y, -1.0), height)), height - 1.0)
        ok = (in_front & (reach > 0.0) & _finite(u) & _finite(v) & _finite(ext_x) & _finite(ext_y)
              & _finite(a) & _finite(b) & _finite(c) & (x0 <= x1) & (y0 <= y1))
        lambda_max = 0.5 * (a + c) + math.sqrt(0.25 * (a - c) ** 2 + b * b)
        radius = min(np.ceil(3.0 * math.sqrt(lambda_max)), float(_MAX_RADIUS))
        row = _FORWARD_OUT * LANES + l
        buf[row] = p2
        buf[row + LANES] = u if ok else 0.0
        buf[row + 2 * LANES] = v if ok else 0.0
        buf[row + 3 * LANES] = a if ok else 0.0
        buf[row + 4 * LANES] = b if ok else 0.0
        buf[row + 5 * LANES] = c if ok else 0.0
        buf[row + 6 * LANES] = c / det if ok else 0.0
        buf[row + 7 * LANES] = -b / det if ok else 0.0
        buf[row + 8 * LANES] = a / det if ok else 0.0
        buf[row + 9 * LANES] = x0 if ok else 0.0
        buf[row + 10 * LANES] = y0 if ok else 0.0
        buf[row + 11 * LANES] = x1 if ok else 0.0
        buf[row + 12 * LANES] = y1 if ok else 0.0
        buf[row + 13 * LANES] = radius if ok else 0.0
        buf[row + 14 * LANES] = 1.0 if ok else 0.0


@njit(cache=True, parallel=True)
def _forward_kernel(means, quats, scales, q_max, camera, width, height, near, low_pass):
    n, dtype = means.shape[0], means.dtype
    means2d, conics, cov2d = np.zeros((n, 2), dtype), np.zeros((n, 3), dtype), np.zeros((n, 3), dtype)
    depths, radii = np.zeros(n, dtype), np.zeros(n, np.int32)
    valid, boxes = np.zeros(n, np.bool_), np.zeros((n, 4), np.int64)
    blocks = -(-n // LANES)
    for chunk in prange(_CHUNKS):
        buf = np.empty((_FORWARD_OUT + 15) * LANES)
        for block in range(chunk * blocks // _CHUNKS, (chunk + 1) * blocks // _CHUNKS):
            g0 = block * LANES
            count = min(LANES, n - g0)
            _load_block(buf, g0, count, means, scales, quats, q_max)
            _forward_lanes(buf, camera, width, height, near, low_pass)
            for l in range(count):
                g, row = g0 + l, _FORWARD_OUT * LANES + l
                depths[g] = buf[row]
                means2d[g, 0], means2d[g, 1] = buf[row + LANES], buf[row + 2 * LANES]
                for k in range(3):
                    cov2d[g, k] = buf[row + (3 + k) * LANES]
                    conics[g, k] = buf[row + (6 + k) * LANES]
                for k in range(4):
                    boxes[g, k] = int(buf[row + (9 + k) * LANES])
                radii[g] = int(buf[row + 13 * LANES])
                valid[g] = buf[row + 14 * LANES] > 0.0
    return means2d, conics, cov2d, depths, radii, valid, boxes


def project_forward(means, quats, scales, opacities, camera, width, height, near, low_pass):
    """``camera`` [16] float64: R (row-major 9), t (3), fx, fy, cx, cy. Returns ``means2d [N, 2], conics
    [N, 3], cov2d [N, 3], depths [N]`` in the means' dtype (computed in float64, rounded once on the way
    out), int32 ``radii [N]``, bool ``valid [N]``, int64 ``boxes [N, 4]``, exactly as
    :func:`.project._project_core` (culled: zeros, valid False)."""
    q_max = alpha_q_max(opacities)[:, None]
    return _forward_kernel(means, quats, scales, q_max, camera, width, height, near, low_pass)


@njit(cache=True, inline="always")
def _screen_covariance(camera, buf, l, z, tx, ty, low_pass):
    """Lane ``l``'s 2D covariance ``(a, b, c)``, its determinant (Cauchy-Binet, not clamped), the Jacobian
    rows ``t0 = (fx/z)(M0 - tx M2)``, ``t1 = (fy/z)(M1 - ty M2)``, M = R_wc R_q S (rows: the Gaussian's
    scaled axes seen from the camera), R_q and the unit quaternion with its norm."""
    fx, fy = camera[12], camera[13]
    w, x, y, zq, norm = _unit_quaternion(buf[_QUATS * LANES + l], buf[(_QUATS + 1) * LANES + l],
                                         buf[(_QUATS + 2) * LANES + l], buf[(_QUATS + 3) * LANES + l])
    rq = _quaternion_matrix(w, x, y, zq)
    s0, s1, s2 = buf[_SCALES * LANES + l], buf[(_SCALES + 1) * LANES + l], buf[(_SCALES + 2) * LANES + l]
    m00, m01, m02 = (_rotated(camera, 0, rq[0], rq[3], rq[6]) * s0, _rotated(camera, 0, rq[1], rq[4], rq[7]) * s1,
                     _rotated(camera, 0, rq[2], rq[5], rq[8]) * s2)
    m10, m11, m12 = (_rotated(camera, 1, rq[0], rq[3], rq[6]) * s0, _rotated(camera, 1, rq[1], rq[4], rq[7]) * s1,
                     _rotated(camera, 1, rq[2], rq[5], rq[8]) * s2)
    m20, m21, m22 = (_rotated(camera, 2, rq[0], rq[3], rq[6]) * s0, _rotated(camera, 2, rq[1], rq[4], rq[7]) * s1,
                     _rotated(camera, 2, rq[2], rq[5], rq[8]) * s2)
    a0, a1, a2 = fx / z * (m00 - tx * m20), fx / z * (m01 - tx * m21), fx / z * (m02 - tx * m22)
    b0, b1, b2 = fy / z * (m10 - ty * m20), fy / z * (m11 - ty * m21), fy / z * (m12 - ty * m22)
    a = a0 * a0 + a1 * a1 + a2 * a2 + low_pass
    b = a0 * b0 + a1 * b1 + a2 * b2
    c = b0 * b0 + b1 * b1 + b2 * b2 + low_pass
    c01, c02, c12 = a0 * b1 - a1 * b0, a0 * b2 - a2 * b0, a1 * b2 - a2 * b1
    det = c01 * c01 + c02 * c02 + c12 * c12 + low_pass * (a + c - low_pass)  # = a c - b^2
    return (a, b, c, det, (a0, a1, a2), (b0, b1, b2), (m00, m01, m02, m10, m11, m12, m20, m21, m22), rq,
            (w, x, y, zq, norm))


@njit(cache=True, error_model="numpy")
def _backward_lanes(buf, count, camera, width, height, low_pass, camera_grad):
    """:func:`project_backward` of one block's ``count`` live lanes in ``buf``: inputs to outputs, and the
    camera gradient added to its per-lane sums (a function of its own, as :func:`_forward_lanes`)."""
    cam = _as_tuple(camera)  # scalars in registers: the array could overlap buf as far as LLVM knows
    lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos = _limits(cam, width, height)
    fx, fy = cam[12], cam[13]
    for l in range(LANES):
        live = l < count
        drawn = live & (buf[_EXTRA * LANES + l] > 0.0)
        m0, m1, m2 = buf[_MEANS * LANES + l], buf[(_MEANS + 1) * LANES + l], buf[(_MEANS + 2) * LANES + l]
        p0 = _rotated(cam, 0, m0, m1, m2) + cam[9]
        p1 = _rotated(cam, 1, m0, m1, m2) + cam[10]
        p2 = _rotated(cam, 2, m0, m1, m2) + cam[11]
        z = p2 if drawn else 1.0
        xz, yz = p0 / z, p1 / z
        tx, ty = max(min(xz, lim_x_pos), -lim_x_neg), max(min(yz, lim_y_pos), -lim_y_neg)
        a, b, c, det, t0, t1, m, rq, unit = _screen_covariance(cam, buf, l, z, tx, ty, low_pass)
        # conic = (c, -b, a) / det with det = a c - b^2 (clamped at 1e-300: no gradient there).
        gA, gB, gC = buf[(_EXTRA + 3) * LANES + l], buf[(_EXTRA + 4) * LANES + l], buf[(_EXTRA + 5) * LANES + l]
        g_det = -(gA * c - gB * b + gC * a) / (det * det) if det > 1e-300 else 0.0
        det = max(det, 1e-300)
        g_a = gC / det + g_det * c
        g_b = -gB / det - 2.0 * g_det * b
        g_c = gA / det + g_det * a
        # a = t0.t0 + lp, b = t0.t1, c = t1.t1 + lp; t0 = (fx/z)(M0 - tx M2), t1 = (fy/z)(M1 - ty M2).
        g_t0 = (2.0 * g_a * t0[0] + g_b * t1[0], 2.0 * g_a * t0[1] + g_b * t1[1], 2.0 * g_a * t0[2] + g_b * t1[2])
        g_t1 = (2.0 * g_c * t1[0] + g_b * t0[0], 2.0 * g_c * t1[1] + g_b * t0[1], 2.0 * g_c * t1[2] + g_b * t0[2])
        sx, sy = fx / z, fy / z
        g_m = (sx * g_t0[0], sx * g_t0[1], sx * g_t0[2], sy * g_t1[0], sy * g_t1[1], sy * g_t1[2],
               -tx * sx * g_t0[0] - ty * sy * g_t1[0], -tx * sx * g_t0[1] - ty * sy * g_t1[1],
               -tx * sx * g_t0[2] - ty * sy * g_t1[2])
        g_tx = -(sx * g_t0[0] * m[6] + sx * g_t0[1] * m[7] + sx * g_t0[2] * m[8])
        g_ty = -(sy * g_t1[0] * m[6] + sy * g_t1[1] * m[7] + sy * g_t1[2] * m[8])
        g_s0 = (g_t0[0] * (m[0] - tx * m[6]) + g_t0[1] * (m[1] - tx * m[7]) + g_t0[2] * (m[2] - tx * m[8]))
        g_s1 = (g_t1[0] * (m[3] - ty * m[6]) + g_t1[1] * (m[4] - ty * m[7]) + g_t1[2] * (m[5] - ty * m[8]))
        # s0 = fx / z, s1 = fy / z; tx = clamp(x / z, -lim_x_neg, lim_x_pos), the limits depend on fx, cx
        # (tx = (width - cx + m width) / fx above, -(cx + m width) / fx below); u = fx x / z + cx.
        gu, gv = buf[(_EXTRA + 1) * LANES + l], buf[(_EXTRA + 2) * LANES + l]
        in_x, in_y = (-lim_x_neg < xz) & (xz < lim_x_pos), (-lim_y_neg < yz) & (yz < lim_y_pos)
        g_p = (g_tx / z + gu * fx / z if in_x else gu * fx / z,
               g_ty / z + gv * fy / z if in_y else gv * fy / z,
               -(g_s0 * fx + g_s1 * fy) / (z * z) - (g_tx * xz / z if in_x else 0.0)
               - (g_ty * yz / z if in_y else 0.0) - (gu * fx * xz + gv * fy * yz) / z)
        clamp_fx = 0.0 if in_x else (-g_tx * lim_x_pos / fx if xz >= lim_x_pos else g_tx * lim_x_neg / fx)
        clamp_fy = 0.0 if in_y else (-g_ty * lim_y_pos / fy if yz >= lim_y_pos else g_ty * lim_y_neg / fy)
        # M[i, j] = sum_k R[i, k] Rq[k, j] s_j.
        s = (buf[_SCALES * LANES + l], buf[(_SCALES + 1) * LANES + l], buf[(_SCALES + 2) * LANES + l])
        g_rq = (_rotated_t(cam, 0, g_m[0], g_m[3], g_m[6]) * s[0],
                _rotated_t(cam, 0, g_m[1], g_m[4], g_m[7]) * s[1],
                _rotated_t(cam, 0, g_m[2], g_m[5], g_m[8]) * s[2],
                _rotated_t(cam, 1, g_m[0], g_m[3], g_m[6]) * s[0],
                _rotated_t(cam, 1, g_m[1], g_m[4], g_m[7]) * s[1],
                _rotated_t(cam, 1, g_m[2], g_m[5], g_m[8]) * s[2],
                _rotated_t(cam, 2, g_m[0], g_m[3], g_m[6]) * s[0],
                _rotated_t(cam, 2, g_m[1], g_m[4], g_m[7]) * s[1],
                _rotated_t(cam, 2, g_m[2], g_m[5], g_m[8]) * s[2])
        # dL/ds_j = sum_i g_M[i, j] (R Rq)[i, j] (not g_M . M / s_j: s_j may be 0).
        g_s = (g_m[0] * _rotated(cam, 0, rq[0], rq[3], rq[6]) + g_m[3] * _rotated(cam, 1, rq[0], rq[3], rq[6])
               + g_m[6] * _rotated(cam, 2, rq[0], rq[3], rq[6]),
               g_m[1] * _rotated(cam, 0, rq[1], rq[4], rq[7]) + g_m[4] * _rotated(cam, 1, rq[1], rq[4], rq[7])
               + g_m[7] * _rotated(cam, 2, rq[1], rq[4], rq[7]),
               g_m[2] * _rotated(cam, 0, rq[2], rq[5], rq[8]) + g_m[5] * _rotated(cam, 1, rq[2], rq[5], rq[8])
               + g_m[8] * _rotated(cam, 2, rq[2], rq[5], rq[8]))
        # Rq of the unit quaternion (w, x, y, z), then the normalisation q / |q|.
        w, x, y, zq, norm = unit
        gw = 2.0 * (-zq * g_rq[1] + y * g_rq[2] + zq * g_rq[3] - x * g_rq[5] - y * g_rq[6] + x * g_rq[7])
        gx = 2.0 * (y * g_rq[1] + zq * g_rq[2] + y * g_rq[3] - 2.0 * x * g_rq[4] - w * g_rq[5]
                    + zq * g_rq[6] + w * g_rq[7] - 2.0 * x * g_rq[8])
        gy = 2.0 * (-2.0 * y * g_rq[0] + x * g_rq[1] + w * g_rq[2] + x * g_rq[3] + zq * g_rq[5]
                    - w * g_rq[6] + zq * g_rq[7] - 2.0 * y * g_rq[8])
        gz = 2.0 * (-2.0 * zq * g_rq[0] - w * g_rq[1] + x * g_rq[2] + w * g_rq[3] - 2.0 * zq * g_rq[4]
                    + y * g_rq[5] + x * g_rq[6] + y * g_rq[7])
        radial = w * gw + x * gx + y * gy + zq * gz
        turning = drawn & (norm > 0.0)
        safe_norm = norm if turning else 1.0
        g_q = ((gw - w * radial) / safe_norm, (gx - x * radial) / safe_norm, (gy - y * radial) / safe_norm,
               (gz - zq * radial) / safe_norm)
        # p = R m + t: the depth's gradient reaches every Gaussian, the rest only the drawn ones.
        gp0, gp1 = (g_p[0] if drawn else 0.0), (g_p[1] if drawn else 0.0)
        gp2 = buf[(_EXTRA + 6) * LANES + l] + (g_p[2] if drawn else 0.0)
        row = _BACKWARD_OUT * LANES + l
        buf[row] = _rotated_t(cam, 0, gp0, gp1, gp2)
        buf[row + LANES] = _rotated_t(cam, 1, gp0, gp1, gp2)
        buf[row + 2 * LANES] = _rotated_t(cam, 2, gp0, gp1, gp2)
        buf[row + 3 * LANES] = g_q[0] if turning else 0.0
        buf[row + 4 * LANES] = g_q[1] if turning else 0.0
        buf[row + 5 * LANES] = g_q[2] if turning else 0.0
        buf[row + 6 * LANES] = g_q[3] if turning else 0.0
        buf[row + 7 * LANES] = g_s[0] if drawn else 0.0
        buf[row + 8 * LANES] = g_s[1] if drawn else 0.0
        buf[row + 9 * LANES] = g_s[2] if drawn else 0.0
        if camera_grad:  # R (9), t (3), fx, fy, cx, cy, each lane's own sum
            row = _CAMERA * LANES + l
            for i in range(3):  # unrolled by the compiler: constant rows
                gp_i = gp0 if i == 0 else (gp1 if i == 1 else gp2)
                buf[row + (9 + i) * LANES] += gp_i if live else 0.0
                for k in range(3):
                    shape = (g_m[3 * i] * rq[3 * k] * s[0] + g_m[3 * i + 1] * rq[3 * k + 1] * s[1]
                             + g_m[3 * i + 2] * rq[3 * k + 2] * s[2])
                    centre = m0 if k == 0 else (m1 if k == 1 else m2)
                    buf[row + (3 * i + k) * LANES] += (shape if drawn else 0.0) + gp_i * centre if live else 0.0
            buf[row + 12 * LANES] += gu * xz + g_s0 / z + clamp_fx if drawn else 0.0
            buf[row + 13 * LANES] += gv * yz + g_s1 / z + clamp_fy if drawn else 0.0
            buf[row + 14 * LANES] += gu - (0.0 if in_x else g_tx / fx) if drawn else 0.0
            buf[row + 15 * LANES] += gv - (0.0 if in_y else g_ty / fy) if drawn else 0.0


@njit(cache=True, parallel=True)
def project_backward(means, quats, scales, camera, width, height, low_pass, valid, grad_means2d, grad_conics,
                     grad_depths, chunks, camera_grad):
    """Gradients of ``sum(means2d * g2d) + sum(conics * gc) + sum(depths * gz)`` w.r.t. means [N, 3],
    quats [N, 4], scales [N, 3] (in the means' dtype) and the camera ``[chunks, 16]`` (partial sums over
    ``chunks`` contiguous runs of blocks: R, t, fx, fy, cx, cy; summed per lane, then over the lanes). A fixed
    ``chunks`` (not the thread count) keeps the sums the same whatever the threads. ``camera_grad``
    False: the camera's are left at zero (a camera held fixed: ~50 sums per Gaussian spared)."""
    n, dtype = means.shape[0], means.dtype
    g_means, g_quats, g_scales = np.zeros((n, 3), dtype), np.zeros((n, 4), dtype), np.zeros((n, 3), dtype)
    g_camera = np.zeros((chunks, 16))
    upstream = np.empty((n, 7))  # the block's extra rows: valid, grad u, v, conic A, B, C, depth
    upstream[:, 0] = valid
    upstream[:, 1:3] = grad_means2d
    upstream[:, 3:6] = grad_conics
    upstream[:, 6] = grad_depths
    blocks = -(-n // LANES)
    for chunk in prange(chunks):
        buf = np.zeros((_CAMERA + 16) * LANES)
        for block in range(chunk * blocks // chunks, (chunk + 1) * blocks // chunks):
            g0 = block * LANES
            count = min(LANES, n - g0)
            _load_block(buf, g0, count, means, scales, quats, upstream)
            _backward_lanes(buf, count, camera, width, height, low_pass, camera_grad)
            for l in range(count):
                g, row = g0 + l, _BACKWARD_OUT * LANES + l
                for k in range(3):
                    g_means[g, k] = buf[row + k * LANES]
                    g_scales[g, k] = buf[row + (7 + k) * LANES]
                for k in range(4):
                    g_quats[g, k] = buf[row + (3 + k) * LANES]
        if camera_grad:
            for k in range(16):
                total = 0.0
                for l in range(LANES):
                    total += buf[(_CAMERA + k) * LANES + l]
                g_camera[chunk, k] = total
    return g_means, g_quats, g_scales, g_camera
