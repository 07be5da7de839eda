"""A contactless finger photo made into what NIST's fingerprint tools expect of a contact print.

NFIQ2 and mindtct are built for 500 ppi plain impressions: 8-bit gray, ridges dark on a white
background, fingertip up, 197-799 px wide and 197-999 px tall after white borders are cropped.
:func:`contact_like` converts a photo (or a render) and its finger mask:

1. **Ridge area only**: the distal phalanx within ``RIDGE_AREA_WIDTHS`` finger widths of the tip
   (:func:`~fingersplat3d.align.correspond.texture.ridge_area`); the rest of the finger and the background
   become white.
2. **Ridges dark**: the band-passed ridge texture (:func:`~fingersplat3d.align.correspond.texture.ridge_texture`,
   unit local RMS, so shading and exposure drop out) mapped to ``128 -+ 48 * texture``. Under the
   plain light of contactless rigs ridge crests are the bright lines (``ridges="bright"``, the
   default, inverts them); ``"dark"`` keeps the photo's polarity.
3. **~500 ppi**: scaled so the measured ridge period becomes ``TARGET_PERIOD_PX`` (9 px, the
   ~0.46 mm inter-ridge distance of adult fingers at 500 ppi). Photos carry no scale, so the ridge
   period stands in for it.
4. **Upright and within NFIQ2's size limits**: rotated so the fingertip points up; a ridge area
   still too large is cut to 799 x 999 px around its axis, keeping the tip end.

The result keeps the affine map back to the photo's pixels, so minutiae found on the print can be
drawn on, or carried from, the photo. Pure numpy/OpenCV.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..align.correspond.texture import as_gray, measure_ridge_period, no_ridges, ridge_area, ridge_texture
from ..errors import InputError

__all__ = ["ContactImage", "contact_like", "print_at_period", "prints_about_period", "SCALE_STEPS", "TARGET_PERIOD_PX",
           "MAX_SIZE", "MIN_SIDE"]

TARGET_PERIOD_PX = 9.0
MAX_SIZE = (799, 999)  # NFIQ2's largest width and height after white borders are cropped
MIN_SIDE = 197  # NFIQ2's smallest width and height
MARGIN = 8  # white pixels around the print (mindtct ignores a border of blocks)
GRAY, SWING = 128.0, 48.0  # print level of the mean skin and of one local RMS of ridge texture


@dataclass(frozen=True, eq=False)
class ContactImage:
    """An 8-bit contact-like print and the affine map from the photo's pixels to it."""

    image: np.ndarray  # [h, w] uint8, ridges dark, background 255
    affine: np.ndarray  # [2, 3] photo pixel (x, y) -> print pixel
    period_px: float  # the photo's ridge period
    ppi_scale: float  # print pixels per photo pixel

    @classmethod
    def of_print(cls, image: np.ndarray, period_px: float = 0.0) -> "ContactImage":
        """An image that already is a print (a rolled print, a contact gallery's): the identity map, scale 1."""
        return cls(image, np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), float(period_px), 1.0)

    def to_print(self, xy: np.ndarray) -> np.ndarray:
        """Photo pixels ``[N, 2]`` -> print pixels."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        return xy @ self.affine[:, :2].T + self.affine[:, 2]

    def to_photo(self, xy: np.ndarray) -> np.ndarray:
        """Print pixels ``[N, 2]`` -> photo pixels."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        return (xy - self.affine[:, 2]) @ np.linalg.inv(self.affine[:, :2]).T

    def photo_pixels(self) -> np.ndarray:
        """``[h, w, 2]``: the photo pixel ``(x, y)`` each print pixel shows, NaN off the inked skin."""
        rows, cols = np.mgrid[0:self.image.shape[0], 0:self.image.shape[1]]
        pixels = self.to_photo(np.stack([cols.ravel(), rows.ravel()], 1)).reshape(rows.shape + (2,))
        return np.where((self.image < 255)[..., None], pixels, np.nan)

    @property
    def ridge_area_size(self) -> tuple[int, int]:
        """``(width, height)`` px of the inked part's bounding box; ``(0, 0)`` for a blank print."""
        rows, cols = np.nonzero(self.image < 255)
        if len(rows) == 0:
            return 0, 0
        return int(cols.max() - cols.min() + 1), int(rows.max() - rows.min() + 1)

    @property
    def fits_nfiq2(self) -> bool:
        """Whether the print's ridge area is within NFIQ2's size limits."""
        width, height = self.ridge_area_size
        return MIN_SIDE <= width <= MAX_SIZE[0] and MIN_SIDE <= height <= MAX_SIZE[1]


def contact_like(image: np.ndarray, mask: np.ndarray, *, ridges: str = "bright",
                 period_px: float | None = None) -> ContactImage:
    """The contact-like print of a finger photo (see the module docstring)."""
    if ridges not in ("bright", "dark"):
        raise InputError(f"ridges={ridges!r}: use 'bright' (crests are the bright lines) or 'dark'")
    gray = as_gray(image)
    mask = np.asarray(mask, bool)
    if mask.shape != gray.shape:
        raise InputError(f"the mask {mask.shape} does not match the image {gray.shape}")
    if mask.sum() < 64:
        raise InputError("the finger mask is empty: there is no finger to make a print of")
    area = ridge_area(mask) & mask
    period = float(period_px) if period_px is not None else _ridge_period(gray, mask, area)
    texture = ridge_texture(gray, area, period)
    sign = -1.0 if ridges == "bright" else 1.0
    ink = np.clip(GRAY + sign * SWING * texture, 0.0, 254.0)
    affine, size = _upright_affine(area, TARGET_PERIOD_PX / period)
    printed = cv2.warpAffine(ink.astype(np.float32), affine, size, flags=cv2.INTER_AREA if period > TARGET_PERIOD_PX
                             else cv2.INTER_LINEAR, borderValue=255.0)
    inside = cv2.warpAffine(area.astype(np.float32), affine, size, flags=cv2.INTER_LINEAR, borderValue=0.0) > 0.5
    printed = np.where(inside, np.rint(printed), 255).astype(np.uint8)
    return ContactImage(printed, affine, period, TARGET_PERIOD_PX / period)


