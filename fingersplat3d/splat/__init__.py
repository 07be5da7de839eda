"""Gaussian splatting: the model, the rasterizer (reference + fast), losses, fitting, camera paths.

Importing this package (and the rasterizer) does not load Open3D; the Open3D adapter that turns a
fused point cloud into initial Gaussians lives in :mod:`fingersplat3d.splat.init` and is imported
on demand.
"""
from __future__ import annotations

import importlib
import sys
import types

_HOMES = {
    "RigGeometry": ".camera_path", "arc_cameras": ".camera_path", "cameras_at_angles": ".camera_path",
    "rig_geometry": ".camera_path",
    "SH_C0": ".gaussians", "Gaussians": ".gaussians", "covariance_3d": ".gaussians", "rgb_to_sh": ".gaussians",
    "sh_to_rgb": ".gaussians",
    "masked_l1": ".losses", "photometric_loss": ".losses", "ssim": ".losses", "ssim_map": ".losses",
    "Projection": ".project", "project_gaussians": ".project",
    "matrix_to_quaternion": "..rotations", "normalize_quaternions": "..rotations", "quaternion_to_matrix": "..rotations",
    "RenderOutput": ".rasterize", "rasterize": ".rasterize",
    "reference_rasterize": ".reference",
}
__all__ = list(_HOMES)


def __getattr__(name: str):
    """The package's names, each loaded from its module when first asked for: a parser that reads
    :mod:`fingersplat3d.splat.config`'s presets does not wait for torch."""
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name], __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_HOMES))


class _Package(types.ModuleType):
    """The import system binds each submodule on its package once it is loaded; where a submodule has the name of the
    function the package gives (``rasterize``), the function keeps the name, as when the package imported it eagerly."""

    def __setattr__(self, name: str, value) -> None:
        if isinstance(value, types.ModuleType) and _HOMES.get(name, "").lstrip(".") == name:
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
