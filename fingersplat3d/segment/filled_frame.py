"""A finger that fills the frame across its width: the frame's border ring is mostly skin, not background.

Both segmentations read the background from the frame's border ring (2 % of the long side): the dark-background one
takes a photo whose ring is dark for a dark-background photo, the one for any background
(:mod:`~fingersplat3d.segment.any_background`) takes the ring for background. A tight crop of a finger (a dataset's
crop, a phone's close-up) cut by the frame along both flanks and at its base has skin over most of the ring: the
ring's median is skin, so a finger on a dark background went to the other segmentation, which took the skin for
background (real dev views cut to 0.8 of the finger's width: mask IoU 0.64-0.88, against 0.999 by brightness).

:func:`ring_skin` finds the ring's skin: pixels of the pad's colour (the image centre's, which such a crop shows;
:func:`~fingersplat3d.segment.any_background._colour_distance`) whose ridge-band texture is at least
:data:`TEXTURE_SHARE` of the centre's. A plain desk or out-of-focus clutter is smooth, in-focus clutter is not the
pad's colour, and a finger's shaded flank is missed (it is darker than the centre): measured on the real dev views
composited onto the three backgrounds of :mod:`~fingersplat3d.experiments.backgrounds`, the share of the ring found
skin is the same on every background to 0.02-0.04 (a whole view 0.00-0.03 of its ring; cut to 0.8 of its width 0.23-
0.57 of the 0.59-0.66 its mask holds).

:func:`~fingersplat3d.segment.masks.finger_mask` takes a photo whose ring is not dark for a dark-background photo where
at least :data:`MIN_DARK_RING` of the ring is dark, its brightness mask holds the ring's skin (:data:`MIN_SKIN_SHARE`)
and leaves a black ring (:data:`BLACK_SHARE`); the other segmentation takes :func:`filling_cut` where its own mask
leaves out the ring's skin (:func:`holds_ring_skin`: a finger cut at both ends, carried out to the frame, holds it).
Pure numpy/OpenCV.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..scene import scaled_size

__all__ = ["ring_skin", "filling_cut", "holds_ring_skin", "HELD_SKIN", "FILL_SHARE", "WORK_SIDE", "TEXTURE_SHARE",
           "SKIN_DISTANCE", "MIN_DARK_RING", "MIN_SKIN_SHARE", "BLACK_SHARE"]

WORK_SIDE = 640
"""Long side (pixels) the ring is examined at."""
RING_SHARE = 0.02
"""Width of the frame's border ring, a share of the long side (as both segmentations take it)."""
CENTRE_SHARE = 0.25
"""The image centre whose colour and texture are the pad's: a box this share of each side."""
SKIN_DISTANCE = 3.0
"""A ring pixel within this colour distance of the centre's colours may be skin."""
TEXTURE_SHARE = 0.2
"""... if its ridge-band energy is at least this share of the centre's median (ridges, not a plain surface)."""
BAND_SIGMAS = (0.7, 2.0)
"""The ridge band: the gray image blurred by the first (px at the working size) less it blurred by the second (ridge
periods of ~3-10 px there: 6-20 px in a 1280-px photo)."""
MIN_BAND_OVER_NOISE = 1.0
"""The centre shows ridges only where its ridge band's energy is at least this many times that of the band finer than
it (median over the centre): measured 2.2-6.1 on the real dev views' pads, 0.22-0.24 on sensor noise (a plain desk)."""
MIN_RIDGE_CONTRAST = 0.005
"""... and the band's RMS is at least this share of the centre's median brightness: the real pads 0.005-0.018 RMS at
0.3-0.5 brightness (0.014-0.05), out-of-focus clutter 0.001 at ~0.5."""
ENERGY_SIGMA = 4.0
"""The band's square is averaged over this many pixels (about a ridge period)."""
FILL_SHARE = 0.2
"""A frame whose border ring is found skin (:func:`ring_skin`) over at least this share may be a finger filling it
(:func:`filling_cut`, :func:`holds_ring_skin`). Measured on the real dev views: whole 0.00-0.03, cut to the finger's
width 0.07-0.28, to 0.8 of it 0.23-0.57; cut at both ends (no tip, no base) 0.3-0.34, where the other cut's mask,
carried out to the frame, holds the skin."""
CLOSE_SHARE = 0.05
"""The ring's runs of skin are closed over this share of the long side (:func:`filling_cut`)."""
NEAR_SKIN_DISTANCE = 5.0
"""Ring pixels within this colour distance of the pad's start as probable background, not sure (:func:`filling_cut`)."""
HELD_SKIN = 0.5
"""A mask holds the ring's skin where at least this share of it lies inside (:func:`holds_ring_skin`)."""
MIN_DARK_RING = 0.1
"""A frame the finger fills still shows its background over at least this share of its ring (dark, for the
dark-background segmentation; off the skin, for :func:`filling_cut`)."""
MIN_SKIN_SHARE = 0.1
"""... and at least this share of the ring that the brightness mask holds is found skin (:func:`ring_skin`): that mask
is the finger, not a lit wall or a window (plain). Measured on the real dev views cut to 0.6-0.8 of their width:
0.17-0.87 (a finger's shaded flank is missed)."""
BLACK_SHARE = 0.1
"""... and the ring that mask leaves has its median under this share of the image's 90th-percentile brightness: a dark
background (0.005-0.01 of it on those views; every dark-background photo of the project's data under 0.1), not the
finger's own shaded skin beside a bright desk taken for the finger."""


