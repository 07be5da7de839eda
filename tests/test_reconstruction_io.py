"""Reconstruction-folder writers: fused.ply, depth/<view>.*, report.json (docs/conventions.md file contracts)."""
import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from fingersplat3d.geometry import points_to_cloud
from fingersplat3d.io.depth import read_depth
from fingersplat3d.io.images import read_image
from fingersplat3d.io.reconstruction import (DepthFiles, depth_legend_picture, write_fused_cloud, write_report,
                                             write_view_depth)


def _cloud(count: int = 500, seed: int = 0):
    rng = np.random.default_rng(seed)
    points = rng.normal(0.0, 5.0, (count, 3))
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    colors = rng.random((count, 3))
    return points, colors, normals


def _leftovers(folder: Path) -> list[str]:
    return sorted(path.name for path in folder.rglob("*") if path.name.startswith("."))


def test_fused_cloud_round_trips_through_open3d_and_pymeshlab(tmp_path):
    import open3d as o3d
    import pymeshlab

    points, colors, normals = _cloud()
    path = write_fused_cloud(tmp_path / "fused.ply", points_to_cloud(points, colors, normals))
    assert path.read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")
    assert b"property float x" in path.read_bytes()[:400]  # float32, half the size of Open3D's own files

    cloud = o3d.io.read_point_cloud(str(path))
    assert cloud.has_colors() and cloud.has_normals()
    np.testing.assert_allclose(np.asarray(cloud.points), points, atol=1e-5)
    np.testing.assert_allclose(np.asarray(cloud.normals), normals, atol=1e-6)
    np.testing.assert_allclose(np.asarray(cloud.colors), colors, atol=0.5 / 255 + 1e-9)

    meshes = pymeshlab.MeshSet()
    meshes.load_new_mesh(str(path))
    mesh = meshes.current_mesh()
    assert mesh.vertex_number() == len(points) and mesh.face_number() == 0
    assert mesh.has_vertex_color()
    np.testing.assert_allclose(mesh.vertex_matrix(), points, atol=1e-5)
    np.testing.assert_allclose(mesh.vertex_normal_matrix(), normals, atol=1e-6)
    np.testing.assert_allclose(mesh.vertex_color_matrix()[:, :3], colors, atol=0.5 / 255 + 1e-6)


def test_fused_cloud_refuses_empty_and_nan_clouds_and_leaves_nothing(tmp_path):
    import open3d as o3d

    target = tmp_path / "fused.ply"
    with pytest.raises(ValueError, match="fused.ply: refusing to write an empty point cloud"):
        write_fused_cloud(target, o3d.geometry.PointCloud())
    points, colors, normals = _cloud()
    points[3] = np.nan
    with pytest.raises(ValueError, match="NaN or Inf in 1 of its 500 points"):
        write_fused_cloud(target, points_to_cloud(points, colors, normals))
    points[3] = 0.0
    normals[7] = np.inf
    with pytest.raises(ValueError, match="normals"):
        write_fused_cloud(target, points_to_cloud(points, colors, normals))
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(TypeError, match="PointCloud"):
        write_fused_cloud(target, points)


def _depth(shape=(60, 80)) -> np.ndarray:
    v, u = np.mgrid[0:shape[0], 0:shape[1]]
    depth = (290.0 + 0.1 * u + 0.05 * v).astype(np.float32)
    depth[:, :10] = np.nan
    return depth


