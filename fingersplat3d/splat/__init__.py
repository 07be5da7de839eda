"""Gaussian splatting: the model, the rasterizer (reference + fast), losses, fitting, camera paths.

Importing this package (and the rasterizer) does not load Open3D; the Open3D adapter that turns a
fused point cloud into initial Gaussians lives in :mod:`fingersplat3d.splat.init` and is imported
on demand.
"""
from .gaussians import SH_C0, Gaussians, rgb_to_sh, sh_to_rgb
from .quaternion import covariance_3d, matrix_to_quaternion, normalize_quaternions, quaternion_to_matrix

__all__ = ["Gaussians", "SH_C0", "rgb_to_sh", "sh_to_rgb", "covariance_3d", "matrix_to_quaternion",
           "normalize_quaternions", "quaternion_to_matrix"]
