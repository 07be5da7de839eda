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


def test_the_knots_count_across_the_finger_on_a_crop_shorter_along_it_than_across():
    """A finger band the frame cuts at both ends, 60 px along it and 160 px across: the knots are spaced by its width
    (the widest disc), not by its box's short side (its length), which would make its field four times as dense; a
    whole finger keeps its box's short side exactly (its width within CROP_WIDER)."""
    from fingersplat3d.align.solve.depth_field import CROP_WIDER

    band = np.zeros((300, 60), bool)
    band[70:230] = True  # rows across the finger, cut by the left and right borders
    crop = FieldGrid.covering(band, 8)
    assert abs(crop.spacing - 159 / 8) <= 1.0
    finger = np.zeros((200, 400), bool)
    v, u = np.mgrid[:200, :400]
    finger[(np.abs(v - 100) <= 50) & (u >= 80) | ((u - 80) ** 2 + (v - 100) ** 2 <= 50 ** 2)] = True
    whole = FieldGrid.covering(finger, 8)
    assert whole.spacing == 100 / 8 and CROP_WIDER > 1.0