def _working(image: np.ndarray) -> np.ndarray:
    """``image`` (``[H, W]`` or ``[H, W, 3]`` float in [0, 1]) as ``[h, w, 3]`` float32 at most :data:`WORK_SIDE`."""
    height, width = image.shape[:2]
    factor = min(1.0, WORK_SIDE / max(height, width))
    small = np.asarray(image, np.float32)
    if factor < 1.0:
        small = cv2.resize(small, scaled_size((width, height), factor), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(small if small.ndim == 3 else np.repeat(small[..., None], 3, axis=2))


def _ring(shape: tuple[int, int]) -> np.ndarray:
    ring = np.zeros(shape, bool)
    width = max(2, int(RING_SHARE * max(shape)))
    ring[:width], ring[-width:], ring[:, :width], ring[:, -width:] = True, True, True, True
    return ring


def _centre(shape: tuple[int, int]) -> np.ndarray:
    """The image centre's box (:data:`CENTRE_SHARE` of each side), ``[h, w]`` bool."""
    height, width = shape
    centre = np.zeros(shape, bool)
    half_h, half_w = max(1, int(CENTRE_SHARE * height / 2)), max(1, int(CENTRE_SHARE * width / 2))
    centre[height // 2 - half_h: height // 2 + half_h, width // 2 - half_w: width // 2 + half_w] = True
    return centre


def ring_skin(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(ring, skin)`` at the working size (``[h, w]`` bool each): the frame's border ring and which of its pixels are
    skin of the pad (the image centre's colour, textured like it; see the module docstring); no skin where the centre
    shows no ridges (:data:`MIN_BAND_OVER_NOISE`, :data:`MIN_RIDGE_CONTRAST`). ``image``: ``[H, W]`` or
    ``[H, W, 3]`` float in [0, 1]."""
    from .grabcut import _colour_distance, _gray

    colour = _working(image)
    height, width = colour.shape[:2]
    ring = _ring((height, width))
    centre = _centre((height, width))
    gray = _gray(colour)
    finer = cv2.GaussianBlur(gray, (0, 0), BAND_SIGMAS[0])
    band = finer - cv2.GaussianBlur(gray, (0, 0), BAND_SIGMAS[1])
    energy = cv2.GaussianBlur(band * band, (0, 0), ENERGY_SIGMA)
    noise = cv2.GaussianBlur((gray - finer) ** 2, (0, 0), ENERGY_SIGMA)
    pad = float(np.median(energy[centre]))
    if (np.median(energy[centre] / np.maximum(noise[centre], 1e-12)) < MIN_BAND_OVER_NOISE
            or np.sqrt(pad) < MIN_RIDGE_CONTRAST * float(np.median(gray[centre]))):
        return ring, np.zeros_like(ring)  # the centre shows no ridges: sensor noise, or a plain thing
    textured = energy > TEXTURE_SHARE * pad
    skin = ring & textured & (_colour_distance(colour, centre) < SKIN_DISTANCE)
    return ring, skin


def filling_cut(colour: np.ndarray, colour8: np.ndarray, ring: np.ndarray, skin: np.ndarray) -> np.ndarray | None:
    """The finger's mask at the working size where it fills the frame (at least :data:`FILL_SHARE` of the border ring
    found skin by :func:`ring_skin`), else None: one GrabCut told that the image centre is finger, the ring's skin
    (its runs closed over :data:`CLOSE_SHARE` of the long side: the shaded skin between them) probable finger, the
    rest of the ring background (probable only where it lies within :data:`NEAR_SKIN_DISTANCE` of the pad's colour:
    a flank darker than the pad); the pieces that hold the centre, holes filled. None too where under
    :data:`MIN_DARK_RING` of the ring is left to background, before the cut or after it (a frame inside the finger, a
    texture of one colour). ``colour``: ``[h, w, 3]`` float32 in [0, 1] at the working size, ``colour8`` the same in 8
    bits, ``ring`` and ``skin`` its :func:`ring_skin`.

    The other segmentation's cuts take the ring for background and weigh ridges against the image's median texture,
    the skin's here: on the real dev views cut to 0.6 of their width and composited onto a bright desk, out-of-focus
    and in-focus clutter, their mask IoU was 0.44 / 0.47 / 0.65 (median), this cut's 0.99 / 0.99 / 0.99."""
    from .grabcut import _colour_distance, _grab_cut
    from .morphology import disc
    from .regions import fill_holes

    if np.count_nonzero(skin) < FILL_SHARE * np.count_nonzero(ring):
        return None
    closing = disc(max(3, int(CLOSE_SHARE * max(ring.shape))))
    crossing = ring & cv2.morphologyEx(skin.view(np.uint8), cv2.MORPH_CLOSE, closing).view(bool)
    centre = _centre(ring.shape)
    labels = np.full(ring.shape, cv2.GC_PR_FGD, np.uint8)
    outside = ring & ~crossing
    if np.count_nonzero(outside) < MIN_DARK_RING * np.count_nonzero(ring):
        return None  # no background on the ring: a frame inside the finger, or a texture of one colour
    near = _colour_distance(colour, centre) < NEAR_SKIN_DISTANCE
    labels[outside] = np.where(near[outside], cv2.GC_PR_BGD, cv2.GC_BGD)
    labels[centre] = cv2.GC_FGD
    finger = _grab_cut(colour8, labels)
    count, pieces = cv2.connectedComponents(finger.view(np.uint8), connectivity=8)
    held = np.unique(pieces[centre & finger])
    finger = fill_holes(np.isin(pieces, held[held > 0]))
    return finger if np.count_nonzero(outside & ~finger) >= MIN_DARK_RING * np.count_nonzero(ring) else None


def holds_ring_skin(mask: np.ndarray, ring: np.ndarray, skin: np.ndarray) -> bool:
    """Whether ``mask`` (``[h, w]`` bool at the working size) holds at least :data:`HELD_SKIN` of the ``skin``
    :func:`ring_skin` finds on the border ``ring``, or the ring shows under :data:`FILL_SHARE` of skin (nothing to
    hold). A cut that takes the ring for background leaves a finger filling the frame out along the ring; one carried
    out to the frame where the finger crosses it (a crop cut at both ends) keeps it."""
    found = np.count_nonzero(skin)
    return found < FILL_SHARE * np.count_nonzero(ring) or np.count_nonzero(skin & mask) >= HELD_SKIN * found
