"""Initial Gaussians from an Open3D point cloud: KNN scales, normal-aligned discs, colours, errors."""
from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
import torch

from fingersplat3d.errors import InputError
from fingersplat3d.splat.init import gaussians_from_cloud, knn_mean_distance
from fingersplat3d.rotations import quaternion_to_matrix
from fingersplat3d.splat.gaussians import covariance_3d


def grid_cloud(spacing: float = 0.5, size: int = 12, normals: bool = True, colours: bool = True,
               rotation: np.ndarray | None = None) -> o3d.geometry.PointCloud:
    """A square grid in a plane (z = 0, then rotated) with colours varying along x."""
    u, v = np.meshgrid(np.arange(size) * spacing, np.arange(size) * spacing)
    points = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], 1)
    normal = np.array([0.0, 0.0, 1.0])
    if rotation is not None:
        points, normal = points @ rotation.T, rotation @ normal
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if normals:
        cloud.normals = o3d.utility.Vector3dVector(np.tile(normal, (len(points), 1)))
    if colours:
        ramp = points[:, 0] - points[:, 0].min()
        ramp = ramp / max(ramp.max(), 1e-9)
        cloud.colors = o3d.utility.Vector3dVector(np.stack([ramp, 0.5 * np.ones_like(ramp), 1 - ramp], 1))
    return cloud


def interior(size: int = 12) -> np.ndarray:
    index = np.arange(size * size).reshape(size, size)
    return index[1:-1, 1:-1].ravel()


def test_knn_scale_on_a_grid():
    """On a square grid every interior point has 4 neighbours at the spacing: 3-NN mean = spacing."""
    cloud = grid_cloud(spacing=0.5)
    distance = knn_mean_distance(np.asarray(cloud.points))
    assert np.allclose(distance[interior()], 0.5)
    gaussians = gaussians_from_cloud(cloud, 3, scale_factor=2.0)
    assert torch.allclose(gaussians.scales[interior()], torch.tensor(1.0), atol=1e-6)
    assert torch.equal(gaussians.means, torch.from_numpy(np.asarray(cloud.points)).float())
    assert torch.allclose(gaussians.quats, torch.tensor([1.0, 0, 0, 0]).expand(len(gaussians), 4))
    assert torch.allclose(gaussians.opacities, torch.tensor(0.1))
    assert gaussians.means.dtype == torch.float32


def test_knn_matches_brute_force():
    points = np.random.default_rng(0).normal(size=(300, 3))
    distances = np.linalg.norm(points[:, None] - points[None], axis=-1)
    expected = np.sort(distances, axis=1)[:, 1:4].mean(1)
    assert np.allclose(knn_mean_distance(points), expected, atol=1e-9)


def test_colours_rgb_and_gray():
    cloud = grid_cloud()
    colours = np.asarray(cloud.colors)
    rgb = gaussians_from_cloud(cloud, 3)
    gray = gaussians_from_cloud(cloud, 1)
    assert rgb.channels == 3 and gray.channels == 1
    assert torch.allclose(rgb.colors, torch.from_numpy(colours).float(), atol=1e-6)
    assert torch.allclose(gray.colors[:, 0], torch.from_numpy(colours.mean(1)).float(), atol=1e-6)
    plain = gaussians_from_cloud(grid_cloud(colours=False), 1)
    assert torch.allclose(plain.colors, torch.tensor(0.5))


@pytest.mark.parametrize("with_normals", [True, False])
def test_flatten_aligns_discs_with_the_surface(with_normals):
    from fingersplat3d.synth.rigs import rotation_about

    rotation = rotation_about([1.0, 2.0, 0.5], 40.0)
    normal = rotation @ np.array([0.0, 0.0, 1.0])
    cloud = grid_cloud(spacing=0.3, normals=with_normals, rotation=rotation)
    gaussians = gaussians_from_cloud(cloud, 3, flatten=0.1)
    frames = quaternion_to_matrix(gaussians.quats).double().numpy()
    assert np.allclose(np.linalg.det(frames), 1.0, atol=1e-5)
    alignment = np.abs(frames[:, :, 2] @ normal)  # third axis is the normal (up to sign when estimated)
    assert np.all(alignment > 1 - 1e-5)
    scales = gaussians.scales[interior()].double()
    assert torch.allclose(scales[:, 0], torch.tensor(0.3, dtype=torch.float64), atol=1e-6)
    assert torch.allclose(scales[:, 2], torch.tensor(0.03, dtype=torch.float64), atol=1e-6)
    # the thin direction of the covariance is the surface normal
    covariance = covariance_3d(gaussians.quats.double(), gaussians.scales.double()).numpy()
    _, vectors = np.linalg.eigh(covariance)
    assert np.all(np.abs(vectors[:, :, 0] @ normal) > 1 - 1e-5)


def test_duplicates_and_tiny_clouds_stay_finite():
    points = np.array([[0.0, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    gaussians = gaussians_from_cloud(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)), 1)
    assert all(torch.isfinite(t).all() for t in gaussians.tensors())
    two = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array([[0.0, 0, 0], [0, 0, 2]])))
    assert torch.allclose(gaussians_from_cloud(two, 3).scales, torch.tensor(2.0))
    same = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.zeros((3, 3))))
    assert all(torch.isfinite(t).all() for t in gaussians_from_cloud(same, 3).tensors())


def test_bad_input():
    with pytest.raises(InputError, match="point cloud"):
        gaussians_from_cloud(o3d.geometry.PointCloud(), 1)
    one = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.zeros((1, 3))))
    with pytest.raises(InputError):
        gaussians_from_cloud(one, 1)
    nan = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array([[0.0, 0, 0], [np.nan, 0, 0]])))
    with pytest.raises(InputError, match="NaN"):
        gaussians_from_cloud(nan, 1)
    cloud = grid_cloud()
    for kwargs in ({"channels": 2}, {"channels": 1, "opacity": 1.0}, {"channels": 1, "scale_factor": 0.0},
                   {"channels": 1, "flatten": 0.0}):
        with pytest.raises(ValueError):
            gaussians_from_cloud(cloud, **kwargs)


def test_init_is_importable_without_loading_open3d_elsewhere():
    """The splat package itself does not pull in Open3D; only splat.init does."""
    import subprocess
    import sys

    code = "import sys, fingersplat3d.splat, fingersplat3d.splat.losses, fingersplat3d.splat.camera_path; " \
           "print('open3d' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "False"
