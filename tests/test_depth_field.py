"""Cubic B-spline depth-correction fields: partition of unity, dense = sparse, bending of a plane is zero."""
import numpy as np

from fingersplat3d.align.solve.depth_field import FieldGrid


def grid():
    mask = np.zeros((60, 80), bool)
    mask[10:50, 5:70] = True
    return FieldGrid.covering(mask, 4), mask


def test_weights_sum_to_one_and_dense_agrees_with_the_sparse_basis():
    field, mask = grid()
    coefficients = np.random.default_rng(0).normal(size=field.size)
    rows, cols = np.mgrid[0:60, 0:80]
    basis = field.basis(np.stack([cols.ravel(), rows.ravel()], 1).astype(float))
    np.testing.assert_allclose(basis.weight.sum(1), 1.0, atol=1e-12)
    np.testing.assert_allclose(field.dense(coefficients, mask.shape), basis.evaluate(coefficients).reshape(60, 80), atol=1e-12)


def test_bending_of_linear_coefficients_is_zero_and_of_a_bump_is_not():
    field, _ = grid()
    triples, weights = field.bending()
    gy, gx = field.shape
    plane = (2.0 * np.arange(gy)[:, None] - 3.0 * np.arange(gx)[None, :]).ravel()
    assert np.abs((plane[triples] * weights).sum(1)).max() < 1e-12
    bump = np.zeros(field.size)
    bump[field.size // 2] = 1.0
    assert np.abs((bump[triples] * weights).sum(1)).max() == 2.0
