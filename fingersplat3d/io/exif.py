"""The focal length a photo's EXIF records, in the photo's own pixels.

Phones and cameras write the lens's focal length into every JPEG: ``FocalLength`` (mm) with the sensor's
``FocalPlaneXResolution`` (pixels per unit at the full image), or ``FocalLengthIn35mmFilm`` (the focal a 36 x 24 mm
frame would need for the same view, by the diagonal). Either gives the focal in the full image's pixels; a photo
scaled down keeps its EXIF, so the focal is scaled with it (``PixelXDimension`` / ``PixelYDimension`` are the full
image's size). A photo cropped to another shape cannot be placed in the full image: no focal then. Two views cannot
fix the focal themselves (their turn follows it; docs/measurements.md), so a focal the camera wrote is worth having.

Read with Pillow (a dependency of the package; HEIC/HEIF through pillow-heif, whose images come upright with the
orientation tag reset, the stored size's quarter turn then found as an editor's is); an unreadable or odd EXIF is never
an error, only no focal.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ExifFocal", "exif_focal"]

_EXIF_IFD = 0x8769
_ORIENTATION = 0x0112
_FOCAL_LENGTH = 0x920A
_FOCAL_35MM = 0xA405
_PLANE_X_RESOLUTION = 0xA20E
_PLANE_UNIT = 0xA210
_PIXEL_X, _PIXEL_Y = 0xA002, 0xA003
_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}  # inch (the default), cm, and the mm / um some makers write
FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
PLAUSIBLE = (0.2, 50.0)
"""A focal outside these multiples of the photo's long side is not a camera's (a 4:3 photo's 10 mm-equivalent
fish-eye is ~0.3, its 1600 mm-equivalent telephoto ~46): such an EXIF is set aside."""
SHAPE_TOLERANCE = 0.01
"""A photo whose sides are not the full image's scaled by one factor (to this share) was cropped: no focal."""


@dataclass(frozen=True)
class ExifFocal:
    """The focal in the photo's pixels (None when its EXIF gives none) and, in words, where it came from or why not."""

    focal_px: float | None
    how: str


def _number(value) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if math.isfinite(number) and number > 0 else None


def exif_focal(path: str | Path, size: tuple[int, int]) -> ExifFocal:
    """The focal of the photo at ``path`` in the pixels of the image as read (``size`` = (width, height), upright)."""
    found = _exif_focal(path, size)
    if found.focal_px is not None and not PLAUSIBLE[0] <= found.focal_px / max(size) <= PLAUSIBLE[1]:
        return ExifFocal(None, f"{found.how} gives {found.focal_px:.0f} px, {found.focal_px / max(size):.2g} times the "
                               "long side: not a camera's focal")
    return found


def _exif_focal(path: str | Path, size: tuple[int, int]) -> ExifFocal:
    try:
        from PIL import Image

        from .images import HEIF_SUFFIXES

        if Path(path).suffix.lower() in HEIF_SUFFIXES:  # a phone's HEIC: Pillow reads its EXIF through pillow-heif
            from pillow_heif import register_heif_opener

            register_heif_opener()
        with Image.open(path) as image:
            exif = image.getexif()
            stored = image.size  # as stored, before the orientation tag turns it
            tags = dict(exif.get_ifd(_EXIF_IFD)) if exif else {}
            orientation = exif.get(_ORIENTATION, 1) if exif else 1
    except Exception as error:  # noqa: BLE001 - a photo Pillow cannot parse has no focal for us, not an error
        return ExifFocal(None, f"no EXIF read ({type(error).__name__})")
    if not tags:
        return ExifFocal(None, "no EXIF focal length")
    full = (_number(tags.get(_PIXEL_X)), _number(tags.get(_PIXEL_Y)))
    full = full if full[0] and full[1] else (float(stored[0]), float(stored[1]))
    if orientation in (5, 6, 7, 8):  # the tag turns the stored image by a quarter
        full = full[::-1]
    grow = (size[0] / full[0], size[1] / full[1])
    if abs(grow[0] / grow[1] - 1.0) > SHAPE_TOLERANCE:  # an editor may have turned the pixels and dropped the tag
        full = full[::-1]
        grow = (size[0] / full[0], size[1] / full[1])
    if abs(grow[0] / grow[1] - 1.0) > SHAPE_TOLERANCE:
        return ExifFocal(None, f"cropped from its {full[0]:.0f}x{full[1]:.0f} original: its focal cannot be placed")
    focal_35 = _number(tags.get(_FOCAL_35MM))
    if focal_35:  # the maker's own figure for this image (CIPA: by the diagonal), preferred
        focal = focal_35 / FULL_FRAME_DIAGONAL_MM * math.hypot(*full) * grow[0]
        return ExifFocal(focal, f"EXIF FocalLengthIn35mmFilm {focal_35:g} mm")
    focal_mm, resolution = _number(tags.get(_FOCAL_LENGTH)), _number(tags.get(_PLANE_X_RESOLUTION))
    unit = _UNIT_MM.get(int(_number(tags.get(_PLANE_UNIT)) or 2))
    if focal_mm and resolution and unit:  # square pixels: the sensor's pixels per mm, at the full image
        focal = focal_mm * resolution / unit * grow[0]
        return ExifFocal(focal, f"EXIF FocalLength {focal_mm:g} mm at {resolution:g} px per {unit:g} mm")
    return ExifFocal(None, "no EXIF focal length")
