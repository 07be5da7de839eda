"""``rig.json``: a calibrated camera rig, in the ``cameras.json`` schema without the finger.

One entry per camera (``name``, ``width``, ``height``, ``K``, ``world_to_cam``); the world is the
rig frame (camera 0's), units ``"arbitrary"`` (camera 0's median depth of the finger in the first
capture used = 1); ``image`` says which camera it is (``"camera f0"``). A top-level ``"rig"`` object
records how it was calibrated (captures used and left out, residuals). Every camera has square pixels
and its principal point at the image centre (the model of :mod:`fingersplat3d.align.solve.rig`; the
cameras' focal lengths may differ); a file that breaks this is an ``InputError`` naming it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..align.solve.rig import Rig
from ..errors import input_error
from ..scene import Camera
from .cameras import read_cameras, write_cameras
from .jsonio import read_json

__all__ = ["write_rig", "read_rig"]


def write_rig(path: str | Path, rig: Rig) -> Path:
    """Write ``rig`` to ``path`` atomically; returns the path."""
    entries = []
    for v, (name, (width, height)) in enumerate(zip(rig.names, rig.sizes)):
        entries.append((name, f"camera {name}", Camera.from_focal(rig.focals[v], width, height, np.linalg.inv(rig.cam_to_rig(v)))))
    return write_cameras(path, entries, units="arbitrary", extra={"rig": rig.info})


def read_rig(path: str | Path) -> Rig:
    """Read and check a ``rig.json`` (or any ``cameras.json`` of one capture of the rig)."""
    path = Path(path)
    cameras = read_cameras(path)
    entries = list(cameras.cameras.items())
    for name, camera in entries:
        if not np.isclose(camera.K[0, 0], camera.K[1, 1], rtol=1e-6):
            raise input_error(path, f"camera {name!r}: a rig camera has one focal length for both axes, not {camera.K[0, 0]:g} "
                                    f"and {camera.K[1, 1]:g}")
        centre = [(camera.width - 1) / 2.0, (camera.height - 1) / 2.0]
        if not np.allclose(camera.K[:2, 2], centre, atol=1e-6):
            raise input_error(path, f"camera {name!r}: the principal point must be the image centre {centre}")
    rig_to_world = np.linalg.inv(entries[0][1].world_to_cam) if entries else np.eye(4)
    poses = [np.linalg.inv(camera.world_to_cam) for _, camera in entries]  # cam -> world
    relative = [np.linalg.inv(rig_to_world) @ pose for pose in poses]  # cam -> rig (camera 0's frame)
    info = read_json(path).get("rig", {})
    return Rig(tuple(name for name, _ in entries), tuple((camera.width, camera.height) for _, camera in entries),
               np.stack([pose[:3, :3] for pose in relative]), np.stack([pose[:3, 3] for pose in relative]),
               [camera.K[0, 0] for _, camera in entries], info if isinstance(info, dict) else {})
