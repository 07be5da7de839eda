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
chart was right; the rounds stop when the verified matches no longer grow. Where the chart was right, the correction
stays near zero and so do the matches.

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

Pure numpy/scipy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import least_squares

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

    def residuals(flat: np.ndarray) -> np.ndarray:
        return (design @ flat.reshape(count, 2) - target).ravel()

    jacobian = np.kron(design, np.eye(2))  # the model is linear in the coefficients
    # Started from the plain least-squares fit: from no correction, the robust loss would weigh least the very offsets
    # the correction is for (a chart ten pixels off), and stay near the chart.
    start = np.linalg.lstsq(design, target, rcond=None)[0].ravel()
    # The loss's scale from how far the matches lie from that fit (1.5 times the median), so that a match a ridge period
    # off (ridge texture repeats) weighs less than the bulk, however wide the bulk is; not under ``scale_px``.
    spread = 1.5 * float(np.median(np.linalg.norm(terms @ start.reshape(count, 2) - offsets, axis=1)))
    solution = least_squares(residuals, start, jac=lambda flat: jacobian, loss="cauchy",
                             f_scale=max(spread, float(scale_px), 1e-3), method="trf")
    coefficients[use] = solution.x.reshape(count, 2)
    return coefficients


def grow_first_guess(chart: ChartPredictor, first: GuidedMatches, match: Callable[[object], GuidedMatches],
                     verify: Callable[[GuidedMatches], GuidedMatches], min_matches: int,
                     scale_px: float) -> tuple[GuidedMatches, int]:
    """The pair's first-guess matches grown (module docstring): ``first`` the matches through ``chart`` alone,
    ``match(predictor)`` matches the pair through a predictor, ``verify`` keeps the matches that agree on one epipolar
    geometry. Each round matches through the cubic correction fitted to the verified matches so far; where that does
    not grow a pair of fewer than :data:`FEW_MATCHES`, through the other :data:`CORRECTIONS` too, keeping the one that
    verifies most. Grown only from at least ``min_matches`` verified ones (a pair the chart did not register stays as
    it was). Returns the best matches and the rounds that grew them."""
    best, verified = first, verify(first)
    grown = 0
    for _ in range(GROWTH_ROUNDS):
        if len(verified) < min_matches:
            break
        needed = MIN_GROWTH * len(verified)
        trials = []
        for use in CORRECTIONS.values():
            trial = match(CorrectedChartPredictor(chart, fit_chart_correction(chart, verified.uv_a, verified.uv_b,
                                                                               scale_px, use)))
            trials.append((trial, verify(trial)))
            if len(trials[-1][1]) >= needed or len(verified) >= FEW_MATCHES:
                break
        trial, checked = max(trials, key=lambda tried: len(tried[1]))
        if len(checked) < needed:
            break
        best, verified, grown = trial, checked, grown + 1
    return best, grown
