"""A finger on any background (a phone photo on a bright desk, a cluttered room): found by its ridges, then cut out
by GrabCut.

The dark-background segmentation (:mod:`fingersplat3d.segment.masks`) needs the finger to be the bright thing in
the frame. Elsewhere brightness says little, but one thing is only on the finger: **friction ridges**, a texture of
one period and a slowly turning orientation. So:

1. the image is worked on at most :data:`WORK_SIDE` px (GrabCut's colour models need no more);
2. OpenCV's GrabCut (colour mixture models and a graph cut) separates what stands apart from the frame's border
   ring, taken as background: a finger enters the frame at one side, so the ring is mostly background (its pixels
   nearer the skin's colour than the ring's own only probably); the largest area of ridges, shrunk by the reach of
   its smoothing (:func:`_sure_finger`), is sure finger;
3. of the pieces that stand apart, the finger is the one with ridges: per pixel, a ridge score (:func:`ridge_score`:
   a periodic texture, strong against the image's median; the best over the periods :data:`PERIODS_PX`) counted
   inside each piece away from its outline (:func:`_ridged_piece`); GrabCut is run again from the ring with that
   piece's own ridge area as sure finger and what is far from its colour (:func:`_colour_distance`, the skin's
   covariance) or brighter than its brightest starting as probable background, so that GrabCut learns the finger's
   colours from skin and not from everything inside the ring;
4. a last GrabCut told what the finger is (that piece's ridged area) and what it is not (everything outside the
   piece; inside it, what is far from the pad's colour, or far from any ridge, starts as probable background), so
   that background stuff that went along with the finger falls away; an earlier piece is kept instead where the
   photo's edges along its outline are twice as strong and what it adds has the skin's hue (:func:`_best_supported`:
   a later cut that dropped the finger's shaded half or its highlit band leaves an outline across the skin, on no
   edge);
5. the finger carried out across the border ring where it reaches it (a finger the frame cuts stays cut by the
   frame), holes filled;
6. steps 2-5 again with a ridge score that also asks the texture to repeat itself a period across its own direction
   (:func:`repetition`: an object's edge or an in-focus line is one crest or one step, and had read as ridges), down
   to ridges finer than the working copy shows (:data:`FINE_PERIODS_PX`, on the photo enlarged); that cut is taken
   where it holds half as many repeating ridges again as the first, or where the first swells past the finger a tenth
   more than it (:func:`_chosen`): the first had found a thing of the clutter, or taken one in; or where the first's
   outline lies on no edge of the photo and its own on edges twice as strong (a band of a desk of the skin's greys
   kept all round the finger). A real finger's skin, its ridges among pores and noise, repeats little at the working
   size, so the first cut stays wherever both agree;
7. back to full size with a smooth edge;
8. the outline moved onto the photo's edge at full size, to a fraction of a pixel (:func:`_on_the_edge`).

Where neither cut finds a finger and a twentieth of the border ring or more is far from the ring's own colour, a last
cut (:func:`_crossing_cut`) takes those pixels for a finger the frame cuts at both ends, crossing the ring: probable
finger instead of sure background, no area of ridges taken for sure finger, and the piece kept only if it reaches them;
where a mask was found whose outline lies on no edge of the photo and which holds under half of those pixels, the
crossing cut is taken where it holds more of them and the photo's edges along its outline are twice as strong (a
patch of a desk's grain was taken for the finger beside it; on clutter, things of every colour cross the ring).

Where the finger fills the frame across its width, the ring is not the background these cuts take it for: where their
mask leaves out half the skin found on the ring, or lies on no edge of the photo, a cut seeded from the image centre
(:func:`~fingersplat3d.segment.filled_frame.filling_cut`) is taken instead, if it holds that skin (:func:`_filled_or`).

It fails with an :class:`~fingersplat3d.errors.InputError` when no ridge area stands out (a photo with no finger,
or one too blurred to show ridges). Pure numpy/OpenCV.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import cv2
import numpy as np

from ..errors import InputError
from ..robust import robust_sigma
from ..scene import scaled_size
from ..structure_tensor import ridge_direction
from .filled_frame import filling_cut, holds_ring_skin, ring_skin
from .grabcut import _colour_distance, _colour_floor, _gray, _grab_cut  # noqa: F401 - tests read them here
from .morphology import dilated, disc, outline
from .regions import crest_level, fill_holes, gradient_magnitude, local_sums
from .silhouette import outline_swell, widest_disc

__all__ = ["finger_mask_any_background", "ridge_score", "repetition", "WORK_SIDE", "PERIODS_PX"]

WORK_SIDE = 640
"""Long side (pixels) GrabCut and the ridge score work at."""
PERIODS_PX = (3.0, 4.5, 6.5)
"""Ridge periods (pixels at the working size) the ridge score is searched over."""
FINE_PERIODS_PX = (1.0, 1.5, 2.25)
"""Finer ridge periods (pixels at the working size) searched where the photo is larger than the working copy, each
scored on the photo enlarged to show it at :data:`PERIODS_PX`'s smallest or more (3x, 2x, 2x the working size): a
phone's photo of a finger a ninth of its width has ridges 2 px apart at 640 px, averaged away at the working size."""
FINE_SLACK = 1.01
"""An enlarged copy may be this much larger than the photo itself (rounding of the working size)."""
MIN_RIDGE_SHARE = 0.003
"""A finger shows ridges over at least this share of the working image ..."""
MIN_RIDGE_AREA_PX = 400
"""... and over at least this many working pixels (a few ridges each way)."""
RIDGE_LEVEL = 0.15
"""Ridge score above which a pixel counts as showing ridges."""
REPEAT_LAGS = (0.8, 1.0, 1.25)
"""Shifts (ridge periods) at which the ridge band is compared with itself across its own direction
(:func:`repetition`); the searched periods lie 1.5 times apart, so every period between them is within a quarter of
one of these."""
REPEAT_GATE = (0.1, 0.4)
"""Where the ridges must repeat (:func:`ridge_score`), each pixel's score is scaled by its :func:`repetition`, 0 at the
first of these and below, 1 at the second and above. Measured at 640 px: the edges and in-focus lines of clutter read
-0.25 to -0.12 (median; 90 % under 0), another group's photographed skin texture 0.35-0.41, but a real dev finger's
skin, ridges among pores and noise, only ~0.05: asked of every photo, the repetition lost real fingers on clutter (3
of 12 views of finger 1 on in-focus clutter found no finger), hence a second cut beside the plain one
(:func:`_chosen`)."""
REPEATED_MORE = 1.5
"""The mask cut where the ridges must repeat is taken over the plain one where it holds this many times the plain one's
pixels of repeating ridges (:func:`_chosen`)."""
SWELL_MARGIN = 1.1
"""... or where the plain one's widest chord over its median one is this many times the other's (a finger's own reads
1.01-1.19, two masks of it within a few hundredths of each other)."""
REPEATED_REACH_SHARE = 0.15
"""The last cut's reach from the ridges (as :data:`RIDGE_REACH_SHARE`) where they must repeat: the repeating ridges
do not spill past the outline as the plain score's do, so a shaded flank lies farther from them (a synthetic finger
on in-focus clutter lost its shaded half at 0.05: IoU 0.70; 0.99 at 0.15 and 0.25)."""
STRENGTH_FLOOR = 8.0
"""Band energy is weighed against this many times its median over the image."""
EVIDENCE_REACH = 2.5
"""How far (in ridge periods) the ridge evidence reaches past a strong edge (:func:`_core`)."""
SURE_SKIN_DISTANCE = 3.0
"""Pixels of the ridge area this close to the core's colour (:func:`_colour_distance`, strict) are sure finger
(:func:`_sure_finger`)."""
SEED_RADIUS = 10
"""Radius (working pixels) of the opening that keeps areas of ridges and drops lines (the edges of other things)."""
SKIN_DISTANCE = 1.5
"""Border-ring pixels this close to the pad's colour (:func:`_colour_distance`) may be finger."""
PIECE_SKIN_DISTANCE = 5.0
"""Pixels farther than this from the pad's colour (:func:`_colour_distance`) start as probable background: in the second
cut everywhere inside the border ring, in the last inside the finger's piece."""
RIDGE_REACH_SHARE = 0.05
"""In the last cut, skin-coloured pixels of the finger's piece farther than this share of its width (the widest disc
inside it) from any ridge evidence start as probable background, not probable finger (:func:`_refined`). The evidence
is smoothed over a period and reaches past the rims, so the skin's own flanks start as finger. Measured (stop 45,
``tools/bench_backgrounds.py``): real views on out-of-focus clutter, worst IoU finger 1 0.903 -> 0.904, finger 2
0.958 -> 0.988; composited captures fused whole 6 -> 7 of 8; 0.15 of the width freed one view of four, 0.01 the same
as 0.05."""
RING_SHARE = 0.02
"""Width of the frame's border ring GrabCut takes as background, as a share of the long side."""
CROSSING_SPREADS = 6.0
"""A pixel of the border ring farther from the ring's median colour than this many times the ring's median distance
from it is not the background's (:func:`_off_ring`): where a finger the frame cuts at both ends crosses the ring."""
MIN_CROSSING_SHARE = 0.05
"""The share of the border ring such pixels must hold for the crossing cut to be tried (a plain or a cluttered
background holds next to none at that distance from its own colour)."""
EDGE_GAIN = 2.0
"""A cut's earlier piece replaces its later one where the photo's edges along the earlier one's outline are this many
times stronger (:func:`_edge_support`): a later cut that took the finger's shaded half or its highlit band for
background leaves an outline across the skin, where the photo has no edge (:func:`_best_supported`)."""
HUE_DISTANCE = 0.08
"""Two pixel sets have one hue where their median chromaticities (colour over its sum) lie this close. Measured: a
synthetic finger's shaded half or highlit band against the rest of its skin 0.00 (one skin colour, shaded); coloured
clutter (brown and navy shapes) beside a real grey finger 0.32. Skin's own hue varies by a few hundredths between its
shade and a highlight; the margin is set between."""
WEAK_EDGE_SHARE = 0.25
"""A found mask whose outline's edges are weaker than this share of the photo's strongest (:func:`_on_no_edge`) is set
beside the crossing cut. Measured: a patch of a bright desk taken for the finger beside it 0.02 of them; real fingers on
in-focus clutter, masked right, 0.43 and 0.64 (their outline partly against things of the skin's grey)."""
CROSSING_HELD = 0.5
"""A mask that holds less than this share of the ring's pixels where something crosses it (:func:`_off_ring`, where
they are :data:`MIN_CROSSING_SHARE` of the ring or more) is set beside the crossing cut: the finger crossing the frame
left out, a patch of the background taken instead (:func:`_crossing_cut`)."""
EDGE_PERCENTILE = 25.0
"""The outline's edge support is this percentile of the edge strength along it: weak where a quarter of it or more runs
across the skin (a finger cut at both ends and halved lengthwise has half its outline there)."""
MIN_OUTLINE_PX = 20
"""An outline with fewer pixels away from the border ring has no edge support to compare."""
EDGE_BLUR_PX = 2.0
"""The photo is blurred this much before the outline is put on its edge (:func:`_on_the_edge`): ridges fade, and a
symmetric blur leaves the midpoint between the two sides on the edge."""
EDGE_CONTRAST = 0.05
"""The least difference (share of the range) between the local finger and background colours for the outline to be
moved onto the edge; elsewhere GrabCut's outline stays."""


