"""Classical finger segmentation: a finger photographed on a dark background (and the switch to any other).

A photo whose frame border is not dark (a phone photo on a desk, a bright or cluttered room) goes to
:mod:`fingersplat3d.segment.any_background` instead; every dark-background photo of the project's data (real,
another group's renders, synthetic) has its border ring at most 0.1 of its bright end.

:func:`finger_mask` works on one image (grayscale ``H x W`` or RGB ``H x W x 3``, float in [0, 1],
any exposure: 16-bit data that only uses the bottom of the range works too):

1. brightness = the brightest channel (skin is bright in at least one channel on a dark
   background), smoothed by a small Gaussian so ridge texture and sensor noise average out;
2. a rough two-class split by Otsu's threshold on a subsample of the pixels (a few hot pixels
   cannot move a histogram split) gives the background level and noise and the skin level; where the skin does not
   stand out from the dark class so found (a finger's shaded flank as dim as a neighbour beside it is bright, three
   levels), that class is split again, as long as its darker part is a level of its own, not a noise tail;
3. the threshold is the midpoint between the background and the skin *at the silhouette*, read
   in a thin band inside a first, low-threshold mask and averaged locally, since the lit side's
   rim is brighter than the shaded side's. The midpoint of a blurred step is where the edge is,
   so the outline lands on the true silhouette on both sides; a plain Otsu split (between the
   background and the *mean* skin) cuts off the darker rim. Skin lit from one side darkens
   gradually toward its far flank, and the band there reads skin brighter than the rim: the level
   is read again inside the mask each midpoint gives, while that moves the edge out by more than
   1 % of the area and leaves the mask as solid (area over convex hull; light spilt on the
   background in stripes, such as projected fringes, would grow it unevenly);
   that level is then moved to the brightness at the crest of the edge's gradient (:func:`_crest_level`): a
   photo's out-of-focus sides (a phone's close-up) ramp over more than the band, where a level read inside falls
   short and the outline grows by about the blur, while a symmetric blur leaves the crest on the true edge;
4. skin darker than that midpoint (valleys, the crease, the shaded side) still clears a noise
   floor; the noise-floor mask, eroded by 2 px (more than its outward bias), fills such notches,
   but only where a closing of the skin mask encloses them: a dim glow or support under the
   finger (seen on real UWA side views) clears the noise floor as well and is not skin;
5. morphological close then open (kernel ~0.5 % of the image size), the outline smoothed by a
   sub-pixel blur of the mask, the largest connected component, holes filled;
6. a neighbouring finger joined to it is cut away (:mod:`~fingersplat3d.segment.neighbours`; both backgrounds).

Measured on ``fs3d synth`` uwa views at 640x512 (docs/measurements.md, the phone close-up's section): IoU >= 0.9966
(median 0.999) against the ground-truth mask sharp, >= 0.976 with the rims blurred by sigma 8 px; ~45 ms at 640x512 and
~270 ms at 1280x1024 on the project's 2-core machine (under load), and the neighbour check of step 6 11 / 44 ms more
(Zen 3).

It fails with an :class:`~fingersplat3d.errors.InputError` naming the image when there is no
finger (an empty, constant or pure-noise image) or no background (the finger would cover
nearly the whole frame).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..errors import InputError
from ..robust import robust_sigma
from .morphology import disc, outline
from .filled_frame import BLACK_SHARE, MIN_DARK_RING, MIN_SKIN_SHARE, ring_skin
from .neighbours import one_finger
from .regions import crest_level, fill_holes, gradient_magnitude, largest_component, local_sums

__all__ = ["finger_mask", "mask_iou", "outward_px", "outline_offset_px"]

SMOOTH_SIGMA_PX = 1.0  # Gaussian pre-smoothing (pixels): averages noise, keeps the edge in place
MIN_CONTRAST_SIGMAS = 6.0  # skin must stand this many background-noise sigmas above the background
MAX_COVERAGE = 0.95  # a "finger" covering more of the frame than this means there is no background
BACKGROUND_SPLITS = 2  # at most this many further splits of the dark class where it holds skin (_thresholds)
MIN_AREA_PX = 4  # fewer finger pixels than this is no finger
LOW_MASK_EROSION_PX = 2  # more than the outward bias of the noise-floor edge (~1 px after blurs)
ROUGH_LEVEL = 0.25  # share of the skin contrast above which the first, rough mask lies (above dim glows)
NOTCH_RADIUS_SCALE = 4  # notches (valleys, a crease) narrower than this many closing radii are filled
DARK_BORDER_SHARE = 0.35  # a border ring darker than this share of the bright end is a dark background
HAZY_BORDER_SHARE = 0.6  # ... and up to this share, a hazy one: tried by brightness where the ridges found no finger
EDGE_BAND = (1.5, 4.0)  # band inside the rough mask (px from its edge) where the edge skin level is read
EDGE_ROUNDS = 8  # at most this many more reads of the edge level, inside the mask the last one gave
EDGE_GROWTH = 0.01  # a read is kept when its mask is larger than the last one's by more than this share
EDGE_SOLIDITY_LOSS = 0.01  # ... and its largest piece's solidity (area / convex hull) is not lower by more than this
CREST_BAND = 0.012  # half-width of the band about the outline where the gradient's crest is looked for (share of the long side)
CREST_BLUR_PX = 2.0  # the brightness is blurred this much more before its gradient: ridges fade, the edge's crest stays put
CREST_ROUNDS = 3  # the band is centred again on the outline the last level gave


def finger_mask(image: np.ndarray, *, name: str = "image") -> np.ndarray:
    """The finger's silhouette ``[H, W]`` bool in ``image`` (``[H, W]`` or ``[H, W, 3]`` in [0, 1]): on a dark
    background by brightness (below); on any other (the frame's border ring brighter than
    :data:`DARK_BORDER_SHARE` of the image's bright end) by its ridges and GrabCut
    (:mod:`~fingersplat3d.segment.any_background`). A border ring up to :data:`HAZY_BORDER_SHARE` of the bright end
    (a dark background under haze or glare, a photo's contrast lowered) is also tried by brightness where the ridges
    found no finger (blurred or faint). A finger that fills the frame across its width, its skin over most of the ring
    and a dark background over the rest, is taken by brightness too (:func:`_filled_dark_frame`)."""
    brightness = _brightness(image, name)
    if not _dark_border(brightness):
        filled = _filled_dark_frame(image, brightness, name)
        if filled is not None:
            return filled
        from .any_background import finger_mask_any_background

        try:
            return one_finger(finger_mask_any_background(np.asarray(image, np.float32), name=name))
        except InputError as no_ridges:
            if not _dark_border(brightness, HAZY_BORDER_SHARE):
                raise
            try:
                return _bright_mask(brightness, name)
            except InputError:
                raise no_ridges from None
    return _bright_mask(brightness, name)


def _bright_mask(brightness: np.ndarray, name: str) -> np.ndarray:
    """The finger's silhouette by brightness, against a background darker than the skin (:func:`finger_mask`)."""
    height, width = brightness.shape
    smooth = cv2.GaussianBlur(brightness, (0, 0), SMOOTH_SIGMA_PX, borderType=cv2.BORDER_REPLICATE)
    floor, threshold = _thresholds(smooth, name)
    threshold = _crest_level(smooth, threshold, floor)
    # Skin darker than the midpoint (valleys, a crease, the shaded side) still clears the noise
    # floor; that low mask, eroded past its outward bias, fills such notches without moving edges.
    low = cv2.erode((smooth > floor).view(np.uint8), disc(LOW_MASK_EROSION_PX), borderType=cv2.BORDER_REPLICATE)
    high = (smooth > threshold).view(np.uint8)
    radius = max(1, round(0.005 * max(height, width)))
    kernel = disc(radius)
    # Only notches of the skin mask are filled from the low mask: a dim glow or a support under
    # the finger clears the noise floor too, but it is not enclosed by skin.
    notches = cv2.morphologyEx(high, cv2.MORPH_CLOSE, disc(NOTCH_RADIUS_SCALE * radius), borderType=cv2.BORDER_REPLICATE)
    mask = high.view(bool) | (low.view(bool) & notches.view(bool))
    mask8 = mask.view(np.uint8)
    # Close then open; the border is replicated so a finger cut by the frame stays cut straight.
    mask8 = cv2.morphologyEx(mask8, cv2.MORPH_CLOSE, kernel, borderType=cv2.BORDER_REPLICATE)
    mask8 = cv2.morphologyEx(mask8, cv2.MORPH_OPEN, kernel, borderType=cv2.BORDER_REPLICATE)
    mask = largest_component(_smooth_outline(mask8.view(bool), radius).view(np.uint8))
    if mask is None or mask.sum() < min(MIN_AREA_PX, height * width):
        raise InputError(f"{name}: no finger found (nothing stands out from the dark background)")
    mask = one_finger(fill_holes(mask))
    if mask.mean() > MAX_COVERAGE:
        raise InputError(f"{name}: the finger covers {100 * mask.mean():.0f}% of the image, "
                         "so there is no background to separate it from")
    return mask


def _filled_dark_frame(image: np.ndarray, brightness: np.ndarray, name: str) -> np.ndarray | None:
    """The finger's silhouette by brightness where it fills the frame across its width on a dark background
    (:mod:`~fingersplat3d.segment.filled_frame`), or None where the photo is not that: under
    :data:`~fingersplat3d.segment.filled_frame.MIN_DARK_RING` of the border ring dark, or a brightness mask that holds
    the ring's skin (:func:`~fingersplat3d.segment.filled_frame.ring_skin`) over less than
    :data:`~fingersplat3d.segment.filled_frame.MIN_SKIN_SHARE` of its part of the ring (a lit wall), or leaves a ring
    that is not black (:data:`~fingersplat3d.segment.filled_frame.BLACK_SHARE`: a bright desk, the finger's shaded
    flank its dark)."""
    ring, skin = ring_skin(np.asarray(image, np.float32))
    small = cv2.resize(brightness, ring.shape[::-1], interpolation=cv2.INTER_AREA)
    bright = _bright_end(brightness)
    if np.count_nonzero(ring & (small <= DARK_BORDER_SHARE * bright)) < MIN_DARK_RING * np.count_nonzero(ring):
        return None
    try:
        mask = _bright_mask(brightness, name)
    except InputError:
        return None
    held = cv2.resize(mask.view(np.uint8), ring.shape[::-1], interpolation=cv2.INTER_NEAREST).view(bool)
    crossed, left = ring & held, ring & ~held
    if (np.count_nonzero(skin & crossed) < MIN_SKIN_SHARE * max(np.count_nonzero(crossed), 1)
            or not left.any() or np.median(small[left]) > BLACK_SHARE * bright):
        return None
    return mask


def _bright_end(brightness: np.ndarray) -> float:
    """The image's bright end: its 90th-percentile brightness, over ~65k pixels."""
    step = max(1, int(np.sqrt(brightness.size / 65536)))
    return float(np.percentile(brightness[::step, ::step], 90))


def _dark_border(brightness: np.ndarray, share: float = DARK_BORDER_SHARE) -> bool:
    """Whether the frame's border ring (2 % of the long side) is dark: its median at most ``share`` of the image's
    90th percentile brightness. A finger enters the frame at one side at most two, so the ring is mostly background."""
    height, width = brightness.shape
    ring = max(1, int(0.02 * max(height, width)))
    border = np.concatenate([brightness[:ring].ravel(), brightness[-ring:].ravel(),
                             brightness[:, :ring].ravel(), brightness[:, -ring:].ravel()])
    bright = _bright_end(brightness)
    return bool(np.median(border) <= share * bright)


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks of the same shape (1.0 when both are empty)."""
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    if a.shape != b.shape:
        raise ValueError(f"masks have different shapes {a.shape} and {b.shape}")
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union


def outward_px(found: np.ndarray, truth: np.ndarray) -> float:
    """How far ``found``'s outline lies outside ``truth``'s on average, px, to a fraction of a pixel: the area between
    them (signed: positive for a mask too wide) over the true outline's length. NaN when ``truth`` is empty."""
    found, truth = np.asarray(found, bool), np.asarray(truth, bool)
    if found.shape != truth.shape:
        raise ValueError(f"masks have different shapes {found.shape} and {truth.shape}")
    contours, _ = cv2.findContours(truth.view(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return float("nan")
    return float(np.count_nonzero(found) - np.count_nonzero(truth)) / max(cv2.arcLength(max(contours, key=cv2.contourArea), True), 1.0)


def outline_offset_px(found: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """How far ``found``'s outline lies from ``truth``'s, in pixels: the median signed distance of its outline pixels
    from the true outline (positive outside the true mask: a mask too wide) and the 90th percentile of the distance.
    NaN when either mask is empty."""
    found, truth = np.asarray(found, bool), np.asarray(truth, bool)
    if found.shape != truth.shape:
        raise ValueError(f"masks have different shapes {found.shape} and {truth.shape}")
    if not found.any() or not truth.any():
        return float("nan"), float("nan")
    distance = cv2.distanceTransform((~outline(truth)).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    on = outline(found)
    signed = np.where(truth[on], -distance[on], distance[on])
    return float(np.median(signed)), float(np.percentile(np.abs(signed), 90))


def _brightness(image: np.ndarray, name: str) -> np.ndarray:
    """Validated float32 ``[H, W]`` brightness: the image itself, or its brightest channel."""
    array = np.asarray(image)
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[..., 0]
    elif array.ndim == 3 and array.shape[2] in (3, 4):  # RGB(A): the brightest colour channel
        array = np.maximum(np.maximum(array[..., 0], array[..., 1]), array[..., 2])
    if array.ndim != 2 or array.size == 0:
        raise InputError(f"{name}: expected an HxW or HxWx3 image, got shape {np.shape(image)}")
    array = np.asarray(array, np.float32)
    if not np.isfinite(array.sum(dtype=np.float64)):  # NaN and Inf survive a sum
        raise InputError(f"{name}: the image contains NaN or Inf")
    return np.ascontiguousarray(array)


def _thresholds(smooth: np.ndarray, name: str) -> tuple[float, np.ndarray]:
    """The noise floor and the per-pixel midpoint between background and silhouette-edge skin."""
    step = max(1, int(np.sqrt(smooth.size / 65536)))  # statistics from ~65k pixels suffice
    sample = smooth[::step, ::step].ravel()
    low, high = float(sample.min()), float(sample.max())
    if not high > low:
        raise InputError(f"{name}: no finger found (the image is constant)")
    split = _otsu(sample, low, high)
    background, skin = sample[sample <= split], sample[sample > split]
    if background.size < (1.0 - MAX_COVERAGE) * sample.size:
        raise InputError(f"{name}: the image is bright almost everywhere, so there is no background "
                         "to separate a finger from")
    bg_level, bg_noise, contrast = _levels(background, skin)
    for _ in range(BACKGROUND_SPLITS):
        # Three levels, not two (skin in shade beside lit skin, a dim finger beside a brighter one): the split fell
        # between the skins and the dark class holds skin too. Only where the skin does not stand out from that class
        # (an image that would otherwise be refused): it is split again while the background it leaves is large
        # enough to be the frame's and stands apart from the rest of it.
        if contrast > MIN_CONTRAST_SIGMAS * bg_noise:
            break
        lower = _otsu(background, float(background.min()), float(background.max()))
        darker = background[background <= lower]
        if darker.size < (1.0 - MAX_COVERAGE) * sample.size or not lower < split:
            break
        level, noise, apart = _levels(darker, background[background > lower])
        if apart <= MIN_CONTRAST_SIGMAS * noise:  # one level with a tail (noise): no skin in it to split off
            break
        split, background, skin = lower, darker, sample[sample > lower]
        bg_level, bg_noise, contrast = _levels(background, skin)
    if contrast <= MIN_CONTRAST_SIGMAS * bg_noise or contrast < 1e-3 * max(high, 1e-12):
        raise InputError(f"{name}: no finger found (nothing stands out from the background noise)")
    floor = bg_level + max(MIN_CONTRAST_SIGMAS * bg_noise, 0.05 * contrast)
    # A first mask from a low threshold keeps the darker skin at the silhouette; the skin level
    # at the silhouette is read in a thin band inside it.
    region = (smooth > max(floor, bg_level + ROUGH_LEVEL * contrast)).view(np.uint8)
    midpoint = _edge_midpoint(smooth, region, bg_level, floor)
    if midpoint is None:
        return floor, np.full_like(smooth, max(floor, bg_level + 0.5 * contrast))
    # Skin shaded toward one side (light from the other) darkens gradually to a rim far dimmer than the band read: the
    # midpoint then cuts inside the finger. Read again inside the mask it gives, as long as that moves the edge out
    # and leaves the mask as solid (light spilt on the background, such as projected fringes, grows it in stripes).
    region = (smooth > midpoint).view(np.uint8)
    area, solid = int(np.count_nonzero(region)), None  # the solidity only where a read grows the mask
    for _ in range(EDGE_ROUNDS):
        again = _edge_midpoint(smooth, region, bg_level, floor)
        if again is None:
            break
        grown = (smooth > again).view(np.uint8)
        grown_area = int(np.count_nonzero(grown))
        if grown_area <= area * (1.0 + EDGE_GROWTH):
            break
        solid = _solidity(region) if solid is None else solid
        grown_solid = _solidity(grown)
        if grown_solid < solid - EDGE_SOLIDITY_LOSS:
            break
        midpoint, region, area, solid = again, grown, grown_area, grown_solid
    return floor, midpoint


def _levels(background: np.ndarray, skin: np.ndarray) -> tuple[float, float, float]:
    """The background's level and noise (robust sigma) and the skin's contrast above it."""
    level = float(np.median(background))
    return level, robust_sigma(background, level), float(np.median(skin)) - level


def _crest_level(smooth: np.ndarray, threshold: np.ndarray, floor: float) -> np.ndarray:
    """The per-pixel level at the crest of the outline's gradient, starting from ``threshold``'s outline.

    The midpoint of :func:`_thresholds` takes the skin's level in a band a few pixels inside the outline. An edge out
    of focus (a phone's close-up, whose finger sides fall out of its depth of field) ramps over more than that band,
    so the level read is low and the outline grows by about the blur (1.3 px at sigma 4, 7 px at sigma 8 on the
    synthetic close-ups of ``tools/bench_defocus.py``). Wherever a step is blurred symmetrically, its gradient peaks
    at the true edge and the brightness there is the midpoint, whatever the blur. So the level is the brightness
    averaged over a band about the outline weighted by the gradient magnitude to a power
    (:func:`~fingersplat3d.segment.regions.crest_level`: the crest outweighs the skin's ramp toward a shaded rim and
    the ridges, faded by :data:`CREST_BLUR_PX`), averaged locally like the midpoint; the band is centred again on each
    new outline, :data:`CREST_ROUNDS` times."""
    height, width = smooth.shape
    magnitude = gradient_magnitude(cv2.GaussianBlur(smooth, (0, 0), CREST_BLUR_PX, borderType=cv2.BORDER_REPLICATE))
    half_width = max(4.0, CREST_BAND * max(height, width))
    for _ in range(CREST_ROUNDS):
        mask8 = (smooth > threshold).view(np.uint8)
        inside = cv2.distanceTransform(mask8, cv2.DIST_L2, 3)
        outside = cv2.distanceTransform(1 - mask8, cv2.DIST_L2, 3)
        level = crest_level(smooth, magnitude, (inside <= half_width) & (outside <= half_width), threshold)
        if level is None:
            break
        threshold = np.maximum(floor, level)
    return threshold


def _solidity(mask8: np.ndarray) -> float:
    """Area over convex-hull area of the largest piece of ``mask8`` (1: convex; 0 when empty)."""
    contours, _ = cv2.findContours(mask8, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return 0.0
    largest = max(contours, key=cv2.contourArea)
    hull = cv2.contourArea(cv2.convexHull(largest))
    return float(cv2.contourArea(largest) / hull) if hull > 0 else 0.0


def _edge_midpoint(smooth: np.ndarray, region: np.ndarray, bg_level: float, floor: float) -> np.ndarray | None:
    """Per pixel, the midpoint between the background and the skin level read in a thin band inside ``region``
    (uint8); None when the band is too thin to read. That level differs between the lit and the shaded side, so it is
    averaged locally (normalised Gaussian over ~1.5 % of the image size), on a grid a few times coarser than the
    image, which is all such a smooth map needs."""
    inside = cv2.distanceTransform(region, cv2.DIST_L2, 3)
    band = ((inside >= EDGE_BAND[0]) & (inside <= EDGE_BAND[1])).astype(np.float32)
    if np.count_nonzero(band) < 16:
        return None
    height, width = smooth.shape
    weight, total = local_sums(band, band * smooth)
    edge_level = float(total.sum() / max(weight.sum(), 1e-12))  # where no band is near
    local = np.where(weight > 1e-4, total / np.maximum(weight, 1e-4), edge_level).astype(np.float32)
    midpoint = np.maximum(floor, 0.5 * (bg_level + local))
    return cv2.resize(midpoint, (width, height), interpolation=cv2.INTER_LINEAR)


def _otsu(values: np.ndarray, low: float, high: float, bins: int = 256) -> float:
    """Otsu's threshold of ``values`` (a 256-bin histogram over ``[low, high]``)."""
    histogram, edges = np.histogram(values, bins=bins, range=(low, high))
    p = histogram.astype(np.float64) / histogram.sum()
    centres = 0.5 * (edges[:-1] + edges[1:])
    omega = np.cumsum(p)
    mu = np.cumsum(p * centres)
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mu[-1] * omega - mu) ** 2 / (omega * (1.0 - omega))
    between[~np.isfinite(between)] = -1.0
    return float(edges[int(np.argmax(between)) + 1])


def _smooth_outline(mask: np.ndarray, radius: int) -> np.ndarray:
    """Round off pixel staircases: blur the mask a little and cut it at one half."""
    sigma = 0.5 * radius
    if sigma < 0.75:
        return mask
    blurred = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
    smoothed = blurred > 0.5
    return smoothed if smoothed.any() else mask
