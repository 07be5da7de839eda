"""The least turn two views' silhouette widths allow, and the hinge rows that keep the alignment to it."""
import numpy as np
import pytest

from fingersplat3d.align.width_check import WIDTH_TOLERANCE, turn_lower_bounds_deg, typical_half_width


def test_bounds_follow_the_narrowing_of_a_flat_board():
    bounds = turn_lower_bounds_deg([100.0, 100.0 * np.cos(np.radians(40)), 100.0], [1.0, 1.0, 1.0], [1000.0] * 3)
    assert np.allclose(bounds, bounds.T) and np.allclose(np.diag(bounds), 0.0)
    expected = np.degrees(np.arccos((1 + WIDTH_TOLERANCE) * np.cos(np.radians(40))))
    assert bounds[0, 1] == pytest.approx(expected) and 36.0 < expected < 40.0
    assert bounds[0, 2] == 0.0  # equal widths (within the tolerance) allow any turn


def test_widths_are_compared_in_scene_units():
    """A view twice as far (same focal) shows the same finger half as wide: no bound."""
    assert turn_lower_bounds_deg([100.0, 50.0], [1.0, 2.0], [800.0, 800.0])[0, 1] == 0.0
    assert turn_lower_bounds_deg([100.0, 50.0], [1.0, 1.0], [800.0, 800.0])[0, 1] > 55.0


def test_bad_widths_give_no_bound():
    bounds = turn_lower_bounds_deg([100.0, 0.0, np.nan, 80.0], [1.0, 1.0, 1.0, np.inf], [500.0] * 4)
    assert np.isnan(bounds[0, 1]) and np.isnan(bounds[0, 2]) and np.isnan(bounds[0, 3])


def test_typical_half_width_skips_the_tip_cap():
    v, u = np.mgrid[:160, :400]
    capsule = ((np.abs(v - 80) <= 50) & (u >= 80)) | ((u - 80) ** 2 + (v - 80) ** 2 <= 50 ** 2)
    assert typical_half_width(capsule) == pytest.approx(50.5, abs=1.0)
