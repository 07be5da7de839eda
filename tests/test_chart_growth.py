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


def _searched(uv, skip):
    """Which of the grid points ``uv`` a round searches: those ``skip`` (matches kept from before) does not hold."""
    if skip is None or len(skip) == 0:
        return np.ones(len(uv), bool)
    return ~(np.abs(uv[:, None, :] - skip[None, :, :]).max(-1) < 1e-6).any(1)


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

    def match(predictor, skip=None):
        plane = not np.any(predictor.coefficients[plane_only])
        tried.append("plane" if plane else "other")
        keep = (np.arange(len(uv)) < (len(uv) if plane else first_count)) & _searched(uv, None if skip is None else skip.uv_a)
        return _matches(uv[keep], _truth(chart, uv)[keep])

    first = _matches(uv[:first_count], _truth(chart, uv)[:first_count])
    grown, rounds = grow_first_guess((chart,), first, match, lambda m: m, min_matches=20, scale_px=1.0)
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

    def match(predictor, skip=None):
        predicted = predictor(uv)[0]
        truth = _truth(chart, uv)
        near = (np.linalg.norm(predicted - truth, axis=1) <= search) & _searched(uv, None if skip is None else skip.uv_a)
        return _matches(uv[near], truth[near])

    return match


def test_growth_reaches_the_skin_the_chart_alone_missed(chart):
    match = _matcher(chart, search=4.0)
    first = match(chart)
    grown, rounds = grow_first_guess((chart,), first, match, lambda m: m, min_matches=20, scale_px=1.0)
    total = len(_grid())
    assert len(first) < 0.8 * total  # the chart alone reaches the middle only
    assert len(grown) > 0.97 * total and 1 <= rounds <= GROWTH_ROUNDS


def test_a_chart_that_was_right_is_not_grown(chart):
    uv = _grid()
    first = _matches(uv, chart(uv)[0])
    def match(predictor, skip=None):
        searched = _searched(uv, None if skip is None else skip.uv_a)
        return _matches(uv[searched], predictor(uv[searched])[0])

    grown, rounds = grow_first_guess((chart,), first, match, lambda m: m, min_matches=20, scale_px=1.0)
    assert rounds == 0 and grown is first


def test_a_pair_the_chart_did_not_register_is_not_grown(chart):
    match = _matcher(chart, search=4.0)
    first = match(chart)
    grown, rounds = grow_first_guess((chart,), first, match, lambda m: m, min_matches=len(first) + 1, scale_px=1.0)
    assert rounds == 0 and grown is first


def test_a_pair_matched_both_ways_grows_each_way_in_its_own_views_chart(chart):
    """Both ways (``RegistrationConfig.first_guess_both_ways``): a grid on b is predicted in a through the inverse
    shift, and its correction is learned from the same matches read from b (in b's chart coordinates)."""
    back = ChartPredictor(chart.chart_b, chart.chart_a, ChartShift(-chart.shift.turn, -chart.shift.d_sigma, 50, 200, 3.0))
    on_a = _grid()
    from_b = _grid() + 3.0  # skin points of a whose true places in b make b's grid
    on_b = _truth(chart, from_b)
    search = 4.0

    def match(forward, backward, skip=None):
        near_b = ((np.linalg.norm(forward(on_a)[0] - _truth(chart, on_a), axis=1) <= search)
                  & _searched(on_a, None if skip is None else skip.uv_a))
        near_a = ((np.linalg.norm(backward(on_b)[0] - from_b, axis=1) <= search)
                  & _searched(on_b, None if skip is None else skip.uv_b))
        return _matches(on_a[near_b], _truth(chart, on_a)[near_b]).joined(_matches(on_b[near_a], from_b[near_a]).swapped())

    first = match(chart, back)
    reached_back = np.isin(first.uv_b[:, 0], on_b[:, 0]).sum()
    assert reached_back < 0.8 * len(on_b)  # the inverse chart misses the flanks as the chart does
    grown, rounds = grow_first_guess((chart, back), first, match, lambda m: m, min_matches=20, scale_px=1.0)
    assert len(grown) > 0.97 * (len(on_a) + len(on_b)) and 1 <= rounds <= GROWTH_ROUNDS


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_robust_fit_reaches_scipys_cauchy_least_squares(chart, seed):
    """The correction's own reweighted least squares against scipy's trust region on the same loss (its reference)."""
    from scipy.optimize import least_squares

    from fingersplat3d.align.correspond.chart_growth import _cauchy_least_squares

    rng = np.random.default_rng(seed)
    design = np.column_stack([np.ones(300), rng.normal(size=(300, 4))])
    target = design @ rng.normal(size=(5, 2)) + rng.normal(0.0, 0.3, (300, 2))
    target[rng.random(300) < 0.25] += rng.uniform(5.0, 20.0, 2)  # a quarter of the matches wrong
    start = np.linalg.lstsq(design, target, rcond=None)[0]
    ours = _cauchy_least_squares(design, target, start, 1.0)
    reference = least_squares(lambda flat: (design @ flat.reshape(5, 2) - target).ravel(), start.ravel(),
                              jac=lambda flat: np.kron(design, np.eye(2)), loss="cauchy", f_scale=1.0, method="trf",
                              xtol=1e-12, ftol=1e-12, gtol=1e-12).x.reshape(5, 2)
    np.testing.assert_allclose(ours, reference, atol=1e-6)

    def loss(x):
        return np.log1p(((design @ x - target) / 1.0) ** 2).sum()

    assert loss(ours) <= loss(reference) + 1e-9 and loss(ours) < loss(start)
