"""Which way round a gallery of prints is, read from the comparison scores alone (no genuine/impostor labels).

A photo of the pad and an inked, scanned or live-scan contact print of it are mirror images (a stamp and its
impression); a rolled print made from a model or a texture (``fs3d synth``'s, another group's renders') keeps the
photo's handedness. bozorth3 is not mirror-invariant: compared the wrong way round, a finger's own print scores as
a stranger's. A gallery's handedness is one fact about the whole gallery, so it is read once per kind of probe: each
probe is compared with every gallery print as it is and mirrored, and the way whose probes find the stronger best
matches is kept. The right way round, a probe's best match is its own finger's print wherever the matcher can tell
fingers apart at all; the wrong way round, every score is an impostor's. Where neither way stands out (the matcher
tells nothing apart), the probes are kept as they are.

Pure numpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Handedness", "gallery_handedness", "median_best"]


@dataclass(frozen=True)
class Handedness:
    """The way round chosen, and the statistic each way: the median over the probes of their best score against the
    gallery (NaN where no probe was compared that way)."""

    mirrored: bool
    best_as_is: float
    best_mirrored: float


def median_best(scores: np.ndarray) -> float:
    """Median over the probes (rows) of each probe's best score over the gallery (columns; NaN: not compared)."""
    scores = np.asarray(scores, np.float64)
    if scores.ndim != 2:
        raise ValueError(f"scores must be [probes, gallery], got shape {scores.shape}")
    compared = np.isfinite(scores).any(axis=1)
    if not compared.any():
        return float("nan")
    return float(np.median(np.nanmax(scores[compared], axis=1)))


def gallery_handedness(as_is: np.ndarray, mirrored: np.ndarray) -> Handedness:
    """The gallery's way round from the ``[probes, gallery]`` scores of the probes as they are and mirrored (NaN where
    a pair was not compared): mirrored only where the mirrored probes' median best score is higher."""
    best_as_is, best_mirrored = median_best(as_is), median_best(mirrored)
    flip = bool(np.isfinite(best_mirrored) and (not np.isfinite(best_as_is) or best_mirrored > best_as_is))
    return Handedness(flip, best_as_is, best_mirrored)
