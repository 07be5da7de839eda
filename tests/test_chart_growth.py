"""A pair's first guess grown through its charts corrected by the matches they gave (align/correspond/chart_growth.py)."""
import numpy as np
import pytest

from fingersplat3d.align.correspond.chart import CylinderChart
from fingersplat3d.align.correspond.chart_growth import (CORRECTIONS, FEW_MATCHES, GROWTH_ROUNDS,
                                                          CorrectedChartPredictor, fit_chart_correction, grow_first_guess)
from fingersplat3d.align.correspond.chart_shift import ChartPredictor, ChartShift
from fingersplat3d.align.correspond.guided import GuidedMatches


def capsule(rows=200, cols=420, radius=70, tip=90):
    """A horizontal capsule cut by the right border, tip to the left."""
    v, u = np.mgrid[:rows, :cols]
    return ((np.abs(v - rows // 2) <= radius) & (u >= tip)) | ((u - tip) ** 2 + (v - rows // 2) ** 2 <= radius ** 2)


@pytest.fixture(scope="module")
def chart():
    a = CylinderChart.from_mask(capsule())
    b = CylinderChart.from_mask(capsule(radius=64))
    return ChartPredictor(a, b, ChartShift(np.radians(20.0), 3.0, 50, 200, 3.0))


def _grid(step=6.0):
    v, u = np.mgrid[40:160:step, 110:400:step]
    return np.column_stack([u.ravel(), v.ravel()]).astype(np.float64)


def _truth(chart, uv):
    """Where a skin point really lies in b: the chart's guess off by a smooth error that grows toward the flanks (a
    flat section read as a circle), up to ~8 px."""
    sigma, theta = chart.chart_a.surface(uv)
    error = np.column_stack([0.8 * sigma / chart.chart_a.radius, 9.0 * theta ** 3 - 2.0 * theta])
    return chart(uv)[0] + error


def _matches(uv_a, uv_b):
    identity = np.broadcast_to(np.eye(2), (len(uv_a), 2, 2)).copy()
    return GuidedMatches(uv_a, uv_b, np.ones(len(uv_a)), identity, identity.copy())


def test_the_correction_is_learned_from_the_matches_despite_wrong_ones(chart):
    uv = _grid()
    rng = np.random.default_rng(0)
    found = _truth(chart, uv) + rng.normal(0.0, 0.3, uv.shape)
    wrong = rng.random(len(uv)) < 0.2
    found[wrong] += np.array([11.0, 0.0])  # a ridge period off, all one way: plain least squares would follow them
    coefficients = fit_chart_correction(chart, uv, found, scale_px=1.0)
    corrected = CorrectedChartPredictor(chart, coefficients)
    probe = _grid(step=9.0)
    miss = np.linalg.norm(corrected(probe)[0] - _truth(chart, probe), axis=1)
    assert np.median(miss) < 0.5 and miss.max() < 2.0  # the chart alone: up to ~8 px
    assert np.median(np.linalg.norm(chart(probe)[0] - _truth(chart, probe), axis=1)) > 3.0
    np.testing.assert_array_equal(corrected(probe)[1], chart(probe)[1])  # what b sees is the chart's call


def test_a_correction_uses_only_its_own_terms(chart):
    uv = _grid()
    found = _truth(chart, uv)
    for use in CORRECTIONS.values():
        coefficients = fit_chart_correction(chart, uv, found, scale_px=1.0, use=use)
        unused = np.setdiff1d(np.arange(len(coefficients)), use)
        assert not np.any(coefficients[unused]) and np.all(np.isfinite(coefficients))
    # the truth's error is cubic in the surface angle: the cubic fits it best, the plane worst
    misses = {name: np.median(np.linalg.norm(CorrectedChartPredictor(chart, fit_chart_correction(
        chart, uv, found, 1.0, use))(uv)[0] - found, axis=1)) for name, use in CORRECTIONS.items()}
    assert misses["cubic"] < 0.1 < misses["plane"]


@pytest.mark.parametrize("first_count", [60, FEW_MATCHES])
def test_a_pair_of_few_matches_is_grown_through_a_lower_correction_where_the_cubic_fails(chart, first_count):
    """Which correction reaches farther is told by matching through it (a wide pair's first matches lie in a band the
    cubic can swing off beyond): here only the plane's matches verify. With few first matches the growth tries it
    after the cubic and follows it; with many, it stops at the cubic (each correction tried costs a matching)."""
    uv = _grid()
    plane_only = np.setdiff1d(np.arange(7), CORRECTIONS["plane"])
    tried = []

    def match(predictor):
        plane = not np.any(predictor.coefficients[plane_only])
        tried.append("plane" if plane else "other")
        keep = np.arange(len(uv)) < (len(uv) if plane else first_count)
        return _matches(uv[keep], _truth(chart, uv)[keep])

    first = _matches(uv[:first_count], _truth(chart, uv)[:first_count])
    grown, rounds = grow_first_guess(chart, first, match, lambda m: m, min_matches=20, scale_px=1.0)
    if first_count < FEW_MATCHES:
        assert len(grown) == len(uv) and rounds == 1
        assert tried == ["other", "plane", "other"]  # the cubic, then the plane, which grew; round 2 has many: the cubic
    else:
        assert grown is first and rounds == 0 and tried == ["other"]


def test_too_few_matches_leave_the_chart_as_it_is(chart):
    uv = _grid()[:10]
    assert not np.any(fit_chart_correction(chart, uv, _truth(chart, uv), scale_px=1.0))


def _matcher(chart, search=12.0):
    """Guided matching in miniature: a grid point is matched (at its true place) when the prediction lies within
    ``search`` px of it."""
    uv = _grid()

    def match(predictor):
        predicted = predictor(uv)[0]
        truth = _truth(chart, uv)
        near = np.linalg.norm(predicted - truth, axis=1) <= search
        return _matches(uv[near], truth[near])

    return match


def test_growth_reaches_the_skin_the_chart_alone_missed(chart):
    match = _matcher(chart, search=4.0)
    first = match(chart)
    grown, rounds = grow_first_guess(chart, first, match, lambda m: m, min_matches=20, scale_px=1.0)
    total = len(_grid())
    assert len(first) < 0.8 * total  # the chart alone reaches the middle only
    assert len(grown) > 0.97 * total and 1 <= rounds <= GROWTH_ROUNDS


def test_a_chart_that_was_right_is_not_grown(chart):
    uv = _grid()
    first = _matches(uv, chart(uv)[0])
    grown, rounds = grow_first_guess(chart, first, lambda predictor: _matches(uv, predictor(uv)[0]), lambda m: m,
                                     min_matches=20, scale_px=1.0)
    assert rounds == 0 and grown is first


def test_a_pair_the_chart_did_not_register_is_not_grown(chart):
    match = _matcher(chart, search=4.0)
    first = match(chart)
    grown, rounds = grow_first_guess(chart, first, match, lambda m: m, min_matches=len(first) + 1, scale_px=1.0)
    assert rounds == 0 and grown is first