def ridge_score(gray: np.ndarray, period: float, repeated: bool = False) -> np.ndarray:
    """Per-pixel ridge evidence in [0, 1) at ``period`` px: how periodic the texture is (the energy of a band around
    ``period`` over itself plus those of the bands three times finer and coarser: near 1 on ridges, low at the edge
    of a plain object, whose step spreads over every band, and in sensor noise, which is finest) times how strong
    (``e / (e + 8 median)``); ``repeated``: times how far the band repeats a period across its own direction
    (:func:`repetition` through :data:`REPEAT_GATE`: a sharp line or edge puts most of its energy in the band too, but
    once)."""
    score, band, energy = _periodic_score(gray, period)
    return (_repeated_score(score, band, energy, period) if repeated else score).astype(np.float32)


def _periodic_score(gray: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`ridge_score`'s plain score at ``period``, with the ridge band and its smoothed energy it came from."""
    blurred = [gray] + [cv2.GaussianBlur(gray, (0, 0), sigma) for sigma in (0.15 * period, 0.45 * period, 1.35 * period)]
    fine_band, ridge_band, coarse_band = (blurred[k] - blurred[k + 1] for k in range(3))
    smooth = [cv2.GaussianBlur(band * band, (0, 0), period) for band in (fine_band, ridge_band, coarse_band)]  # ~2 ridges
    fine, ridge, coarse = smooth
    periodic = ridge / np.maximum(ridge + coarse + fine, 1e-12)
    floor = STRENGTH_FLOOR * max(float(np.median(ridge)), 1e-12)
    return periodic * ridge / (ridge + floor), ridge_band, ridge


def _repeated_score(score: np.ndarray, band: np.ndarray, energy: np.ndarray, period: float) -> np.ndarray:
    """A plain score times how far its ``band`` repeats (:func:`repetition` through :data:`REPEAT_GATE`)."""
    low, high = REPEAT_GATE
    return score * np.clip((repetition(band, energy, period) - low) / (high - low), 0.0, 1.0)


def repetition(band: np.ndarray, energy: np.ndarray, period: float) -> np.ndarray:
    """Per pixel, how far the ridge ``band`` repeats itself one period across its own direction: its product with
    itself moved by about a period both ways across the local direction
    (:func:`~fingersplat3d.structure_tensor.ridge_direction`), averaged over a period and divided by the band's
    ``energy`` there (the same average of its square), the best of :data:`REPEAT_LAGS`. A row of parallel crests
    reads near 1; the one crest of a line, or the one step of an object's edge, near 0 or below (a period away lies
    its dip, or nothing)."""
    across, _ = ridge_direction(band, period)
    rows, cols = band.shape
    u, v = np.meshgrid(np.arange(cols, dtype=np.float32), np.arange(rows, dtype=np.float32))
    best = np.full(band.shape, -np.inf, np.float32)
    for lag in REPEAT_LAGS:
        du, dv = lag * period * across[..., 0], lag * period * across[..., 1]
        ahead, behind = (cv2.remap(band, u + sign * du, v + sign * dv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
                         for sign in (1.0, -1.0))
        product = cv2.GaussianBlur(band * 0.5 * (ahead + behind), (0, 0), period)
        np.maximum(best, product / np.maximum(energy, 1e-12), out=best)
    return best


def _ridge_evidence(gray: np.ndarray, photo: np.ndarray | None = None) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """The best ridge score over the searched periods, per pixel of ``gray`` (the working copy), and the period
    (working px) that gave it: plain, and asking the ridges to repeat (:func:`ridge_score`; each period's bands made
    once for both). With ``photo`` (the gray photo at its own size, larger than ``gray``), the repeating ridges finer
    than :data:`PERIODS_PX` too (:data:`FINE_PERIODS_PX`), each scored on a copy of the photo enlarged so that it is at
    least the smallest searched period there, and averaged back onto the working grid."""
    height, width = gray.shape
    plain, repeated = [], []
    for period in PERIODS_PX:
        score, band, energy = _periodic_score(gray, period)
        plain.append(score.astype(np.float32))
        repeated.append(_repeated_score(score, band, energy, period).astype(np.float32))
    periods = list(PERIODS_PX)
    enlarged = {}
    for period in FINE_PERIODS_PX if photo is not None else ():
        zoom = int(np.ceil(PERIODS_PX[0] / period - 1e-6))
        if zoom * max(height, width) > max(photo.shape) * FINE_SLACK:
            continue  # the photo has not the pixels to show ridges that fine
        if zoom not in enlarged:
            enlarged[zoom] = cv2.resize(photo, (zoom * width, zoom * height), interpolation=cv2.INTER_AREA)
        score = ridge_score(enlarged[zoom], zoom * period, repeated=True)
        repeated.append(cv2.resize(score, (width, height), interpolation=cv2.INTER_AREA))
        periods.append(period)
    return _best(plain, PERIODS_PX), _best(repeated, periods)


def _best(scores: list[np.ndarray], periods) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the best of ``scores`` and the period of the one that gave it."""
    stacked = np.stack(scores)
    return stacked.max(0), np.asarray(periods, np.float32)[stacked.argmax(0)]


def _core(area: np.ndarray, period: np.ndarray) -> np.ndarray:
    """The part of an area of ridge evidence that is surely finger: the evidence's band energies are smoothed over a
    period, so beside a strong edge (dark skin on a bright desk) the area reaches :data:`EVIDENCE_REACH` periods past
    the finger's outline (measured: 14 px at the 6.5 px period on real views, the masks 26 px too wide at 1280 px).
    Pixels that far inside the area are kept; a narrow area keeps at least its middle, the half farthest inside."""
    inside = cv2.distanceTransform(np.pad(area, 1).view(np.uint8), cv2.DIST_L2, 5)[1:-1, 1:-1]
    reach = EVIDENCE_REACH * float(np.median(period[area])) if area.any() else 0.0
    core = inside > reach
    if np.count_nonzero(core) < MIN_RIDGE_AREA_PX // 4:
        core = inside > 0.5 * float(inside.max())
    return core


def _ring(shape: tuple[int, int], width: int) -> np.ndarray:
    ring = np.zeros(shape, bool)
    ring[:width], ring[-width:], ring[:, :width], ring[:, -width:] = True, True, True, True
    return ring


def _to_border(finger: np.ndarray, width: int) -> np.ndarray:
    """The mask carried out across the border ring from the ring's inner edge."""
    out = finger.copy()
    out[:width] = finger[width][None]
    out[-width:] = finger[-width - 1][None]
    out[:, :width] = out[:, width][:, None]
    out[:, -width:] = out[:, -width - 1][:, None]
    return out


def _largest_ridge_area(ridged: np.ndarray) -> tuple[np.ndarray, int] | None:
    """The largest area of ``ridged`` pixels once an opening has dropped lines (the edges of other things), and its
    size; None when nothing is left."""
    opened = cv2.morphologyEx(ridged.view(np.uint8), cv2.MORPH_OPEN, disc(SEED_RADIUS))
    count, blobs, stats, _ = cv2.connectedComponentsWithStats(opened, connectivity=8)
    if count < 2:
        return None
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return blobs == largest, int(stats[largest, cv2.CC_STAT_AREA])


def _sure_finger(area: np.ndarray, period: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """What of an area of ridge evidence GrabCut may take as sure finger: its :func:`_core`, and the rest of the area
    whose colour is within :data:`SURE_SKIN_DISTANCE` of the core's and which joins it (the skin toward the pad's rim,
    not the desk or the clutter the evidence spilled over)."""
    core = _core(area, period)
    if not core.any():
        return core
    near = area & (_colour_distance(colour, core, strict=True) < SURE_SKIN_DISTANCE)
    count, pieces = cv2.connectedComponents((near | core).view(np.uint8), connectivity=8)
    held = np.unique(pieces[core])
    return np.isin(pieces, held[held > 0])


def _skin_like(colour: np.ndarray, pad: np.ndarray, background: np.ndarray, within: float) -> np.ndarray:
    """Pixels whose colour may be the finger's: within ``within`` of the pad's colour (:func:`_colour_distance`), or
    nearer the pad's colour than the ``background`` sample's (median and MAD, so that skin in the sample does not
    widen it). The second keeps a finger's shaded base, darker than its pad but far from a bright desk."""
    to_skin = _colour_distance(colour, pad)
    if not background.any():
        return to_skin < within
    sample = colour[background].astype(np.float32)
    centre = np.median(sample, 0)
    spread = np.array([robust_sigma(sample[:, k], centre[k]) for k in range(sample.shape[1])], np.float32)
    to_background = np.linalg.norm((colour - centre) / (spread + _colour_floor(colour)), axis=-1)
    return (to_skin < within) | (to_skin < to_background)


def _pad(evidence: np.ndarray) -> np.ndarray | None:
    """The largest area of ridges, or None when it is too small to be a finger's."""
    found = _largest_ridge_area(evidence > RIDGE_LEVEL)
    enough = max(MIN_RIDGE_SHARE * evidence.size, MIN_RIDGE_AREA_PX)
    return found[0] if found is not None and found[1] >= enough else None


def _piece_pad(piece: np.ndarray, evidence: np.ndarray, period: np.ndarray, colour: np.ndarray) -> np.ndarray | None:
    """The sure finger of the largest area of ridges inside ``piece`` (:func:`_sure_finger`), or None where it has none
    (one area of ridges, not lines)."""
    found = _largest_ridge_area((evidence > RIDGE_LEVEL) & piece)
    if found is None:
        return None
    ridged = _sure_finger(found[0], period, colour)
    return ridged if ridged.any() else None


def _ridged_piece(colour8: np.ndarray, labels: np.ndarray, evidence: np.ndarray, least: float) -> np.ndarray | None:
    """GrabCut from ``labels`` (changed in place); of the pieces it keeps, the one with the most pixels of ridges away
    from its outline, at least ``least`` of them; None where none has that many."""
    candidates = _grab_cut(colour8, labels)
    count, components, stats, _ = cv2.connectedComponentsWithStats(candidates.view(np.uint8), connectivity=8)
    best, best_count = 0, least
    for label in range(1, count):
        if stats[label, cv2.CC_STAT_AREA] < best_count:
            continue
        inner = cv2.erode((components == label).view(np.uint8), np.ones((7, 7), np.uint8)).view(bool)
        ridged = float(np.count_nonzero(evidence[inner] > RIDGE_LEVEL))
        if ridged >= best_count:
            best, best_count = label, ridged
    return components == best if best else None


def _refined(colour8: np.ndarray, piece: np.ndarray, evidence: np.ndarray, period: np.ndarray,
             ring_width: int, reach_share: float = RIDGE_REACH_SHARE) -> np.ndarray:
    """A last GrabCut, now told what the finger is (its ridged area) and what it is not (everything outside the
    piece): background stuff that went along with the finger (it was not in the border ring) falls away. Skin-coloured
    pixels of the piece farther than ``reach_share`` of its width from any ridge start as probable background: a grey
    thing the finger touches is as near the skin's colour as its shaded flank, but shows no ridges (what GrabCut
    learned of the finger's colours from it had kept it whole)."""
    ridged = _piece_pad(piece, evidence, period, colour8)
    if ridged is None:
        return piece
    skin = _skin_like(colour8, ridged, ~piece, PIECE_SKIN_DISTANCE)
    away = cv2.distanceTransform(1 - ((evidence > RIDGE_LEVEL) & piece).view(np.uint8), cv2.DIST_L2, 5)
    near = skin & (away <= reach_share * widest_disc(piece))
    labels = np.where(piece & near, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    labels[~piece] = cv2.GC_BGD
    labels[_ring(piece.shape, ring_width) & ~skin] = cv2.GC_BGD  # where the finger enters the frame it stays probable
    labels[ridged] = cv2.GC_FGD
    finger = _grab_cut(colour8, labels)
    count, components = cv2.connectedComponents(finger.view(np.uint8), connectivity=8)
    held = np.unique(components[ridged & finger])
    return np.isin(components, held[held > 0])


def _on_the_edge(colour: np.ndarray, mask: np.ndarray, reach: float) -> np.ndarray:
    """``mask`` with its outline moved onto the photo's edge, to a fraction of a pixel.

    GrabCut works on a copy of at most :data:`WORK_SIDE` px and keeps an edge's blended pixels: its outline lies
    about one photo pixel outside the finger at 640 px, more once scaled up, and half a pixel of outline turns a
    registered camera by up to half a degree. Within ``reach`` px of that outline, each pixel's colour (blurred by
    :data:`EDGE_BLUR_PX`) is placed between the finger's and the background's local colours (their means over the
    band's inner and outer halves, :func:`~fingersplat3d.segment.regions.local_sums`) and is finger past that
    place's level at the crest of its gradient (:func:`~fingersplat3d.segment.regions.crest_level`, as the
    dark-background masks take theirs), wherever the two colours differ by :data:`EDGE_CONTRAST`. ``colour``
    ``[H, W, 3]`` float32 in [0, 1]."""
    mask8 = mask.view(np.uint8)
    inside = cv2.distanceTransform(mask8, cv2.DIST_L2, 3)
    outside = cv2.distanceTransform(1 - mask8, cv2.DIST_L2, 3)
    band = (inside <= reach) & (outside <= reach)
    smooth = cv2.GaussianBlur(colour, (0, 0), EDGE_BLUR_PX, borderType=cv2.BORDER_REPLICATE)
    height, width = mask.shape
    means = []
    for side in (band & mask, band & ~mask):
        weight = side.astype(np.float32)
        mass, total = local_sums(weight, weight[..., None] * smooth)
        seen = mass > 1e-3 * max(float(mass.max()), 1e-30)
        mean = np.where(seen[..., None], total / np.maximum(mass, 1e-30)[..., None], np.nan).astype(np.float32)
        means.append(cv2.resize(mean, (width, height), interpolation=cv2.INTER_LINEAR))
    skin, background = means
    step = skin - background
    size = np.einsum("ijk,ijk->ij", step, step)
    placed = np.einsum("ijk,ijk->ij", smooth - background, step) / np.maximum(size, 1e-12)
    moved = band & (size > EDGE_CONTRAST ** 2)  # NaN where a side was not seen: compares False
    # the skin darkens (or pales) toward its rim, so the midpoint of the two sides' means would move the outline by
    # that trend (~0.5 px on the real views); the level at the crest of the place's gradient is the midpoint at the edge
    placed = np.nan_to_num(placed).astype(np.float32)
    level = crest_level(placed, gradient_magnitude(placed), moved, np.full_like(placed, 0.5))
    snapped = mask.copy()
    if level is not None:
        snapped[moved] = placed[moved] > level[moved]
    count, pieces = cv2.connectedComponents(snapped.view(np.uint8), connectivity=8)
    held = np.unique(pieces[snapped & (inside > reach)])
    return fill_holes(np.isin(pieces, held[held > 0])) if held.any() else mask


def _off_ring(colour: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """The border ring's pixels far from its own colour (:data:`CROSSING_SPREADS`): ``[H, W]`` bool."""
    values = colour[ring]
    centre = np.median(values, axis=0)
    spread = float(np.median(np.linalg.norm(values - centre, axis=1)))
    return ring & (np.linalg.norm(colour - centre, axis=-1) > CROSSING_SPREADS * max(spread, _colour_floor(colour)))


class _Work(NamedTuple):
    """The working copy of a photo: gray ``[H, W]`` and colour ``[H, W, 3]`` float32 in [0, 1], 8-bit colour for
    GrabCut, the frame's border ring and its width, :func:`_edge_strength`, and the ring grown by two pixels (the
    outline along its inner side is no edge of the photo)."""
    gray: np.ndarray
    colour: np.ndarray
    colour8: np.ndarray
    ring: np.ndarray
    ring_width: int
    strength: np.ndarray
    near_ring: np.ndarray


def _working_copy(small: np.ndarray) -> _Work:
    """The :class:`_Work` of a photo already at the working size (``[H, W]`` or ``[H, W, 3]`` float32 in [0, 1])."""
    height, width = small.shape[:2]
    ring_width = max(2, int(RING_SHARE * max(height, width)))
    colour = small if small.ndim == 3 else np.repeat(small[..., None], 3, axis=2)
    colour8 = np.ascontiguousarray((colour * 255.0 + 0.5).astype(np.uint8))
    ring = _ring((height, width), ring_width)
    return _Work(_gray(small), colour, colour8, ring, ring_width, _edge_strength(colour), dilated(ring, 2))


def _cut(work: _Work, evidence: np.ndarray, period: np.ndarray, reach_share: float,
         crossing: np.ndarray | None = None) -> np.ndarray:
    """The finger's mask at the working size from its ridge ``evidence`` and their ``period`` (steps 2-4 of the
    module docstring); ``work``: the photo's working copy (:class:`_Work`). An
    InputError (naming nothing: the caller adds the image's name) where no piece shows ridges. ``crossing``: the ring's
    pixels where a finger crosses it (:func:`_off_ring`), probable finger instead of sure background, and no largest
    area of ridges taken for sure finger (the cut of a finger the frame cuts at both ends, once the others failed); the
    piece must then reach them."""
    gray, colour, colour8, ring, ring_width = work.gray, work.colour, work.colour8, work.ring, work.ring_width
    pad = _pad(evidence) if crossing is None else None
    pad = _sure_finger(pad, period, colour) if pad is not None else None
    labels = np.where(ring, cv2.GC_BGD, cv2.GC_PR_FGD).astype(np.uint8)
    if crossing is not None:
        labels[crossing] = cv2.GC_PR_FGD
    if pad is not None:  # skin where the finger enters the frame is not sure background; the pad is sure finger
        labels[ring & _skin_like(colour, pad, ring, SKIN_DISTANCE)] = cv2.GC_PR_BGD
        labels[pad] = cv2.GC_FGD
    least = max(MIN_RIDGE_SHARE * gray.size, MIN_RIDGE_AREA_PX)
    piece = _ridged_piece(colour8, labels.copy(), evidence, least)
    if piece is not None and crossing is not None and not (piece & dilated(crossing, ring_width)).any():
        piece = None  # a patch of the background's own texture, not a finger crossing the frame
    if piece is None:
        raise InputError("no finger found: nothing that stands apart from the frame's edges shows ridges "
                         "(out of focus, or no background to separate a finger from)")
    # The piece with the most ridges is the finger; the largest area of ridges need not be on it (in-focus lines that
    # cross make one; a faint finger's ridge areas are patches): its own is. Cut again, what is far from that skin's
    # colour, or brighter than its brightest (shading and slant darken skin), starting as probable background: had it
    # started as probable finger, GrabCut's finger colours would be learned from the clutter inside the frame too
    # (finger 1's real views on out-of-focus clutter: IoU 0.966 -> 0.996; with a distance per channel, blind to a
    # colour off the skin's own, it had made them worse, 0.72 -> 0.60; the brightness bound: the synthetic views on
    # in-focus clutter, worst IoU 0.67 -> 0.96)
    first, skin = piece, _piece_pad(piece, evidence, period, colour)
    if skin is not None:
        brightest = float(np.percentile(gray[skin], 99)) + _colour_floor(colour)
        labels[~ring] = cv2.GC_PR_FGD
        labels[~ring & ~(_skin_like(colour, skin, ring, PIECE_SKIN_DISTANCE) & (gray <= brightest))] = cv2.GC_PR_BGD
        labels[labels == cv2.GC_FGD] = cv2.GC_PR_FGD
        labels[skin] = cv2.GC_FGD
        again = _ridged_piece(colour8, labels, evidence, least)
        piece = again if again is not None else piece
    last = _refined(colour8, piece, evidence, period, ring_width, reach_share)
    return _best_supported((last, piece, first), work)


def _edge_strength(colour: np.ndarray) -> np.ndarray:
    """How strong an edge each pixel of the working copy lies on: the gradient's magnitude over the three channels of
    the copy blurred by :data:`EDGE_BLUR_PX` (the ridges fade, an object's outline stays). ``[H, W]`` float32."""
    smooth = cv2.GaussianBlur(colour, (0, 0), EDGE_BLUR_PX, borderType=cv2.BORDER_REPLICATE)
    channels = [gradient_magnitude(np.ascontiguousarray(smooth[..., k])) for k in range(smooth.shape[-1])]
    return np.sqrt(sum(channel * channel for channel in channels)).astype(np.float32)


def _edge_support(mask: np.ndarray, work: _Work) -> float | None:
    """The :data:`EDGE_PERCENTILE` of :func:`_edge_strength` along ``mask``'s outline away from the border ring (where
    a finger the frame cuts has its outline on the ring's inner side, no edge of the photo); None where fewer than
    :data:`MIN_OUTLINE_PX` outline pixels are left."""
    rim = outline(mask) & ~work.near_ring
    if np.count_nonzero(rim) < MIN_OUTLINE_PX:
        return None
    return float(np.percentile(work.strength[rim], EDGE_PERCENTILE))


def _on_no_edge(mask: np.ndarray, work: _Work) -> bool:
    """Whether ``mask``'s outline lies on no edge of the photo: its :func:`_edge_support` under
    :data:`WEAK_EDGE_SHARE` of the photo's strongest edges (their 99th percentile)."""
    support = _edge_support(mask, work)
    return support is not None and support < WEAK_EDGE_SHARE * float(np.percentile(work.strength, 99))


def _best_supported(masks: tuple[np.ndarray, ...], work: _Work, grown: bool = True) -> np.ndarray:
    """The first of ``masks`` (a cut's last piece, then its earlier ones), unless an earlier one's outline lies on
    edges :data:`EDGE_GAIN` times stronger (:func:`_edge_support`): each later cut drops what it takes for background,
    and where it takes the finger's own shaded half or highlit band its outline runs across the skin. Only where what
    the earlier one adds has the skin's hue (:func:`_same_hue`): on in-focus clutter, a piece holding coloured things
    beside the finger has their strong edges for outline. ``grown``: False where the masks are not a cut's stages
    (each earlier one the later grown) but rival cuts, taken by their edges alone.

    Measured: a finger of another make cut to 0.9 widths on a bright desk, its darker half dropped by the last cut
    (IoU 0.47; the outline's edges 0.04 against 1.08 for the piece before it, IoU 0.99), its lighter band by the
    second (0.84; 0.14 against 0.98, 0.99); the masks of ``tools/bench_backgrounds.py`` as before but one view on
    in-focus clutter mended (docs/measurements.md, stop 94)."""
    best, best_support = masks[0], _edge_support(masks[0], work)
    for mask in masks[1:]:
        support = _edge_support(mask, work)
        if (support is not None and (best_support is None or support >= EDGE_GAIN * best_support)
                and (not grown or _same_hue(mask & ~best, best, work.colour))):
            best, best_support = mask, support
    return best


def _same_hue(extra: np.ndarray, kept: np.ndarray, colour: np.ndarray) -> bool:
    """Whether the pixels ``extra`` have the chromaticity of ``kept`` (each pixel's colour over its sum, medians within
    :data:`HUE_DISTANCE`): the finger's shaded half is its own skin, darker; a thing beside it has its own hue. True
    where either is empty."""
    if not extra.any() or not kept.any():
        return True

    def median_chroma(pixels: np.ndarray) -> np.ndarray:  # of the set's pixels only, not the whole photo's
        return np.median(pixels / np.maximum(pixels.sum(axis=-1, keepdims=True), 1e-6), 0)

    return float(np.linalg.norm(median_chroma(colour[extra]) - median_chroma(colour[kept]))) <= HUE_DISTANCE


def _chosen(plain: np.ndarray | None, cut_again: Callable[[], np.ndarray | None],
            repeated: np.ndarray, work: _Work) -> np.ndarray | None:
    """Of the mask cut from the plain ridge score and the one cut from the score that asks the ridges to repeat
    (``cut_again()``, None where it finds no finger; ``repeated``, :func:`ridge_score`), the plain one, unless the
    other holds :data:`REPEATED_MORE` times its repeating ridges (the plain one found something else: a thing whose
    edges and lines read as ridges, or a finger whose ridges are too fine for the working copy), or the plain one swells
    past the finger by :data:`SWELL_MARGIN` more than the other
    (:func:`~fingersplat3d.segment.silhouette.outline_swell`: something of the skin's colour joined to it), or the
    plain one's outline lies on no edge of the photo (:func:`_on_no_edge`) and the other's on edges :data:`EDGE_GAIN`
    times stronger (:func:`_edge_support`). A desk of the skin's own grey, or one lit unevenly (a lamp beside it, so
    that its greys span the finger's), leaves GrabCut's colour models little to part them by, and the plain score's
    ridge evidence, reaching past the rims, held a band of desk all round the finger; the repeating ridges do not
    reach past them. Measured on the real grey views (docs/measurements.md, stop 107): on a lamp-lit desk IoU 0.93
    (0.89) finger 1, 0.95 (one view lost) finger 2 held out, now 0.995 (0.988) and 0.990 (0.954); on a plain desk of
    the skin's grey 0.88-0.89, now 0.995-0.999. Either where the other is None. The second cut is made only where it
    could be taken: not where the plain one holds that share of the image's repeating ridges already, swells within
    the margin (no mask's swell is under 1) and lies on the photo's edges."""
    if plain is None:
        return cut_again()
    ridged = repeated > RIDGE_LEVEL
    held, swell = np.count_nonzero(ridged & plain), outline_swell(plain)
    no_edge = _on_no_edge(plain, work)
    if (REPEATED_MORE * held >= np.count_nonzero(ridged) and (swell is None or swell <= SWELL_MARGIN)
            and not no_edge):
        return plain
    again = cut_again()
    if again is None:
        return plain
    if np.count_nonzero(ridged & again) > REPEATED_MORE * held:
        return again
    again_swell = outline_swell(again)
    if swell is not None and again_swell is not None and swell > SWELL_MARGIN * again_swell:
        return again
    if no_edge:
        ours, theirs = _edge_support(plain, work), _edge_support(again, work)
        if ours is not None and theirs is not None and theirs >= EDGE_GAIN * ours:
            return again
    return plain


def _framed_cut(work: _Work, evidence: tuple[np.ndarray, np.ndarray], reach: float,
                crossing: np.ndarray | None = None) -> np.ndarray:
    """:func:`_cut` from ``evidence`` (the ridge score and its period) carried out across the border ring where it
    reaches it, holes filled (steps 2-5 of the module docstring)."""
    return fill_holes(_to_border(_cut(work, *evidence, reach, crossing), work.ring_width))


def _crossing_cut(work: _Work, evidence: tuple[np.ndarray, np.ndarray],
                  found: np.ndarray | None = None) -> np.ndarray | None:
    """The finger's mask where it crosses the frame's border ring (a crop cut at both ends), or None: tried only where
    :data:`MIN_CROSSING_SHARE` of the ring is off its own colour, and where the other cuts' mask ``found`` holds less
    than :data:`CROSSING_HELD` of those pixels; None where it holds no more of them than ``found`` (the caller takes it
    over ``found`` only where its outline lies on stronger edges, :func:`_best_supported`). Measured: a
    finger of another make cropped to 0.9 widths on a bright desk, its ridges fainter than the desk's grain (8 % of the
    finger over the ridge level against 22 % of the frame): no finger found by the other cuts (the largest area of
    ridges lay on the desk, and GrabCut learned the skin crossing the ring as background); with this cut IoU 0.999
    (docs/measurements.md, stop 93); another, whose other cuts took a patch of the desk beside it (IoU 0.00): 0.99
    (stop 94)."""
    crossing = _off_ring(work.colour, work.ring)
    total = np.count_nonzero(crossing)
    if total < MIN_CROSSING_SHARE * np.count_nonzero(work.ring):
        return None
    held = 0 if found is None else np.count_nonzero(found & crossing)
    if held >= CROSSING_HELD * total:
        return None
    try:
        crossed = _framed_cut(work, evidence, RIDGE_REACH_SHARE, crossing)
    except InputError:
        return None
    return crossed if np.count_nonzero(crossed & crossing) > held else None


def _filled_or(finger: np.ndarray | None, work: _Work) -> np.ndarray | None:
    """``finger`` (the other cuts' mask at the working size, or None), or the cut of a finger that fills the frame
    (:func:`~fingersplat3d.segment.filled_frame.filling_cut`) where that holds the skin found on the border ring and
    ``finger`` is None, leaves half that skin out (:func:`~fingersplat3d.segment.filled_frame.holds_ring_skin`: it took
    the ring for background), or lies on no edge of the photo (:func:`_on_no_edge`) where the filling cut's outline lies
    on stronger ones (:func:`_edge_support`). Measured: real dev views cut to 0.6-0.8 of their width on a desk or
    clutter, the other cuts' masks held the ring's skin at 0.86-0.88 but lay on edges of 0.06 of the photo's scale
    (IoU 0.70-0.73), the filling cut's on 0.08-0.13 (0.73-0.92); cut at both ends instead, the other cuts' masks lay on
    0.33-1.29 (IoU 0.95-1.00) and the filling cut's were at times worse (0.68-0.83), so those are kept."""
    ring, skin = ring_skin(work.colour)  # once: each test below asks of the same ring
    held = finger is not None and holds_ring_skin(finger, ring, skin)
    if held and not _on_no_edge(finger, work):
        return finger
    filled = filling_cut(work.colour, work.colour8, ring, skin)
    if filled is None or not holds_ring_skin(filled, ring, skin):
        return finger
    if not held:
        return filled
    ours, theirs = _edge_support(filled, work), _edge_support(finger, work)
    return filled if ours is not None and (theirs is None or ours > theirs) else finger


def finger_mask_any_background(image: np.ndarray, *, name: str = "image") -> np.ndarray:
    """The finger's silhouette ``[H, W]`` bool in ``image`` (``[H, W]`` or ``[H, W, 3]`` float in [0, 1]) on any
    background (see the module docstring)."""
    height, width = image.shape[:2]
    factor = min(1.0, WORK_SIDE / max(height, width))
    size = scaled_size((width, height), factor)
    small = cv2.resize(image, size, interpolation=cv2.INTER_AREA) if factor < 1.0 else image
    small = np.clip(np.asarray(small, np.float32), 0.0, 1.0)
    top = float(np.percentile(small, 99.5))
    stretch = 1.0 / top if 0.0 < top < 0.5 else 1.0  # a dim exposure (16-bit data using the bottom of its range)
    small = np.clip(small * stretch, 0.0, 1.0)  # ... stretched before 8-bit GrabCut and the edge's contrast test
    work = _working_copy(small)
    if work.ring.all():  # a strip thinner than two border rings: nothing inside them to be a finger
        raise InputError(f"{name}: no finger found: the image is {width}x{height} pixels, too thin to hold one")
    full = np.clip(np.asarray(image, np.float32) * stretch, 0.0, 1.0)
    plain_evidence, repeated = _ridge_evidence(work.gray, _gray(full) if factor < 1.0 else None)

    def cut_again() -> np.ndarray | None:
        try:
            return _framed_cut(work, repeated, REPEATED_REACH_SHARE)
        except InputError:
            return None

    try:
        plain, problem = _framed_cut(work, plain_evidence, RIDGE_REACH_SHARE), None
    except InputError as error:
        plain, problem = None, error
    finger = _chosen(plain, cut_again, repeated[0], work)
    if finger is None:  # a finger the frame cuts at both ends fills much of the ring GrabCut took as background
        finger = _crossing_cut(work, plain_evidence)
    elif _on_no_edge(finger, work):  # ... or left out where a patch of the background's own texture was taken for it
        crossed = _crossing_cut(work, plain_evidence, finger)
        finger = finger if crossed is None else _best_supported((finger, crossed), work, grown=False)
    finger = _filled_or(finger, work)
    if finger is None:
        raise InputError(f"{name}: {problem}")
    if factor < 1.0:  # back to full size with a smooth edge
        finger = cv2.resize(finger.astype(np.float32), (width, height), interpolation=cv2.INTER_LINEAR) > 0.5
    full = full if full.ndim == 3 else np.repeat(full[..., None], 3, axis=2)
    return _on_the_edge(full, finger, 2.0 / factor + 1.0)
