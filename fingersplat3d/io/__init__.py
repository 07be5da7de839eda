"""Reading and writing: images, cameras.json, depth maps, capture folders, dataset layouts."""
from ..atomic import atomic_dir, atomic_path
from .cameras import CameraSet, read_cameras, write_cameras
from .capture import CaptureFiles, capture_files, is_capture_folder, read_capture, write_capture
from .datasets import UWAGroup, find_uwa_groups, load_any, load_cfpose, load_image_folder, load_uwa
from .depth import depth_colormap, read_depth, write_depth, write_depth_preview
from .gaussians_ply import GAUSSIAN_PLY_FIELDS, read_gaussians_ply, write_gaussians_ply
from .images import IMAGE_SUFFIXES, read_image, read_mask, write_image, write_mask
from .minutiae import read_minutiae, validate_minutiae, write_minutiae
from .reconstruction import DepthFiles, depth_legend_picture, write_fused_cloud, write_report, write_view_depth

__all__ = [
    "atomic_dir", "atomic_path",
    "IMAGE_SUFFIXES", "read_image", "write_image", "read_mask", "write_mask",
    "CameraSet", "read_cameras", "write_cameras",
    "GAUSSIAN_PLY_FIELDS", "read_gaussians_ply", "write_gaussians_ply",
    "read_depth", "write_depth", "write_depth_preview", "depth_colormap",
    "read_minutiae", "write_minutiae", "validate_minutiae",
    "CaptureFiles", "capture_files", "is_capture_folder", "read_capture", "write_capture",
    "UWAGroup", "find_uwa_groups", "load_uwa", "load_cfpose", "load_image_folder", "load_any",
    "DepthFiles", "depth_legend_picture", "write_fused_cloud", "write_report", "write_view_depth",
]
