"""``JᵀJ`` of a sparse Jacobian as a dense matrix (numba): the Gauss-Newton matrix of every Levenberg-Marquardt step
of the alignment (:mod:`.levenberg`).

Why not scipy's sparse product: ``(J.T @ J).toarray()`` sizes the product in one pass, fills it in a second, forms
both triangles and converts to dense after, all in one thread: 0.24 s a step at ten views' 2,000 unknowns (8 s of a
ten-view registration), 14 ms at three. Here only the upper triangle is summed, straight into the dense matrix, the
column pairs of each row split between the threads by their first column (no two threads write one entry), and
mirrored: 0.08 s and 4.5 ms on 2 cores. Every entry is summed over the rows in the same order as scipy's, so the
result is the same to the bit where no row repeats a column (the alignment's: measured on real and ten-view systems),
to rounding where one does, and the same whatever the thread count.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
from numba import njit, prange

from ...device import numba_threads

__all__ = ["normal_matrix"]


@njit(cache=True, parallel=True)
def _upper_gram(indptr, indices, data, size, parts):
    out = np.zeros((size, size))
    for part in prange(parts):
        for r in range(indptr.shape[0] - 1):
            lo, hi = indptr[r], indptr[r + 1]
            for i in range(lo, hi):
                ci = indices[i]
                if ci % parts != part:
                    continue
                di = data[i]
                for j in range(lo, hi):
                    cj = indices[j]
                    if cj >= ci:
                        out[ci, cj] += di * data[j]
    for a in prange(size):
        for b in range(a):
            out[a, b] = out[b, a]
    return out


def normal_matrix(jacobian: sparse.spmatrix) -> np.ndarray:
    """``JᵀJ`` ``[n, n]`` float64, dense, of a sparse ``[m, n]`` Jacobian."""
    csr = sparse.csr_matrix(jacobian)
    return _upper_gram(csr.indptr.astype(np.int64), csr.indices.astype(np.int64), csr.data.astype(np.float64),
                       csr.shape[1], numba_threads())
