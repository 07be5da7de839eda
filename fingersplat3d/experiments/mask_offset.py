"""A capture's finger masks grown or shrunk by a fixed number of photo pixels: how far the fit's focal and turns
follow the outline (``python3 tools/bench_real.py --mask-offset PX``).

Three cameras on a ring hold their focal weakly, and the silhouettes are among what holds it: a one-pixel change of
the outline moved a real capture's focal by up to 6 % (docs/measurements.md). If the masks missed a band of the same
width in pixels on every photo (blur at the rims, the dark limb of grazing skin), the nearer fingers, larger in the
frame, would lose a smaller share of their width than the farther ones, and the fitted focal would follow the finger's
distance, as it does on the real captures. Each view's mask is found as the fuse finds it
(:func:`~fingersplat3d.segment.masks.finger_mask`, on the photo) and grown (``px`` > 0) or shrunk (``px`` < 0) by
a disc of ``|px|`` pixels (:mod:`~fingersplat3d.segment.morphology`); the fuse then uses it as a given mask. Pure
numpy/OpenCV.
"""
from __future__ import annotations

from typing import Sequence

__all__ = ["with_offset_masks"]


def with_offset_masks(views: Sequence, px: int) -> list:
    """``views`` with their finger masks (their own where given, else found) grown by ``px`` pixels (shrunk where
    negative, as found at 0)."""
    from ..segment.masks import finger_mask
    from ..segment.morphology import dilated, eroded

    px = int(px)
    out = []
    for view in views:
        mask = view.mask if view.mask is not None else finger_mask(view.image, name=view.name)
        if px > 0:
            mask = dilated(mask, px)
        elif px < 0:
            mask = eroded(mask, -px)
        out.append(view.with_(mask=mask))
    return out