SCALE_STEPS = (0.87, 0.93, 1.0, 1.07, 1.15)
"""The scales about the probes' ridge period a gallery print is compared at (:func:`prints_about_period`): steps of
7 %, so that no scale is more than 3.5 % off the best, over +-15 %, the bias measured between two kinds of print of
one finger (another group's renders unrolled against its rolled print: the rolled print matched best 11 % off the
period both read)."""


def _print_period(image: np.ndarray) -> float | None:
    """The ridge period of a print (8-bit gray, ridges dark on white), measured where it is inked (its dark pixels,
    closed over the valleys); None where no ridges are read."""
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(f"a print is an 8-bit gray image, got {image.dtype} of shape {image.shape}")
    inked = cv2.morphologyEx((image < 230).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((25, 25), np.uint8)) > 0
    return measure_ridge_period(image.astype(np.float32) / 255.0, inked if inked.any() else None)


def _scaled_print(image: np.ndarray, scale: float, period: float) -> ContactImage:
    """``image`` resized by ``scale``; the affine maps its pixels to the resized print's."""
    size = (max(1, round(image.shape[1] * scale)), max(1, round(image.shape[0] * scale)))
    scaled = cv2.resize(image, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    affine = np.array([[size[0] / image.shape[1], 0.0, 0.0], [0.0, size[1] / image.shape[0], 0.0]])
    return ContactImage(scaled, affine, float(period), float(scale))


def print_at_period(image: np.ndarray, target: float = TARGET_PERIOD_PX, tolerance: float = 0.02) -> ContactImage:
    """A print (8-bit gray, ridges dark on white: a contact print, a rolled print) scaled so that its ridge period is
    ``target`` pixels, as :func:`contact_like` scales a photo's: compared with each other, two prints of one finger
    then meet at one scale whatever the finger's own ridge spacing (adult fingers' 0.40-0.55 mm span 8-11 px at 500
    ppi, and bozorth3 tolerates little: a gallery 10 % off the probes' scale took the synthetic fingers' genuine
    median from 83 to 35-57). A print whose period is not read, or already within ``tolerance`` of the target, is
    kept as it is. The result's affine maps the given print's pixels to the scaled one's."""
    period = _print_period(image)
    if period is None or abs(target / period - 1.0) <= tolerance:
        return ContactImage.of_print(image, period or 0.0)
    return _scaled_print(image, target / period, period)


def prints_about_period(image: np.ndarray, steps: tuple[float, ...] = SCALE_STEPS,
                        target: float = TARGET_PERIOD_PX) -> list[ContactImage]:
    """A print at each of ``steps`` times the scale that brings its ridge period to ``target``
    (:func:`print_at_period`), for a comparison that takes its best over them: two kinds of print of one finger need
    not read the same period (a photo unrolled through a guessed section, a rolled print pressed flat). The print as it
    is, alone, where its period is not read."""
    period = _print_period(image)
    if period is None:
        return [ContactImage.of_print(image)]
    return [_scaled_print(image, step * target / period, period) for step in steps]


def _ridge_period(gray: np.ndarray, mask: np.ndarray, area: np.ndarray) -> float:
    """The ridge period of the finger's ridge area; an InputError where it shows no ridges (blank, out of focus,
    blurred beyond the ridges, or too small to measure: :func:`~fingersplat3d.align.correspond.texture.no_ridges`)."""
    from ..segment.silhouette import widest_disc

    period = measure_ridge_period(gray, area)
    why = no_ridges(period, widest_disc(mask))
    if why is not None:
        raise InputError(why + ": no print")
    return period


def _upright_affine(area: np.ndarray, scale: float) -> tuple[np.ndarray, tuple[int, int]]:
    """The photo -> print map: scale, tip up, ridge area cropped to the limits; and the print size."""
    from ..segment.silhouette import silhouette_frame

    frame = silhouette_frame(area)
    angle = np.arctan2(frame.axis[1], frame.axis[0])
    turn = -0.5 * np.pi - angle  # the axis (toward the tip) becomes (0, -1): up
    rotation = scale * np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    rows, cols = np.nonzero(area)
    points = np.stack([cols, rows], 1).astype(np.float64) @ rotation.T
    low, high = points.min(0), points.max(0)
    centre_x = float((np.asarray(frame.origin) @ rotation.T)[0])
    width_cap, height_cap = MAX_SIZE[0] - 2 * MARGIN, MAX_SIZE[1] - 2 * MARGIN
    if high[0] - low[0] > width_cap:  # too wide: keep the middle around the axis
        low[0] = centre_x - 0.5 * width_cap
        high[0] = low[0] + width_cap
    if high[1] - low[1] > height_cap:  # too tall: keep the tip end (the top)
        high[1] = low[1] + height_cap
    offset = MARGIN - low
    affine = np.hstack([rotation, offset[:, None]])
    size = (int(np.ceil(high[0] - low[0])) + 2 * MARGIN + 1, int(np.ceil(high[1] - low[1])) + 2 * MARGIN + 1)
    return affine, size
