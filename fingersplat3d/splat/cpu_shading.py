"""The facing cosines of :mod:`.shading` on the CPU (numba): one pass over the Gaussians.

:func:`.shading.facing_cosines` in tensor operations costs ~30 of them per render, each a pass over the Gaussians
with its own allocation; at the fit's 50k Gaussians that was 7 ms a step on 2 cores (6 % of a ``balanced`` step),
here 0.7 ms with the conversions (measured on a Zen 3 EPYC, docs/measurements.md, stop 48). The same formula: the
unit quaternion's rotation column of the smallest log-scale (the first smallest, as ``argmin``), ``|n . d| / |d|``
with ``d`` from the centre to the camera, 1 where that is not finite, held in ``[MIN_FACING, 1]``; float64 inside.
``tests/test_shading.py`` checks it against the tensor version.
Pure numpy in, numpy out.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .cpu_project import _finite, _quaternion_matrix, _unit_quaternion

__all__ = ["facing_cosines_cpu"]

_TINY = np.finfo(np.float64).tiny


@njit(cache=True, parallel=True, error_model="numpy")
def _facing(means, quats, log_scales, centre, low, out):
    for g in prange(means.shape[0]):
        w, x, y, z, _ = _unit_quaternion(float(quats[g, 0]), float(quats[g, 1]), float(quats[g, 2]), float(quats[g, 3]))
        r = _quaternion_matrix(w, x, y, z)  # row-major: column k is (r[k], r[3 + k], r[6 + k])
        k = 0
        if log_scales[g, 1] < log_scales[g, k]:
            k = 1
        if log_scales[g, 2] < log_scales[g, k]:
            k = 2
        n0, n1, n2 = (r[0], r[3], r[6]) if k == 0 else ((r[1], r[4], r[7]) if k == 1 else (r[2], r[5], r[8]))
        d0, d1, d2 = centre[0] - means[g, 0], centre[1] - means[g, 1], centre[2] - means[g, 2]
        length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        cosine = abs(n0 * d0 + n1 * d1 + n2 * d2) / max(length, _TINY)
        out[g] = min(max(cosine, low), 1.0) if _finite(cosine) else 1.0


def facing_cosines_cpu(means: np.ndarray, quats: np.ndarray, log_scales: np.ndarray, centre: np.ndarray,
                       min_facing: float) -> np.ndarray:
    """``[N]`` float64 cosines (see the module docstring); ``centre`` the camera's centre ``[3]``."""
    out = np.empty(means.shape[0])
    if len(out):
        _facing(np.ascontiguousarray(means), np.ascontiguousarray(quats), np.ascontiguousarray(log_scales),
                np.asarray(centre, np.float64), float(min_facing), out)
    return out
