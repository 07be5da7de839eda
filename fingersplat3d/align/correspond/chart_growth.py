"""A pair's first guess grown past its cylinder charts: the charts' error learned from the matches they gave.

A chart (:mod:`~fingersplat3d.align.correspond.chart`) reads a view as a circle's section, so its prediction of where a
skin point lies in the other view is only right where the finger is round. On a flat finger (another group's renders,
a section about 0.35 as deep as wide) it compresses the turn across the pad and stretches it toward the flanks: the
chart's turn between rolls -18 and 0 reads -10 degrees, and a pair 47 or 65 degrees apart finds only 70-90 verified
first-guess matches in the middle of its overlap. The first alignment of such a capture then follows the close pair's
many matches (about 2,000) and the wide pair's few, slightly wrong ones, its relief comes out twice too deep, and the
wide view ends 10-20 degrees off and unregistered (14 of the 84 triplets of the IMPOSE dev sample lost a view that way;
3 with growth through the cubic alone, none with the nested corrections below).

The chart's error is smooth over the skin: a function of where a point lies on a's chart, mostly of its surface angle.
So the matches the chart gave, which are right, are used to learn it: a low-order polynomial in a's chart coordinates,
fitted to the verified matches' offsets from the chart's prediction by robust least squares, is added to the
prediction, and the pair is matched again with the same search. Each round reaches skin a little farther from where the
chart was right; the rounds stop when the verified matches no longer grow. A round searches only the points not
verified before and keeps the verified ones as they were (searched again through a correction fitted to them, they
cost half a round's matching, about 0.6 s of a real capture's geometry, for registrations the same within their
noise: docs/measurements.md, stop 84). Where the chart was right, the correction stays near zero and so do the
matches.

Which polynomial is a question of reach. The first matches of a wide pair (60-90) lie in a band mid-pad, and the
correction is needed beyond it: there a cubic fitted to that band can swing a ridge period or more off, while a plane
in (surface angle, distance along) holds; once the matches cover the overlap, the cubic is what fits the flanks. Which
one reaches farther is not told by the band's own residuals (chosen by held-out matches from the band's edges, three
of eight wide pairs of the IMPOSE sample were left ungrown), only by matching through it. So each round matches
through the cubic first and, where that does not grow a pair with fewer than :data:`FEW_MATCHES` verified matches,
through the plane and the quadratic too (:data:`CORRECTIONS`), keeping the one that verifies most. Through the cubic
alone, six of those eight pairs stayed at their 60-80 first matches (three views lost); so, all eight grew to 270-1,006.
A pair with more matches is grown through the cubic alone: the others cost a matching each (0.3 s at 1280x1024), and
with every round trying all three a real capture's geometry took 2-5 s longer for the same result.

A pair matched both ways (``RegistrationConfig.first_guess_both_ways``: a grid on b too, predicted in a through the
inverse shift) grows each way through a correction of its own, in its own grid's chart coordinates, fitted to the same
verified matches read from that side; the rounds count the two ways' matches together.

Pure numpy/scipy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .chart_shift import ChartPredictor
from .guided import GuidedMatches

__all__ = ["CorrectedChartPredictor", "fit_chart_correction", "grow_first_guess", "CORRECTIONS", "FEW_MATCHES",
           "GROWTH_ROUNDS", "MIN_GROWTH"]

GROWTH_ROUNDS = 4
"""Rounds of matching again through the corrected charts, at most."""
MIN_GROWTH = 1.05
"""A round is kept when it verifies at least this many times as many matches as the best before it; else the rounds
stop."""
_TERMS = 7  # 1, theta, theta^2, theta^3, s, s theta, s^2 (s: distance along the finger over the chart radius)
CORRECTIONS: dict[str, tuple[int, ...]] = {"cubic": tuple(range(_TERMS)), "plane": (0, 1, 4), "quadratic": (0, 1, 2, 4)}
"""The nested corrections a round can try, as the polynomial terms they use (indices into 1, theta, theta^2, theta^3,
s, s theta, s^2; theta a's chart's surface angle, s the distance along the finger over the chart's radius); the cubic
first."""
FEW_MATCHES = 200
"""Below this many verified matches, a round whose cubic does not grow the pair tries the lower corrections too."""
_RIDGE = 1e-2  # Tikhonov pull of each coefficient toward 0, in pixels (keeps terms the matches do not reach at 0)


def _basis(predictor: ChartPredictor, uv: np.ndarray) -> np.ndarray:
    """``[N, 7]`` polynomial terms of a's chart coordinates at pixels ``uv``."""
    sigma, theta = predictor.chart_a.surface(np.asarray(uv, np.float64))
    s = sigma / max(float(predictor.chart_a.radius), 1e-6)
    return np.stack([np.ones_like(theta), theta, theta ** 2, theta ** 3, s, s * theta, s ** 2], -1)


@dataclass(frozen=True, eq=False)
class CorrectedChartPredictor:
    """A :class:`ChartPredictor` plus a polynomial correction ``[7, 2]`` (pixels of b) in a's chart coordinates."""

    chart: ChartPredictor
    coefficients: np.ndarray

    def __call__(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted pixels in b ``[N, 2]`` and whether b sees them ``[N]``."""
        predicted, seen = self.chart(uv)
        return predicted + _basis(self.chart, uv) @ self.coefficients, seen


def fit_chart_correction(chart: ChartPredictor, uv_a: np.ndarray, uv_b: np.ndarray, scale_px: float,
                         use: tuple[int, ...] = CORRECTIONS["cubic"]) -> np.ndarray:
    """``[7, 2]`` coefficients taking ``chart``'s predictions of ``uv_a`` to the matched ``uv_b`` with the terms ``use``
    (the others 0), by least squares with a Cauchy loss (a wrong match weighs little; its scale 1.5 times the median
    miss of the plain least-squares fit it starts from, at least ``scale_px``) and a light pull of every term toward
    zero."""
    use = list(use)
    terms = _basis(chart, uv_a)[:, use]
    offsets = np.asarray(uv_b, np.float64) - chart(uv_a)[0]
    finite = np.isfinite(terms).all(1) & np.isfinite(offsets).all(1)
    terms, offsets = terms[finite], offsets[finite]
    coefficients = np.zeros((_TERMS, 2))
    count = len(use)
    if len(terms) < 2 * count:
        return coefficients
    design = np.vstack([terms, _RIDGE * np.eye(count)])
    target = np.vstack([offsets, np.zeros((count, 2))])

    # Started from the plain least-squares fit: from no correction, the robust loss would weigh least the very offsets
    # the correction is for (a chart ten pixels off), and stay near the chart.
    start = np.linalg.lstsq(design, target, rcond=None)[0]
    # The loss's scale from how far the matches lie from that fit (1.5 times the median), so that a match a ridge period
    # off (ridge texture repeats) weighs less than the bulk, however wide the bulk is; not under ``scale_px``.
    spread = 1.5 * float(np.median(np.linalg.norm(terms @ start - offsets, axis=1)))
    coefficients[use] = _cauchy_least_squares(design, target, start, max(spread, float(scale_px), 1e-3))
    return coefficients


def _cauchy_least_squares(design: np.ndarray, target: np.ndarray, start: np.ndarray, scale: float,
                          iterations: int = 100, tolerance: float = 1e-10) -> np.ndarray:
    """``[k, 2]`` coefficients minimising ``sum log(1 + (r / scale)^2)`` over every entry ``r`` of ``design @ x -
    target`` (the loss scipy's ``least_squares(loss="cauchy")`` applies entry by entry, so each column is its own fit),
    from ``start``, by iteratively reweighted least squares (each entry weighs ``1 / (1 + (r / scale)^2)``, the loss's
    derivative; the loss falls at every step). Why not scipy's ``least_squares``: for this linear model its trust
    region took 0.15 s a fit of 3,900 matches (a wide pair's growth fits 7-14), these steps 0.02 s, to the same
    minimum (tests/test_chart_growth.py)."""
    solution = np.array(start, np.float64)
    for column in range(target.shape[1]):
        x, y = solution[:, column], target[:, column]
        for _ in range(iterations):
            root = 1.0 / np.sqrt(1.0 + ((design @ x - y) / scale) ** 2)
            step = np.linalg.lstsq(design * root[:, None], y * root, rcond=None)[0]
            moved = float(np.max(np.abs(step - x)))
            x = step
            if moved <= tolerance * max(1.0, float(np.max(np.abs(x)))):
                break
        solution[:, column] = x
    return solution


def grow_first_guess(charts: Sequence[ChartPredictor], first: GuidedMatches,
                     match: Callable[..., GuidedMatches], verify: Callable[[GuidedMatches], GuidedMatches],
                     min_matches: int, scale_px: float) -> tuple[GuidedMatches, int]:
    """The pair's first-guess matches grown (module docstring): ``charts`` the pair's chart predictors, a to b and, where
    the pair is matched both ways, b to a; ``first`` the matches through them alone (read from a to b),
    ``match(*predictors, skip=matches)`` matches the pair through one predictor per chart (leaving out the grid points
    that ``matches`` hold already, each way from its own view), ``verify`` keeps the matches that agree on one epipolar
    geometry. Each round matches through the cubic corrections fitted to the verified matches so far
    (each way's in its own view's chart coordinates); where that does not grow a pair of fewer than
    :data:`FEW_MATCHES`, through the other :data:`CORRECTIONS` too, keeping the one that verifies most. Grown only
    from at least ``min_matches`` verified ones (a pair the chart did not register stays as it was). Returns the best
    matches and the rounds that grew them."""
    best, verified = first, verify(first)
    grown = 0
    for _ in range(GROWTH_ROUNDS):
        if len(verified) < min_matches:
            break
        needed = MIN_GROWTH * len(verified)
        ends = [(verified.uv_a, verified.uv_b), (verified.uv_b, verified.uv_a)]
        trials = []
        for use in CORRECTIONS.values():
            predictors = tuple(CorrectedChartPredictor(chart, fit_chart_correction(chart, *ends[way], scale_px, use))
                               for way, chart in enumerate(charts))
            trial = verified.joined(match(*predictors, skip=verified))
            trials.append((trial, verify(trial)))
            if len(trials[-1][1]) >= needed or len(verified) >= FEW_MATCHES:
                break
        trial, checked = max(trials, key=lambda tried: len(tried[1]))
        if len(checked) < needed:
            break
        best, verified, grown = trial, checked, grown + 1
    return best, grown
