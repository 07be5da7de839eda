"""The working window: a photo cut, about its own centre, to the part that holds the finger.

A phone photo of a finger holds mostly desk: the finger spans a ninth to a fifth of a 12-megapixel frame's width, and
its ridges, 13 px apart, need the photo's own resolution (:mod:`fingersplat3d.working_scale`), so every stage of the
geometry and the splat fit had worked on 12 megapixels to use one or two. The window keeps the finger and a margin round
it and drops the rest before the geometry; the outputs (cameras, depth maps, masks) are put back on the photo's own
pixel grid.

Why about the photo's centre: the geometry takes each camera's principal point at its image's centre (no camera
parameters are given), which a crop off the centre moves: photos each cut to their finger's box came out 1.3-4.5
degrees wide (docs/measurements.md, stop 87). A window symmetric about the photo's centre keeps the principal point
where it was, so the cameras are the ones the whole photo would give; it is only as small as the finger's furthest
reach from the centre allows. It extends to the photo's border on a side where the finger reaches that border, so the
window never cuts the finger where the photo does not.

The splat fit takes the cameras as the geometry found them, so it needs no principal point at its window's centre: it
works in each finger's own box and margin (:func:`box_window`): 55 % of the pixels of a window about the centre for a
long finger in a phone's photo, the fit in half the time (docs/measurements.md, stop 90).

Only photos larger than :data:`~fingersplat3d.working_scale.SURVEY_SIDE` whose window would keep at most
:data:`WINDOW_MAX_SHARE` of them are windowed: the geometry of a smaller photo costs seconds, and every capture the
project is measured on at the rig's framing is left exactly as it was.

Pure numpy; no Open3D, no files.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scene import Camera

__all__ = ["Window", "WINDOW_MARGIN", "WINDOW_MIN_MARGIN_PX", "WINDOW_MAX_SHARE", "box_window", "finger_window"]

WINDOW_MARGIN = 0.25
"""Margin round the finger's box, as a share of the box's short side (about the finger's width): room for a mask
found short of the finger on the survey copy, and background round the outline for the masks, the silhouette contours
and the splat fit's mask cleaning."""
WINDOW_MIN_MARGIN_PX = 32
"""Margin at least this many photo pixels."""
WINDOW_MAX_SHARE = 0.6
"""A window keeping more of the photo's pixels than this share is not used (the photo is worked on whole)."""


@dataclass(frozen=True)
class Window:
    """A part of a photo: columns ``left`` to ``left + width``, rows ``top`` to ``top + height`` (the geometry's
    symmetric about the photo's centre, :func:`finger_window`; the splat fit's round the finger, :func:`box_window`)."""

    left: int
    top: int
    width: int
    height: int
    photo_width: int
    photo_height: int

    @property
    def size(self) -> tuple[int, int]:
        return self.width, self.height

    @property
    def slices(self) -> tuple[slice, slice]:
        """Rows and columns of the photo inside the window."""
        return slice(self.top, self.top + self.height), slice(self.left, self.left + self.width)

    def cut(self, image: np.ndarray) -> np.ndarray:
        """The window's part of a photo-sized array."""
        return image[self.slices]

    def padded(self, values: np.ndarray, fill=np.nan) -> np.ndarray:
        """A window-sized array put back in a photo-sized one, ``fill`` outside the window."""
        out = np.full((self.photo_height, self.photo_width) + values.shape[2:], fill, dtype=values.dtype)
        out[self.slices] = values
        return out

    def camera_on_photo(self, camera: Camera) -> Camera:
        """A camera of the window's pixels (at the window's size) as the photo's: the same pose, its principal point
        moved by the window's corner (back to the photo's centre when the camera's was the window's)."""
        if camera.size != self.size:
            raise ValueError(f"camera is {camera.width}x{camera.height}, window {self.width}x{self.height}")
        K = camera.K.copy()
        K[0, 2] += self.left
        K[1, 2] += self.top
        return Camera(K, camera.world_to_cam, self.photo_width, self.photo_height)

    def camera_in_window(self, camera: Camera) -> Camera:
        """A camera of the whole photo as the window's (at the window's size): :meth:`camera_on_photo` undone."""
        if camera.size != (self.photo_width, self.photo_height):
            raise ValueError(f"camera is {camera.width}x{camera.height}, photo {self.photo_width}x{self.photo_height}")
        K = camera.K.copy()
        K[0, 2] -= self.left
        K[1, 2] -= self.top
        return Camera(K, camera.world_to_cam, self.width, self.height)

    def as_report(self) -> list[int]:
        return [self.left, self.top, self.width, self.height]


def finger_window(mask: np.ndarray, photo_size: tuple[int, int]) -> Window | None:
    """The window of a photo of ``photo_size`` = (W, H) round the finger ``mask`` (any resolution of the photo: its
    box is scaled to the photo), or None when the window would keep more than :data:`WINDOW_MAX_SHARE` of it or the
    mask is empty."""
    width, height = int(photo_size[0]), int(photo_size[1])
    reach = _reach(mask, photo_size)
    if reach is None:
        return None
    (low_x, high_x), (low_y, high_y) = reach
    left, top = _side(low_x, high_x, width), _side(low_y, high_y, height)
    return _kept(Window(left, top, width - 2 * left, height - 2 * top, width, height))


def box_window(mask: np.ndarray, photo_size: tuple[int, int]) -> Window | None:
    """The window of a photo of ``photo_size`` round the finger ``mask``'s own box and the margin of
    :func:`finger_window`, wherever in the photo it lies (for stages that take the cameras as given), cut at the
    photo's borders; None as :func:`finger_window`."""
    width, height = int(photo_size[0]), int(photo_size[1])
    reach = _reach(mask, photo_size)
    if reach is None:
        return None
    (low_x, high_x), (low_y, high_y) = reach
    left, top = max(0, int(np.floor(low_x))), max(0, int(np.floor(low_y)))
    right, bottom = min(width, int(np.ceil(high_x))), min(height, int(np.ceil(high_y)))
    return _kept(Window(left, top, right - left, bottom - top, width, height))


def _reach(mask: np.ndarray, photo_size: tuple[int, int]) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """``((left, right), (top, bottom))``: the finger's box in photo pixels (the mask's pixel edges, any resolution
    of the photo) grown by its margin; None for an empty mask."""
    rows, cols = np.nonzero(np.asarray(mask, bool))
    if rows.size == 0:
        return None
    sx, sy = photo_size[0] / mask.shape[1], photo_size[1] / mask.shape[0]
    box_left, box_right = cols.min() * sx, (cols.max() + 1) * sx
    box_top, box_bottom = rows.min() * sy, (rows.max() + 1) * sy
    margin = max(WINDOW_MARGIN * min(box_right - box_left, box_bottom - box_top), WINDOW_MIN_MARGIN_PX)
    return (box_left - margin, box_right + margin), (box_top - margin, box_bottom + margin)


def _kept(window: Window) -> Window | None:
    """The window, or None where it keeps more than :data:`WINDOW_MAX_SHARE` of its photo."""
    if window.width * window.height > WINDOW_MAX_SHARE * window.photo_width * window.photo_height:
        return None
    return window


def _side(low: float, high: float, length: int) -> int:
    """The window's first index along one side of the photo: symmetric about its centre, reaching ``low`` and
    ``high`` (the finger's reach and margin), 0 where either lies at or past the photo's border."""
    centre = length / 2.0
    reach = max(centre - low, high - centre)
    return int(np.clip(np.floor(centre - reach), 0, length // 2 - 1))
