"""Pointmap backends behind one protocol: ``prior`` (no weights) and ``dust3r`` (a checkpoint, loaded lazily).

The registry lives in :mod:`.base`; the built-in backends are registered here, so that the arrows
run one way (each backend imports ``base``, ``base`` imports no backend).
"""
from . import prior  # noqa: F401  (registers "prior")
from .base import PairPointmaps, Pointmap, PointmapBackend, backend_names, get_backend, register_backend

__all__ = ["Pointmap", "PairPointmaps", "PointmapBackend", "get_backend", "register_backend", "backend_names"]


def _dust3r(**options) -> PointmapBackend:
    """Lazy factory of the ``dust3r`` backend: its network code (and torch) load on first use."""
    from .dust3r.backend import Dust3rBackend

    return Dust3rBackend(**options)


register_backend("dust3r", _dust3r)
