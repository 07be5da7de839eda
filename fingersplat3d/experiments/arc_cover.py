"""How solid a model's new views are: the share of the rendered finger its render leaves uncovered.

A new view's finger is where the render's alpha reaches 0.5, its enclosed holes filled and a few pixels taken off its
outline (where alpha falls to the background by design). Inside it, skin should be opaque: a pixel under 0.5 is a hole
(the background shows), one under 0.9 a thin patch. :func:`cover_gaps` scores one alpha map; :func:`arc_cover` renders
a reconstruction's arc (``fs3d render``'s views, the end cameras left out: they are the fitted photos) and scores it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

__all__ = ["cover_gaps", "arc_cover", "INSET_PX"]

INSET_PX = 3
"""Pixels taken off the rendered finger's outline before scoring (its antialiased edge)."""


def cover_gaps(alpha: np.ndarray, inset_px: int = INSET_PX) -> tuple[int, int, int]:
    """``(finger pixels, pixels under 0.5, pixels under 0.9)`` of an ``[H, W]`` alpha map (see the module docstring)."""
    alpha = np.nan_to_num(np.asarray(alpha, np.float64), nan=0.0)
    finger = ndimage.binary_fill_holes(alpha >= 0.5)
    if inset_px > 0:
        finger = ndimage.binary_erosion(finger, iterations=inset_px)
    return int(finger.sum()), int((finger & (alpha < 0.5)).sum()), int((finger & (alpha < 0.9)).sum())


def arc_cover(folder: Path, count: int = 12, width: int = 640) -> dict:
    """A reconstruction's ``count`` arc views at ``width`` pixels (the longest side), the fitted end cameras left out:
    ``{"holes": share under 0.5, "thin": share under 0.9, "views": scored views}`` over the views' fingers together."""
    from ..io.cameras import read_cameras
    from ..io.gaussians_ply import read_gaussians_ply
    from ..splat.novel import arc_views_at

    cameras = list(read_cameras(Path(folder) / "cameras.json").cameras.values())
    gaussians = read_gaussians_ply(Path(folder) / "gaussians.ply")
    views = arc_views_at(gaussians, cameras, count, width)[1:-1]
    totals = np.sum([cover_gaps(view.alpha) for view in views], axis=0)
    return {"holes": float(totals[1] / max(totals[0], 1)), "thin": float(totals[2] / max(totals[0], 1)), "views": len(views)}
