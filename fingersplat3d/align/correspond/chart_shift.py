"""The turn between two views of a finger, from their unwrapped ridge textures; the first guess of a match.

Two views unwrapped on their cylinder charts (:mod:`fingersplat3d.align.chart`) show the same
skin shifted by ``(d_sigma, turn)``. One global correlation of the two unwrapped images finds that
shift only weakly on real photos (peak 0.07-0.19 against 0.04 elsewhere): the chart is a circle
fitted to a silhouette, and its errors decorrelate the textures over the whole finger. Local
patches (5 ridge periods) still correlate well, so each patch of view a searches the whole angle
range of view b (and a band of ``d_sigma``) for its best normalised cross-correlation, and the
offsets of the patches that correlate vote in a 2D histogram (a Hough transform). The peak is the
shift; its support (votes near the peak) and its ratio to the next-best peak say how sure it is.

Measured on the nine real UWA captures (front-side pairs, 45 degrees apart): every pair's peak
lies at 43-60 degrees, with 19-165 supporting patches out of ~500-700, where one global
correlation of the whole unwrapped images put two of the eighteen pairs at wrong angles. Pairs
90 degrees apart share too little texture for a decisive vote (one of nine) and are left to the
guided matching, which predicts them through the 3D model.

:class:`ChartPredictor` turns a shift into the pixel-to-pixel prediction the guided matcher
(:mod:`fingersplat3d.align.guided`) starts from. Pure numpy/OpenCV.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ...device import per_item
from .chart import MAX_CHART_ANGLE, CylinderChart, Unwrapped

__all__ = ["ChartShift", "estimate_chart_shift", "chart_shift_candidates", "ChartPredictor", "vote_area", "RIDGE_VOTE_SHARE"]

MIN_PATCH_NCC = 0.3
"""A patch votes only when its best correlation reaches this."""
MIN_SUPPORT = 18
"""Votes near the peak a shift needs to be taken (the nine real captures' front-side pairs: 19-165;
views of different synthetic fingers: 8-15)."""
MIN_RATIO = 1.3
"""How far the peak must stand above its best rival (real front-side pairs: 1.39-11.7; different fingers
with more than 12 votes: 1.04-2.3). Views of two fingers that pass the vote are refused by the guided rounds
(``RegistrationConfig.min_agreement``). At 1.1 the weakest real pair with its contrast halved (1.18) registers, but a
mirrored side view passes too (1.16) and its front-side pair then agrees through the model at 15-24 %, as views of
one finger do: kept at 1.3. A view no decisive vote places is tried at its votes' best peaks instead
(``RegistrationConfig.undecided_peaks``), where it must agree far better than that."""
RIVAL_TURN_DEG = 20.0
"""A rival shift must differ from the peak by this much turn (or by 3 bins of d_sigma)."""
RIDGE_VOTE_SHARE = 0.4
"""Where the ridge area (:func:`~fingersplat3d.align.correspond.texture.ridge_area`: the distal phalanx, within 1.4
finger widths of the tip) is less than this share of the finger in view (:func:`vote_area`), a pair votes first on the
ridge areas alone, taken when decisive, else on the whole fingers as everywhere; an undecided pair tries both votes'
peaks, each placed by its agreement through the model (``register._surface_guess``, ``register._candidate_shifts``).
A phone's photo from far back shows a long finger whose skin behind the ridges (smooth, creased, its look set by the
light more than by the skin) correlates everywhere a little: its ~2,000 patches outvoted the ridges' 300-600 and put
a pair 60 degrees apart at -7.5 (phone-like photos, ridge areas 15-24 % of the finger in view; docs/measurements.md,
stop 89). The rig's views show mostly the distal phalanx (real dev views 47-90 %, the shipped samples 50-66 %, another
make at the rig's framing 55-65 %): they vote as before."""
_PATCH_PERIODS = 2.0  # patch half-size in ridge periods (patches are placed every half-size)
_BIN_PERIODS = 0.45  # histogram bin in ridge periods
_MAX_SIGMA_SHIFT = 0.27  # search band of d_sigma, as a fraction of the chart radius
_VALID_PATCH = 0.95  # share of a patch of a that must be on the unwrapped finger
_VALID_TARGET = 0.8  # share of the matched patch of b that must be on the unwrapped finger


