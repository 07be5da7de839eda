"""Pointmap backends behind one protocol: ``prior`` (no weights) and ``dust3r`` (a checkpoint, loaded lazily)."""
from .base import PairPointmaps, Pointmap, PointmapBackend, backend_names, get_backend, register_backend

__all__ = ["Pointmap", "PairPointmaps", "PointmapBackend", "get_backend", "register_backend", "backend_names"]
