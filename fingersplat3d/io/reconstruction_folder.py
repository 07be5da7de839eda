"""A reconstruction folder, read back: its cameras, depth maps, photos and report (docs/conventions.md).

What ``fs3d fuse -o OUT`` wrote, for the commands that work on it afterwards (``fs3d eval register``,
``fs3d print``). Photos are found where ``cameras.json`` says, or beside the folder.
"""
from __future__ import annotations

import json
from functools import cached_property
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["ReconstructionFolder", "is_reconstruction_folder"]


def is_reconstruction_folder(folder: str | Path) -> bool:
    """Whether ``folder`` holds a ``cameras.json`` (what every reconstruction folder has)."""
    return (Path(folder) / "cameras.json").is_file()


class ReconstructionFolder:
    """What the commands read of a reconstruction folder; ``photos``: view name -> photo file, to override."""

    def __init__(self, folder: str | Path, photos: dict[str, Path] | None = None):
        from .cameras import read_cameras

        folder = Path(folder)
        if not is_reconstruction_folder(folder):
            raise InputError(f"{folder}: not a reconstruction folder (no cameras.json; make one with 'fs3d fuse')")
        self.folder = folder
        self.cameras = read_cameras(folder / "cameras.json")
        self._photos = photos or {}

    @property
    def names(self) -> list[str]:
        return self.cameras.names

    @cached_property
    def report(self) -> dict:
        """``report.json`` (empty when missing or unreadable)."""
        try:
            report = json.loads((self.folder / "report.json").read_text())
        except (OSError, ValueError):
            return {}
        return report if isinstance(report, dict) else {}

    @property
    def fitted_to_ridges(self) -> bool:
        """Whether ``fs3d fuse --photometric`` fitted its surfaces to the ridge agreement of its photos."""
        return bool(self.report.get("registration", {}).get("photometric"))

    def has_depth(self, name: str) -> bool:
        return (self.folder / "depth" / f"{name}.npy").is_file()

    def depth(self, name: str) -> np.ndarray:
        from .depth import read_depth

        camera = self.cameras.cameras[name]
        return read_depth(self.folder / "depth" / f"{name}.npy", (camera.height, camera.width))

    def photo_path(self, name: str) -> Path | None:
        listed = Path(self.cameras.images[name])
        for candidate in (self._photos.get(name), listed, self.folder / listed, self.folder.parent / listed):
            if candidate is not None and Path(candidate).is_file():
                return Path(candidate)
        return None

    def photo(self, name: str) -> np.ndarray:
        from .images import read_image

        path = self.photo_path(name)
        if path is None:
            raise InputError(f"view {name!r}'s photo {self.cameras.images[name]!r} was not found")
        return read_image(path)

    def minutiae(self) -> dict | None:
        """``minutiae.json`` of the capture the photos came from (beside its ``images/``), if any."""
        from .minutiae import read_minutiae

        for name in self.cameras.names:
            path = self.photo_path(name)
            if path is not None and path.parent.name == "images" and (path.parent.parent / "minutiae.json").is_file():
                return read_minutiae(path.parent.parent / "minutiae.json")
        return None