@dataclass(frozen=True)
class ChartShift:
    """How view b's chart is shifted against view a's: ``theta_b = theta_a + turn``, ``sigma_b = sigma_a + d_sigma``."""

    turn: float  # radians
    d_sigma: float  # pixels
    support: int
    """Voting patches within two bins of the peak."""
    patches: int
    """Patches that voted (correlation >= ``MIN_PATCH_NCC``)."""
    ratio: float
    """Smoothed histogram peak over the best rival: a peak at least ``RIVAL_TURN_DEG`` of turn or 3 bins of
    ``d_sigma`` away (>= 1)."""

    @property
    def decisive(self) -> bool:
        """Whether the vote singles out one shift (``MIN_SUPPORT`` votes, ``MIN_RATIO`` above the runner-up)."""
        return self.support >= MIN_SUPPORT and self.ratio >= MIN_RATIO


def vote_area(mask: np.ndarray) -> np.ndarray:
    """The part of a finger mask whose patches vote: its ridge area where that is under :data:`RIDGE_VOTE_SHARE` of
    it, else the whole mask."""
    from .texture import ridge_area

    mask = np.asarray(mask, bool)
    area = ridge_area(mask) & mask
    total = int(mask.sum())
    return area if 0 < int(area.sum()) < RIDGE_VOTE_SHARE * total else mask


def _patch_votes(a: Unwrapped, b: Unwrapped, half: int, max_shift: int) -> np.ndarray:
    """``[K, 3]`` (row offset a-b, column offset a-b, correlation) of the patches of a that correlate."""
    rows, cols = a.image.shape
    if b.image.shape[0] < 2 * half:
        return np.zeros((0, 3))  # b's chart fewer rows across than one patch: nothing of it can be scored
    # Share of b's finger under a patch placed with its corner at each pixel (a patch of b that runs
    # past b's right or bottom edge is never scored, so one filter of the whole image serves all).
    coverage = cv2.boxFilter(b.valid.astype(np.float32), -1, (2 * half, 2 * half), normalize=True, anchor=(0, 0),
                             borderType=cv2.BORDER_CONSTANT)
    centres = [(y, x) for y in range(half, rows - half, half) for x in range(half, cols - half, half)
               if a.valid[y - half:y + half, x - half:x + half].mean() >= _VALID_PATCH]

    def vote(centre: tuple[int, int]) -> tuple[float, float, float] | None:
        y, x = centre
        left, right = max(0, x - half - max_shift), min(b.image.shape[1], x + half + max_shift)
        if right - left < 2 * half + 1:
            return None
        template = a.image[y - half:y + half, x - half:x + half]
        score = cv2.matchTemplate(b.image[:, left:right], template, cv2.TM_CCOEFF_NORMED)
        score[coverage[:score.shape[0], left:left + score.shape[1]] < _VALID_TARGET] = -1.0
        _, best, _, (px, py) = cv2.minMaxLoc(score)
        return (y - (py + half), x - (left + px + half), best) if best >= MIN_PATCH_NCC else None

    # Patches in parallel on the process's threads (OpenCV releases the GIL), OpenCV itself on one each.
    votes = [v for v in per_item(vote, centres) if v is not None]
    return np.asarray(votes, np.float64).reshape(-1, 3)


def estimate_chart_shift(a: Unwrapped, b: Unwrapped, period: float) -> ChartShift | None:
    """The shift of b's unwrapped texture against a's, by patch voting (see the module); None when no patch votes."""
    found = chart_shift_candidates(a, b, period, 1)
    return found[0] if found else None


