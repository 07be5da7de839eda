"""The pointmap backend protocol: per-pixel 3D points with confidence, for views and pairs of views.

A *pointmap* of view v in frame f is ``X^{v,f}``: for every pixel of v, the 3D point it sees,
expressed in the camera frame of view f (x right, y down, z forward), in the backend's own
arbitrary units. ``X^{v,v}`` (own frame) is what every backend gives; learned pairwise
backends (DUSt3R) also give ``X^{j,i}``: view j's points in view i's frame.

Backends are chosen by name (``--backend``) through :func:`get_backend`; each one is a class with
``predict_views`` (own-frame pointmaps) and, optionally, ``predict_pairs``. Pairwise relations of
backends without ``predict_pairs`` come from image correspondences in :mod:`fingersplat3d.align`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol, Sequence, runtime_checkable

import numpy as np

from ..errors import InputError
from ..scene import View

__all__ = ["Pointmap", "PairPointmaps", "PointmapBackend", "register_backend", "get_backend", "backend_names"]


@dataclass(frozen=True, eq=False)
class Pointmap:
    """View ``view``'s per-pixel points in its own camera frame, with confidence."""

    view: int
    """Index of the view in the capture."""
    points: np.ndarray  # [H, W, 3] float32, own camera frame, NaN where there is no point
    confidence: np.ndarray  # [H, W] float32 >= 0, 0 where there is no point
    focal: float
    """Focal length in pixels the points are consistent with (principal point at the image centre):
    ``u = focal * x / z + (W - 1) / 2``."""

    def __post_init__(self) -> None:
        if self.points.ndim != 3 or self.points.shape[2] != 3 or self.confidence.shape != self.points.shape[:2]:
            raise ValueError(f"pointmap of view {self.view}: points must be HxWx3 and confidence HxW, "
                             f"got {self.points.shape} and {self.confidence.shape}")

    @property
    def depth(self) -> np.ndarray:
        """``[H, W]`` camera-frame z (NaN where there is no point)."""
        return self.points[..., 2]

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.points).all(axis=-1) & (self.confidence > 0)


@dataclass(frozen=True, eq=False)
class PairPointmaps:
    """A pairwise prediction: views ``i`` and ``j`` both in the camera frame of ``i``."""

    i: int
    j: int
    points_i: np.ndarray  # [Hi, Wi, 3]  X^{i,i}
    points_j: np.ndarray  # [Hj, Wj, 3]  X^{j,i}
    confidence_i: np.ndarray  # [Hi, Wi]
    confidence_j: np.ndarray  # [Hj, Wj]


@runtime_checkable
class PointmapBackend(Protocol):
    """What ``--backend NAME`` resolves to."""

    name: str

    def predict_views(self, views: Sequence[View]) -> list[Pointmap]:
        """Own-frame pointmaps ``X^{v,v}``, one per view, on each view's own pixel grid."""
        ...


_BACKENDS: dict[str, Callable[..., PointmapBackend]] = {}


def register_backend(name: str, factory: Callable[..., PointmapBackend]) -> None:
    """Make ``get_backend(name, **options)`` call ``factory(**options)``."""
    _BACKENDS[name] = factory


def backend_names() -> list[str]:
    return sorted(_BACKENDS)


def get_backend(name: str, **options) -> PointmapBackend:
    """Instantiate a backend by name; unknown names are a clear error listing the known ones.

    The package's ``__init__`` registers the built-in backends (``prior``, ``dust3r``), so this
    module imports none of them.
    """
    if name not in _BACKENDS:
        raise InputError(f"unknown pointmap backend {name!r}; available: {', '.join(backend_names())}")
    return _BACKENDS[name](**options)
