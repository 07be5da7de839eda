"""Cylinder charts and the turn between two views voted from their unwrapped ridge textures."""
import numpy as np
import pytest

from fingersplat3d.align.correspond.chart import CylinderChart
from fingersplat3d.align.correspond.chart_shift import RIVAL_TURN_DEG, chart_shift_candidates, estimate_chart_shift
from fingersplat3d.align.correspond.texture import estimate_ridge_period, ridge_texture
from fingersplat3d.eval.poses import rotation_angle_deg
from fingersplat3d.synth import SynthConfig, synthesize


def capsule(rows=160, cols=400, radius=50, tip=80):
    """A horizontal capsule cut by the right border, tip to the left."""
    v, u = np.mgrid[:rows, :cols]
    return ((np.abs(v - rows // 2) <= radius) & (u >= tip)) | ((u - tip) ** 2 + (v - rows // 2) ** 2 <= radius ** 2)


def test_chart_finds_the_tip_and_inverts_itself():
    chart = CylinderChart.from_mask(capsule())
    assert chart.frame.tip_found and chart.frame.axis[0] < -0.99  # the tip is at the left
    rng = np.random.default_rng(0)
    sigma, theta = rng.uniform(60, 250, 200), rng.uniform(-1.2, 1.2, 200)
    back_sigma, back_theta = chart.surface(chart.pixels(sigma, theta))
    np.testing.assert_allclose(back_sigma, sigma, atol=1e-9)
    np.testing.assert_allclose(back_theta, theta, atol=1e-6)
    assert chart.radius == pytest.approx(50.5, abs=1.0)


def test_unwrapped_grid_is_centred_on_the_line_of_sight():
    mask = capsule()
    chart = CylinderChart.from_mask(mask)
    unwrapped = chart.unwrap(mask.astype(np.float32), mask, step=2.0)
    middle = (unwrapped.image.shape[0] - 1) / 2
    assert unwrapped.angle(middle) == 0.0 and unwrapped.valid[int(middle)].sum() > 0.6 * unwrapped.valid.shape[1]
    assert not unwrapped.valid[0].any() and not unwrapped.valid[-1].any()  # beyond 75 degrees: left out


@pytest.fixture(scope="module")
def finger():
    return synthesize(3, SynthConfig(size=(640, 512))).capture


def _unwrapped(view, period):
    chart = CylinderChart.from_mask(view.mask)
    return chart.unwrap(ridge_texture(view.image, view.mask, period), view.mask, max(1.0, period / 8))


def test_turn_between_views_45_degrees_apart_is_found(finger):
    period = estimate_ridge_period(finger["center"].image, finger["center"].mask)
    for name in ("left", "right"):
        shift = estimate_chart_shift(_unwrapped(finger["center"], period), _unwrapped(finger[name], period), period)
        truth = rotation_angle_deg(finger[name].camera.rotation, finger["center"].camera.rotation)
        assert shift is not None and shift.decisive
        assert abs(abs(np.degrees(shift.turn)) - truth) < 10.0  # a first guess: the cylinder is only a circle
    left = estimate_chart_shift(_unwrapped(finger["center"], period), _unwrapped(finger["left"], period), period)
    right = estimate_chart_shift(_unwrapped(finger["center"], period), _unwrapped(finger["right"], period), period)
    assert np.sign(left.turn) == -np.sign(right.turn)


def test_different_fingers_do_not_give_a_decisive_turn(finger):
    other = synthesize(4, SynthConfig(size=(640, 512))).capture
    period = estimate_ridge_period(finger["center"].image, finger["center"].mask)
    shift = estimate_chart_shift(_unwrapped(finger["center"], period), _unwrapped(other["left"], period), period)
    assert shift is None or not shift.decisive


def test_the_vote_s_further_peaks_come_after_its_first(finger):
    """The peaks an undecided vote is tried at: the first is the vote's own shift, the others lower and each beyond
    the rival reach of the ones before it (a turn RIVAL_TURN_DEG away, or a d_sigma 3 bins away)."""
    period = estimate_ridge_period(finger["center"].image, finger["center"].mask)
    a, b = _unwrapped(finger["center"], period), _unwrapped(finger["left"], period)
    peaks = chart_shift_candidates(a, b, period, 4)
    assert 2 <= len(peaks) <= 4 and peaks[0] == estimate_chart_shift(a, b, period)
    assert peaks[0].ratio >= 1.0 and all(peak.ratio < 1.0 for peak in peaks[1:])
    bin_size = max(1.0, 0.45 * period / a.step)
    for i, later in enumerate(peaks):
        for earlier in peaks[:i]:
            apart_turn = abs(np.degrees(later.turn - earlier.turn)) > RIVAL_TURN_DEG - 3.0  # peaks sit in bins
            apart_sigma = abs(later.d_sigma - earlier.d_sigma) > 2.0 * bin_size * a.step
            assert apart_turn or apart_sigma
    assert chart_shift_candidates(a, b, period, 1) == peaks[:1]


def _rod(length: int, width: int = 100, frame=(2000, 400)) -> np.ndarray:
    """A finger silhouette: a rounded tip at column 100, running ``length`` px to the right (past the frame's edge
    when longer than it)."""
    mask = np.zeros((frame[1], frame[0]), bool)
    rows, cols = np.indices(mask.shape)
    centre, half = frame[1] // 2, width // 2
    body = (np.abs(rows - centre) <= half) & (cols >= 100 + half) & (cols < 100 + length)
    cap = (rows - centre) ** 2 + (cols - (100 + half)) ** 2 <= half ** 2
    return body | cap


def test_only_the_ridge_area_votes_where_most_of_the_finger_in_view_has_no_ridges():
    from fingersplat3d.align.correspond.chart_shift import RIDGE_VOTE_SHARE, vote_area
    from fingersplat3d.align.correspond.texture import RIDGE_AREA_WIDTHS

    long = _rod(5000)  # runs out of the frame: 19 widths in view, its ridges within 1.4 of the tip
    area = vote_area(long)
    assert area.sum() < RIDGE_VOTE_SHARE * long.sum() and not (area & ~long).any()
    cols = np.nonzero(area)[1]
    assert cols.min() == 100 and cols.max() < 100 + (RIDGE_AREA_WIDTHS + 0.2) * 100  # the tip's end
    short = _rod(220)  # a distal phalanx filling the view: every patch votes, as before
    assert (vote_area(short) == short).all()
    no_tip = np.zeros((400, 2000), bool)
    no_tip[150:250, :] = True  # cut at both ends: no tip to reckon the ridges from
    assert (vote_area(no_tip) == no_tip).all()


def test_a_chart_too_short_for_a_patch_gives_no_vote():
    """A view whose unwrapped texture is shorter across than one patch (a thin sliver of a view, a finger the frame
    cuts to a few rows): no patch of the other view is scored in it, and the vote says so without an error (a close-up
    of another make 18 mm across ended in OpenCV's size assertion)."""
    from fingersplat3d.align.correspond.chart import Unwrapped

    rng = np.random.default_rng(0)
    tall = Unwrapped(rng.random((120, 200), dtype=np.float32), np.ones((120, 200), bool), 60.0, 1.0)
    short = Unwrapped(rng.random((12, 200), dtype=np.float32), np.ones((12, 200), bool), 6.0, 1.0)
    assert estimate_chart_shift(tall, short, 10.0) is None
    assert chart_shift_candidates(short, tall, 10.0, 2) == []  # and none of its own to place