def chart_shift_candidates(a: Unwrapped, b: Unwrapped, period: float, count: int) -> list[ChartShift]:
    """The ``count`` best-voted shifts of b's unwrapped texture against a's, best first: each further peak of the
    vote's histogram lies beyond the rival reach of every peak before it. The first is :func:`estimate_chart_shift`'s;
    a later one's ``ratio`` (its peak over the best other, the first) is below 1. Empty when no patch votes."""
    half = max(4, int(round(_PATCH_PERIODS * period / a.step)))
    max_shift = int(round(_MAX_SIGMA_SHIFT * a.radius / a.step))
    votes = _patch_votes(a, b, half, max_shift)
    if len(votes) == 0:
        return []
    bin_size = max(1.0, _BIN_PERIODS * period / a.step)
    d_row, d_col, weight = votes[:, 0], votes[:, 1], votes[:, 2] - MIN_PATCH_NCC + 0.05
    low_row, low_col = d_row.min() - 3 * bin_size, d_col.min() - 3 * bin_size
    shape = (int((d_row.max() - low_row) / bin_size) + 4, int((d_col.max() - low_col) / bin_size) + 4)
    histogram = np.zeros(shape)
    np.add.at(histogram, (((d_row - low_row) / bin_size).astype(int), ((d_col - low_col) / bin_size).astype(int)), weight)
    histogram = cv2.GaussianBlur(histogram, (0, 0), 1.0)
    # A rival is looked for beyond RIVAL_TURN of a peak: the chart's errors smear one true shift along the turn
    # over several bins (measured on real captures: sub-peaks 7-18 degrees away).
    reach = max(3, int(np.ceil(np.radians(RIVAL_TURN_DEG) * b.radius / b.step / bin_size)))
    remaining = histogram.copy()
    middle_a = (a.image.shape[0] - 1) / 2.0
    shifts = []
    while len(shifts) < count and remaining.max() > 0.0:
        peak = np.unravel_index(int(np.argmax(remaining)), shape)
        region = (slice(max(0, peak[0] - reach), peak[0] + reach + 1), slice(max(0, peak[1] - 3), peak[1] + 4))
        others = histogram.copy()
        others[region] = 0.0
        remaining[region] = 0.0
        centre_row = low_row + (peak[0] + 0.5) * bin_size
        centre_col = low_col + (peak[1] + 0.5) * bin_size
        near = (np.abs(d_row - centre_row) < 2 * bin_size) & (np.abs(d_col - centre_col) < 2 * bin_size)
        if not near.any():  # a peak of the smoothing alone, between votes
            continue
        row_shift = float(np.average(d_row[near], weights=weight[near]))
        col_shift = float(np.average(d_col[near], weights=weight[near]))
        turn = float(b.angle(middle_a - row_shift))  # theta_b where theta_a = 0
        shifts.append(ChartShift(turn, -col_shift * a.step, int(near.sum()), len(votes),
                                 float(histogram[peak] / max(float(others.max()), 1e-12))))
    return shifts


@dataclass(frozen=True, eq=False)
class ChartPredictor:
    """Pixels of view a to view b through both charts and a :class:`ChartShift`; ``zoom``: b's pixels per a's along
    the finger, when b's texture was unwrapped at ``zoom`` times a's step (``sigma_b = zoom * (sigma_a + d_sigma)``)."""

    chart_a: CylinderChart
    chart_b: CylinderChart
    shift: ChartShift
    zoom: float = 1.0

    def __call__(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted pixels in b ``[N, 2]`` and whether b sees them ``[N]``."""
        sigma, theta = self.chart_a.surface(uv)
        theta_b = theta + self.shift.turn
        return self.chart_b.pixels(self.zoom * (sigma + self.shift.d_sigma), theta_b), np.abs(theta_b) < MAX_CHART_ANGLE
