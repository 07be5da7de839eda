"""The least turn two views' silhouette widths allow, and the hinge rows that keep the alignment to it."""
import numpy as np
import pytest

from fingersplat3d.align.width_check import WIDTH_TOLERANCE, turn_lower_bounds_deg, typical_half_width


def test_bounds_follow_the_narrowing_of_a_flat_board():
    bounds = turn_lower_bounds_deg([100.0, 100.0 * np.cos(np.radians(40)), 100.0], [1.0, 1.0, 1.0], [1000.0] * 3)
    assert np.allclose(bounds, bounds.T, equal_nan=True) and bounds[0, 0] == 0.0
    expected = np.degrees(np.arccos((1 + WIDTH_TOLERANCE) * np.cos(np.radians(40))))
    assert bounds[0, 1] == pytest.approx(expected) and 36.0 < expected < 40.0
    assert bounds[0, 2] == 0.0  # equal widths (within the tolerance) allow any turn
    assert np.isnan(bounds[1, 2])  # neither is the widest view: no bound


def _ellipse_half_width(roll_deg: np.ndarray, depth_ratio: float) -> np.ndarray:
    """Half-width of an elliptic section (half-axes 1 across, ``depth_ratio`` deep) seen after turning by ``roll_deg``."""
    roll = np.radians(roll_deg)
    return np.sqrt(np.cos(roll) ** 2 + (depth_ratio * np.sin(roll)) ** 2)


@pytest.mark.parametrize("depth_ratio", [0.3, 0.5, 0.8, 1.0])
def test_the_bounds_hold_for_flat_and_round_sections_seen_from_any_rolls(depth_ratio):
    rng = np.random.default_rng(int(depth_ratio * 10))
    for _ in range(50):
        # One view near the section's front (its width function is flat there: a view 5 degrees off still reads its
        # chord nearly level, and the bound may overshoot by up to a degree), the others anywhere.
        front = rng.uniform(-5, 5)
        rolls = np.concatenate([[front], rng.uniform(-60, 60, 4)])
        bounds = turn_lower_bounds_deg(_ellipse_half_width(rolls, depth_ratio), np.ones(5), np.full(5, 1000.0))
        true = np.abs(rolls[:, None] - rolls[None, :])
        bounded = np.isfinite(bounds)
        assert np.all(bounds[bounded] <= true[bounded] + 1.0)
        exact = turn_lower_bounds_deg(_ellipse_half_width(rolls - front, depth_ratio), np.ones(5), np.full(5, 1000.0))
        assert np.all(exact[np.isfinite(exact)] <= true[np.isfinite(exact)] + 1e-9)  # the widest view at the front


def test_only_the_widest_view_bounds_its_turns():
    """Of two oblique views of a flat section, the wider one's rims are at different depths: ``acos(w_b / w_a)`` can
    exceed their true turn (here -38 and -45 degrees, 7 apart, whose widths alone would say at least 17)."""
    rolls = np.array([0.0, -38.0, -45.0])
    widths = _ellipse_half_width(rolls, 0.35)
    assert np.degrees(np.arccos((1 + WIDTH_TOLERANCE) * widths[2] / widths[1])) > 7.0 + 5.0
    bounds = turn_lower_bounds_deg(widths, np.ones(3), np.full(3, 1000.0))
    assert np.isnan(bounds[1, 2]) and 0.0 < bounds[0, 1] <= 38.0 and 0.0 < bounds[0, 2] <= 45.0


def test_widths_are_compared_in_scene_units():
    """A view twice as far (same focal) shows the same finger half as wide: no bound."""
    assert turn_lower_bounds_deg([100.0, 50.0], [1.0, 2.0], [800.0, 800.0])[0, 1] == 0.0
    assert turn_lower_bounds_deg([100.0, 50.0], [1.0, 1.0], [800.0, 800.0])[0, 1] > 55.0


def test_bad_widths_give_no_bound():
    bounds = turn_lower_bounds_deg([100.0, 0.0, np.nan, 80.0], [1.0, 1.0, 1.0, np.inf], [500.0] * 4)
    assert np.isnan(bounds[0, 1]) and np.isnan(bounds[0, 2]) and np.isnan(bounds[0, 3])
    assert np.isnan(turn_lower_bounds_deg([0.0, np.nan], [1.0, 1.0], [500.0] * 2)).all()


def test_typical_half_width_skips_the_tip_cap():
    v, u = np.mgrid[:160, :400]
    capsule = ((np.abs(v - 80) <= 50) & (u >= 80)) | ((u - 80) ** 2 + (v - 80) ** 2 <= 50 ** 2)
    assert typical_half_width(capsule) == pytest.approx(50.5, abs=1.0)
