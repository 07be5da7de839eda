"""Gaussian splatting: the model, the rasterizer (reference + fast), losses, fitting, camera paths.

Importing this package (and the rasterizer) does not load Open3D; the Open3D adapter that turns a
fused point cloud into initial Gaussians lives in :mod:`fingersplat3d.splat.init` and is imported
on demand.
"""
from .camera_path import RigGeometry, arc_cameras, cameras_at_angles, rig_geometry
from .gaussians import SH_C0, Gaussians, covariance_3d, rgb_to_sh, sh_to_rgb
from .losses import masked_l1, photometric_loss, ssim, ssim_map
from .project import Projection, project_gaussians
from ..rotations import matrix_to_quaternion, normalize_quaternions, quaternion_to_matrix
from .rasterize import RenderOutput, rasterize
from .reference import reference_rasterize

__all__ = ["Gaussians", "SH_C0", "rgb_to_sh", "sh_to_rgb", "covariance_3d", "matrix_to_quaternion",
           "normalize_quaternions", "quaternion_to_matrix",
           "masked_l1", "photometric_loss", "ssim", "ssim_map",
           "RigGeometry", "arc_cameras", "cameras_at_angles", "rig_geometry",
           "Projection", "project_gaussians", "RenderOutput", "rasterize", "reference_rasterize"]