def test_view_depth_files_follow_the_contract(tmp_path):
    depth = _depth()
    files = write_view_depth(tmp_path, "left", depth)
    assert isinstance(files, DepthFiles)
    assert files == DepthFiles(tmp_path / "depth/left.npy", tmp_path / "depth/left.png", tmp_path / "depth/left_color.png")
    assert sorted(p.name for p in (tmp_path / "depth").iterdir()) == ["left.npy", "left.png", "left_color.png"]

    raw = np.load(files.depth)
    assert raw.dtype == np.float32 and raw.shape == depth.shape
    np.testing.assert_array_equal(raw, depth)  # NaN positions included
    np.testing.assert_array_equal(read_depth(files.depth, depth.shape), depth)

    preview = cv2.imread(str(files.preview), cv2.IMREAD_UNCHANGED)
    assert preview.dtype == np.uint16 and preview.shape == depth.shape
    assert np.all(preview[:, :10] == 0) and preview[0, 10] == 65535 and preview[-1, -1] == 1  # near bright

    picture = read_image(files.picture, gray=False)
    height, width = picture.shape[:2]
    assert width > depth.shape[1] * height // depth.shape[0]  # the colour bar sits to the right
    image_width = depth.shape[1] * height // depth.shape[0]
    assert np.all(picture[:, : 10 * height // depth.shape[0]] == 0)  # NaN is black
    assert picture[:, :image_width][np.isfinite(np.repeat(np.repeat(depth, height // depth.shape[0], 0),
                                                          height // depth.shape[0], 1))].max() > 0.5


def test_colour_bar_matches_the_picture_and_names_the_units():
    depth = _depth((240, 320))
    mm, arbitrary = depth_legend_picture(depth, "mm"), depth_legend_picture(depth, "arbitrary")
    assert mm.dtype == np.uint8 and mm.shape[0] == 240 and mm.shape[1] > 320
    assert not np.array_equal(mm, arbitrary)  # the labels differ ("mm" vs "units")
    panel = mm[:, 320:]
    nearest = mm[0, 10]  # the nearest valid pixel's colour (hot end) ...
    assert np.any(np.all(panel[:20] == nearest, axis=-1))  # ... tops the bar
    farthest = mm[-1, 319]  # the farthest valid pixel (cold end) ends it
    assert np.any(np.all(panel[-20:] == farthest, axis=-1))
    tiny = depth_legend_picture(np.full((4, 5), np.nan))  # no depth at all: still a picture, enlarged
    assert tiny.shape[0] >= 192 and np.all(tiny[:, :5 * tiny.shape[0] // 4] == 0)
    large = depth_legend_picture(_depth((240, 320)), max_height=120)  # a camera-sized map: a picture to look at
    assert large.shape[0] == 120 and large.shape[1] > 160
    assert np.array_equal(large[:, :160].mean(axis=(0, 1)) > 0, mm[:, :320].mean(axis=(0, 1)) > 0)



def test_a_tall_depth_map_is_shrunk_before_it_is_coloured_with_its_whole_range():
    """A camera-sized map is averaged down first (colouring 20 megapixels cost 1.3 s a view), coloured over the full
    map's near..far: a lone nearest pixel averaged away moves no colour, and a hole stays black."""
    depth = np.full((240, 320), 2.0)
    depth[:, 160:] = 3.0
    depth[0, 0] = 1.0  # the nearest depth, one pixel
    depth[100:140, 100:140] = np.nan
    full, small = depth_legend_picture(depth), depth_legend_picture(depth, max_height=120)
    assert small.shape[0] == 120
    assert np.array_equal(small[60, 40], full[120, 80]) and np.array_equal(small[60, 120], full[120, 240])
    assert not np.array_equal(small[60, 40], small[60, 120]) and np.all(small[60, 60] == 0)

def test_view_depth_refuses_bad_depth_and_names_without_writing(tmp_path):
    bad = _depth()
    bad[5, 5] = -1.0
    with pytest.raises(ValueError, match="negative"):
        write_view_depth(tmp_path, "v0", bad)
    bad[5, 5] = np.inf
    with pytest.raises(ValueError, match="Inf"):
        write_view_depth(tmp_path, "v0", bad)
    with pytest.raises(ValueError, match="view name"):
        write_view_depth(tmp_path, "../v0", _depth())
    with pytest.raises(ValueError, match="units"):
        write_view_depth(tmp_path, "v0", _depth(), units="cm")
    assert not (tmp_path / "depth").exists() or list((tmp_path / "depth").iterdir()) == []


def test_view_depth_failing_midway_leaves_none_of_its_files(tmp_path, monkeypatch):
    import fingersplat3d.io.reconstruction as reconstruction

    def broken(path, image, bits=8):
        raise OSError("disk full")

    monkeypatch.setattr(reconstruction, "write_image", broken)
    with pytest.raises(OSError, match="disk full"):
        write_view_depth(tmp_path, "v0", _depth())
    assert list((tmp_path / "depth").iterdir()) == []


@dataclass(frozen=True)
class _Timing:
    seconds: float
    peak_mb: int


def test_report_is_strict_sorted_json_with_numpy_values(tmp_path):
    report = {
        "preset": "balanced",
        "times": {"fuse": np.float32(1.5), "align": np.float64(0.25)},
        "views": np.int64(3),
        "residuals": np.array([[0.1, 0.2], [0.3, np.nan]]),
        "converged": np.bool_(True),
        "output": tmp_path / "fused.ply",
        "pairs": [(0, 1), (0, 2)],
        "timing": _Timing(2.0, 512),
        "bad": float("inf"),
        7: "numeric key",
    }
    path = write_report(tmp_path / "report.json", report)
    text = path.read_text()
    data = json.loads(text)  # strict JSON: NaN/Inf became null
    assert "NaN" not in text and "Infinity" not in text
    assert list(data) == sorted(data)
    assert data["times"] == {"align": 0.25, "fuse": 1.5}
    assert data["views"] == 3 and data["converged"] is True
    assert data["residuals"] == [[0.1, 0.2], [0.3, None]] and data["bad"] is None
    assert data["output"] == str(tmp_path / "fused.ply") and data["pairs"] == [[0, 1], [0, 2]]
    assert data["timing"] == {"peak_mb": 512, "seconds": 2.0} and data["7"] == "numeric key"


def test_report_with_an_unsupported_value_writes_nothing_and_keeps_the_old_one(tmp_path):
    path = write_report(tmp_path / "report.json", {"ok": 1})
    with pytest.raises(TypeError, match=r"report\.stages\.fuse.*object"):
        write_report(path, {"stages": {"fuse": object()}})
    assert json.loads(path.read_text()) == {"ok": 1}
    assert _leftovers(tmp_path) == []
