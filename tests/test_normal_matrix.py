"""The alignment's Gauss-Newton matrix JᵀJ (numba): scipy's product, to the bit where no row repeats a column,
whatever the threads."""
import numpy as np
import pytest
import scipy.sparse as sparse

from fingersplat3d.align.solve.normal_matrix import normal_matrix


def _jacobian(seed: int) -> sparse.csr_matrix:
    """A Jacobian like the alignment's: a few dozen entries a row over a few hundred columns, rows with a column twice
    (summed by any product, as a Jacobian's repeated entries must be), empty rows and empty columns."""
    rng = np.random.default_rng(seed)
    rows, cols = 500, 120
    counts = rng.integers(0, 25, rows)
    indptr = np.concatenate([[0], np.cumsum(counts)])
    indices = rng.integers(0, cols - 5, indptr[-1])  # the last 5 columns stay empty
    data = rng.normal(size=indptr[-1]) * np.exp(rng.normal(scale=3.0, size=indptr[-1]))
    return sparse.csr_matrix((data, indices, indptr), shape=(rows, cols))


@pytest.mark.parametrize("threads", ["1", "2"])
def test_equals_scipys_product_to_the_bit(monkeypatch, threads):
    monkeypatch.setenv("FS3D_THREADS", threads)
    for seed in range(3):
        jacobian = _jacobian(seed)
        assert any(len(set(row.indices)) < row.nnz for row in jacobian)  # repeated columns are there
        expected = (jacobian.T @ jacobian).toarray()
        result = normal_matrix(jacobian)
        assert result.shape == expected.shape and result.dtype == np.float64
        assert np.array_equal(result, result.T)
        # a repeated column's products are summed in another order: rounding only
        np.testing.assert_allclose(result, expected, rtol=1e-13, atol=1e-13 * np.abs(expected).max())
        jacobian.sum_duplicates()  # as the alignment's rows are: the same sums in the same order
        assert np.array_equal(normal_matrix(jacobian), (jacobian.T @ jacobian).toarray())


def test_extremes_stay_as_scipys():
    jacobian = _jacobian(4).tolil()
    jacobian[0, 0], jacobian[1, 3], jacobian[1, 4] = 1e300, np.inf, np.nan
    jacobian = jacobian.tocsr()
    jacobian.sum_duplicates()
    expected = (jacobian.T @ jacobian).toarray()
    np.testing.assert_array_equal(normal_matrix(jacobian), expected)  # inf and NaN where scipy has them, nowhere else
    assert normal_matrix(sparse.csr_matrix((0, 7))).shape == (7, 7)
