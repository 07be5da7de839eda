"""The true rolled print of a synthetic finger: its ridge pattern on the flattened skin, at 500 ppi.

The generator lays its ridge pattern on the finger in arc-length skin coordinates ``(a, b)`` mm
(:mod:`fingersplat3d.synth.shape`): ``a`` from the tip pole toward the base, ``b`` around the section
from the pad centre. Unrolled, that chart *is* the flattened skin a rolled impression records, so the
print is the pattern itself on a pixel grid: ``x = (b + half width) * px_per_mm``, ``y = a *
px_per_mm`` — tip up, and the same handedness as a photo of the pad taken from in front of it (a
frontal view's ``u`` grows with ``b``, its ``v`` with ``a``). Ridges dark on white, white outside the
skin; the skin is where the finger's surface reaches in ``(a, b)`` (the tip cap is narrower than the
pattern) and the pattern has ridges (tip to crease, its half width).

Its minutiae are those of ``minutiae.json`` (same ids), carried by the same map: the ground truth a
rolled-equivalent print made from photos is scored against. Pure numpy + OpenCV.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .render import skin_weight
from .ridges import RidgePattern
from .shape import FingerSurface

__all__ = ["RolledPrint", "PRINT_PPI", "ROLLED_PRINT_FILE", "true_rolled_print"]

PRINT_PPI = 500.0
"""Pixels per inch of the print (the fingerprint standard's 500 ppi: 19.7 px per mm)."""
ROLLED_PRINT_FILE = "rolled_print.png"
"""Its file in a capture folder (:mod:`fingersplat3d.io.capture`)."""
_SEAM_MM = 3.0  # a triangle this wide in (a, b) straddles the chart's seam at the nail, not skin


@dataclass(frozen=True, eq=False)
class RolledPrint:
    """A rolled print: the image, its skin mask, its resolution and its minutiae."""

    image: np.ndarray  # [H, W] uint8, ridges dark, 255 outside the skin
    mask: np.ndarray  # [H, W] bool, the skin
    ppi: float
    minutiae: list[dict]  # {"id", "kind", "xy": [x, y] px, "angle_deg"} (image convention, as minutiae.json's views)

    @property
    def px_per_mm(self) -> float:
        return self.ppi / 25.4

    def as_json(self, file: str) -> dict:
        """The ``rolled_print`` entry of ``minutiae.json``."""
        height, width = self.image.shape
        return {"file": file, "ppi": self.ppi, "size": [width, height],
                "mapping": "x = (b + half_width_mm) * px_per_mm, y = a * px_per_mm (skin_ab_mm of minutiae_3d)",
                "minutiae": self.minutiae}


def true_rolled_print(surface: FingerSurface, pattern: RidgePattern, minutiae_3d: list[dict],
                      ppi: float = PRINT_PPI) -> RolledPrint:
    """The print of ``pattern`` as laid on ``surface`` (module docstring); ``minutiae_3d`` as in ``minutiae.json``."""
    per_mm = ppi / 25.4
    half_width = float(pattern.half_width_mm)
    length = min(float(surface.params.crease), pattern.length_mm) + 1.0
    width_px, height_px = int(np.ceil(2 * half_width * per_mm)) + 1, int(np.ceil(length * per_mm)) + 1
    rows, cols = np.mgrid[0:height_px, 0:width_px].astype(np.float64)
    a, b = rows / per_mm, cols / per_mm - half_width
    weight = skin_weight(np.stack([a, b], -1), pattern, surface.params.crease)
    mask = (weight >= 0.5) & _surface_reach(surface, (height_px, width_px), per_mm, half_width)
    ridges = pattern.sample(a, b)
    image = np.where(mask, np.clip(127.5 - 127.5 * ridges * weight, 0, 255), 255.0)
    minutiae = []
    for entry in minutiae_3d:
        a_mm, b_mm = entry["skin_ab_mm"]
        angle = float(entry["skin_angle_rad"])  # along (cos, sin) in (a, b): (dx, dy) = (sin, cos) in the print
        minutiae.append({"id": entry["id"], "kind": entry["kind"], "xy": [(b_mm + half_width) * per_mm, a_mm * per_mm],
                         "angle_deg": float(np.degrees(np.arctan2(np.cos(angle), np.sin(angle))))})
    return RolledPrint(np.rint(image).astype(np.uint8), mask, float(ppi), minutiae)


def _surface_reach(surface: FingerSurface, shape: tuple[int, int], per_mm: float, half_width: float) -> np.ndarray:
    """Where in the print the finger's surface exists: its triangles drawn in skin coordinates."""
    corners = surface.pattern_ab[surface.triangles]  # [T, 3, 2] (a, b)
    finite = np.isfinite(corners).all((1, 2))
    extent = np.ptp(np.nan_to_num(corners), axis=1).max(1)
    corners = corners[finite & (extent < _SEAM_MM)]
    polygons = np.stack([(corners[..., 1] + half_width) * per_mm, corners[..., 0] * per_mm], -1)
    reach = np.zeros(shape, np.uint8)
    shift = 4  # sub-pixel vertex positions
    cv2.fillPoly(reach, list(np.rint(polygons * (1 << shift)).astype(np.int32)), 1, lineType=cv2.LINE_8, shift=shift)
    return reach > 0
