"""The standard 3D Gaussian Splatting PLY: write and read :class:`~fingersplat3d.splat.Gaussians`.

The layout is the original 3DGS one, so viewers (SuperSplat, the SIBR viewer, gsplat tools) and
MeshLab open the files: one ``vertex`` element, binary little endian, float32 properties

    x y z nx ny nz f_dc_0 f_dc_1 f_dc_2 opacity scale_0 scale_1 scale_2 rot_0 rot_1 rot_2 rot_3

with the raw parameters: normals zero, ``f_dc`` the SH DC coefficient, ``opacity`` a logit,
``scale_*`` natural-log standard deviations, ``rot_*`` a wxyz quaternion. A grayscale model writes
its one channel into all three ``f_dc``; the reader collapses them back when asked (``channels=1``).
The capture's shading exponent (:mod:`fingersplat3d.splat.shading`) is a header comment,
``comment fs3d facing_exponent 0.42``: other tools skip it and render ``f_dc``, the skin seen face on;
a file without it reads with exponent 0.

The reader accepts what other 3DGS tools write: higher-degree SH (``f_rest_*``) and any extra
properties are ignored, properties may be float or double, the file may be big or little endian. Reading and writing go
through the project's one PLY path, :mod:`fingersplat3d.io.ply` (``plyfile``).
Anything it cannot use is an :class:`~fingersplat3d.errors.InputError` naming the file.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import input_error
from .ply import read_vertex_ply, write_vertex_ply

if TYPE_CHECKING:  # torch is imported on use, so ``import fingersplat3d.io`` stays light
    from ..splat.gaussians import Gaussians

__all__ = ["GAUSSIAN_PLY_FIELDS", "write_gaussians_ply", "read_gaussians_ply", "EXPONENT_COMMENT"]

GAUSSIAN_PLY_FIELDS = ("x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                       "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")
_REQUIRED = tuple(name for name in GAUSSIAN_PLY_FIELDS if name not in ("nx", "ny", "nz"))
EXPONENT_COMMENT = "fs3d facing_exponent"
"""The header comment that carries the model's shading exponent, followed by the number."""


def write_gaussians_ply(path: str | Path, gaussians: "Gaussians") -> Path:
    """Write ``gaussians`` as a standard binary 3DGS PLY at ``path`` (atomically); returns the path."""
    import torch

    means, quats, log_scales, opacity_logits, sh_dc = (
        t.detach().to("cpu", torch.float32).numpy() for t in gaussians.tensors())
    if sh_dc.shape[1] == 1:
        sh_dc = np.repeat(sh_dc, 3, axis=1)  # grayscale: the one channel in all three f_dc
    for name, values in (("means", means), ("quats", quats), ("log_scales", log_scales),
                         ("opacity_logits", opacity_logits), ("sh_dc", sh_dc)):
        if not np.all(np.isfinite(values)):
            raise ValueError(f"cannot write {path}: Gaussians.{name} contains NaN or Inf")
    block = np.zeros(len(means), dtype=[(name, "<f4") for name in GAUSSIAN_PLY_FIELDS])
    columns = {"x": means[:, 0], "y": means[:, 1], "z": means[:, 2], "opacity": opacity_logits}
    columns.update({f"f_dc_{i}": sh_dc[:, i] for i in range(3)})
    columns.update({f"scale_{i}": log_scales[:, i] for i in range(3)})
    columns.update({f"rot_{i}": quats[:, i] for i in range(4)})
    for name, values in columns.items():
        block[name] = values
    return write_vertex_ply(path, block, ["3D Gaussian splats written by fingersplat3d",
                                          f"{EXPONENT_COMMENT} {float(gaussians.facing_exponent)!r}"])


def read_gaussians_ply(path: str | Path, channels: int | None = None) -> "Gaussians":
    """Read a 3DGS PLY into float32 CPU :class:`Gaussians`.

    ``channels``: None keeps the three ``f_dc`` channels; 1 gives a grayscale model (the three
    channels are equal in a file written from one; otherwise their mean, the gray level); 3 is
    the same as None.
    """
    if channels not in (None, 1, 3):
        raise ValueError(f"channels must be None, 1 or 3, got {channels}")
    path = Path(path)
    vertices, comments = read_vertex_ply(path, "3D Gaussian PLY")
    exponent = _facing_exponent(path, comments)
    dtype = vertices.dtype
    missing = [name for name in _REQUIRED if name not in dtype.names]
    if missing:
        raise input_error(path, f"not a 3D Gaussian PLY: missing vertex properties {', '.join(missing)}")

    def columns(*names: str) -> np.ndarray:
        return np.stack([vertices[name].astype(np.float32) for name in names], axis=1)  # [N, len(names)]

    means = columns("x", "y", "z")
    sh_dc = columns("f_dc_0", "f_dc_1", "f_dc_2")
    opacity_logits = columns("opacity")[:, 0]
    log_scales = columns("scale_0", "scale_1", "scale_2")
    quats = columns("rot_0", "rot_1", "rot_2", "rot_3")
    for name, values in (("positions", means), ("f_dc", sh_dc), ("opacity", opacity_logits),
                         ("scales", log_scales), ("rotations", quats)):
        if not np.all(np.isfinite(values)):
            raise input_error(path, f"the Gaussian {name} contain NaN or Inf")
    if channels == 1:
        equal = np.array_equal(sh_dc[:, 0], sh_dc[:, 1]) and np.array_equal(sh_dc[:, 0], sh_dc[:, 2])
        sh_dc = sh_dc[:, :1].copy() if equal else sh_dc.mean(axis=1, keepdims=True, dtype=np.float64).astype(np.float32)
    import torch

    from ..splat.gaussians import Gaussians

    return Gaussians(torch.from_numpy(means), torch.from_numpy(quats), torch.from_numpy(log_scales),
                     torch.from_numpy(np.ascontiguousarray(opacity_logits)), torch.from_numpy(sh_dc), exponent)


def _facing_exponent(path: Path, comments: list[str]) -> float:
    """The shading exponent of the header's ``EXPONENT_COMMENT`` line; 0 without one."""
    from ..splat.shading import MAX_EXPONENT

    for line in comments:
        if line.startswith(EXPONENT_COMMENT + " "):
            text = line[len(EXPONENT_COMMENT):].strip()
            try:
                value = float(text)
            except ValueError:
                value = float("nan")
            if not 0.0 <= value <= MAX_EXPONENT:
                raise input_error(path, f"the header's '{EXPONENT_COMMENT}' is not a number in [0, {MAX_EXPONENT:g}]: {text!r}")
            return value
    return 0.0
