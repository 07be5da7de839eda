"""`fs3d register`: pixels and images carried from one view to another through the model."""
import csv

import numpy as np
import pytest

from fingersplat3d.align.transfer import transfer_points, warp_image
from fingersplat3d.cli import main
from fingersplat3d.errors import EXIT_INPUT
from fingersplat3d.io.capture import read_capture
from fingersplat3d.io.minutiae import read_minutiae


def test_ground_truth_depth_carries_minutiae_to_their_ground_truth_positions(tmp_path):
    # With the exact cameras and depth of a synthetic capture, minutiae seen in both views land on
    # their own ground-truth positions in the other view (to the depth maps' pixel grid).
    assert main(["synth", "--rig", "uwa", "--seed", "4", "--size", "320x256", str(tmp_path / "c")]) == 0
    capture = read_capture(tmp_path / "c")
    minutiae = read_minutiae(tmp_path / "c" / "minutiae.json")
    views = {v.name: v for v in capture.views}
    a, b = views["center"], views["right"]
    in_a = {m["id"]: m for m in minutiae["views"]["center"] if m["visible"]}
    in_b = {m["id"]: m for m in minutiae["views"]["right"] if m["visible"]}
    shared = sorted(set(in_a) & set(in_b))
    assert len(shared) >= 5
    uv_a = np.array([in_a[i]["uv"] for i in shared], float)
    uv_true = np.array([in_b[i]["uv"] for i in shared], float)
    uv_b, status = transfer_points(uv_a, a.depth, a.camera, b.depth, b.camera)
    carried = status == "mapped"
    assert carried.mean() > 0.8
    assert np.median(np.linalg.norm(uv_b[carried] - uv_true[carried], axis=1)) < 1.5
    # Off the finger: marked, not dropped.
    uv_b, status = transfer_points(np.array([[1.0, 1.0]]), a.depth, a.camera, b.depth, b.camera)
    assert status.tolist() == ["off_surface"] and np.isnan(uv_b).all()
    # The warp of A into B agrees with B's own photo where both see the finger.
    warped, valid = warp_image(a.image, a.depth, a.camera, b.depth, b.camera)
    assert valid.mean() > 0.2
    corr = np.corrcoef(warped[valid].ravel(), b.image[valid].ravel())[0, 1]
    assert corr > 0.5


def test_hidden_points_are_marked():
    from fingersplat3d.scene import Camera

    cam = Camera.from_focal(100.0, 40, 30)
    depth_a = np.full((30, 40), 10.0)
    depth_b = np.full((30, 40), 5.0)  # B sees a surface in front of everything A sees
    uv_b, status = transfer_points(np.array([[20.0, 15.0]]), depth_a, cam, depth_b, cam)
    assert status.tolist() == ["hidden"] and np.allclose(uv_b, [[20.0, 15.0]])


def test_register_command_on_a_fused_sample(tmp_path, capsys):
    rec = tmp_path / "rec"
    assert main(["fuse", "data_samples/uwa_seed0", "-o", str(rec), "--no-splat"]) == 0
    points = tmp_path / "points.csv"
    points.write_text("id,x,y\nm1,320,256\nm2,300,240\nfar,2,2\n")
    out = tmp_path / "reg"
    assert main(["register", str(rec), "center", "right", "--points", str(points),
                 "--image", "data_samples/uwa_seed0/images/center.png", "-o", str(out)]) == 0
    with open(out / "points.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["id"] for r in rows] == ["m1", "m2", "far"]
    assert rows[2]["status"] == "off_surface" and rows[2]["x_b"] == ""
    assert rows[0]["status"] in ("mapped", "hidden") and float(rows[0]["x_b"]) > 0
    assert (out / "warp.png").is_file()
    assert main(["register", str(rec), "center", "nope", "--points", str(points), "-o", str(tmp_path / "o2")]) == EXIT_INPUT
    assert "no view named 'nope'" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("u,v\n1,2\n")
    assert main(["register", str(rec), "center", "right", "--points", str(bad), "-o", str(tmp_path / "o3")]) == EXIT_INPUT
    assert "needs x and y columns" in capsys.readouterr().err


def _plane_view(offset_x: float, width=40, height=30, depth=10.0):
    """A camera looking down +z at the plane z = depth, shifted by ``offset_x`` (pixels of that plane)."""
    from fingersplat3d.scene import Camera

    pose = np.eye(4)
    pose[0, 3] = -offset_x * depth / 50.0  # world_to_cam translation: the camera sits at +offset
    return Camera.from_focal(50.0, width, height, pose), np.full((height, width), depth, np.float32)


def test_multi_view_support_is_the_share_another_view_sees():
    from fingersplat3d.align.transfer import multi_view_support

    (cam_a, depth_a), (cam_b, depth_b), (cam_c, depth_c) = _plane_view(0.0), _plane_view(20.0), _plane_view(500.0)
    shares = multi_view_support([depth_a, depth_b, depth_c], [cam_a, cam_b, cam_c], [True, True, True], stride=1)
    assert shares[0] == pytest.approx(0.5, abs=0.05)  # b, shifted by half the image, sees half of a's plane
    assert shares[2] == 0.0  # c sees other ground
    assert multi_view_support([depth_a, depth_b], [cam_a, cam_b], [True, False], stride=1) == [0.0, None]
    shares = multi_view_support([depth_a, depth_a.copy()], [cam_a, cam_a], [True, True], stride=2)
    assert shares == [0.0, 0.0]  # two photos of one skin from one place: seen twice, its depth from neither
    (cam_d, depth_d) = _plane_view(2.0)  # 2 px of the plane aside: rays 2.3 degrees apart at most
    assert multi_view_support([depth_a, depth_d], [cam_a, cam_d], [True, True], stride=1) == [0.0, 0.0]
    assert multi_view_support([depth_a, depth_d], [cam_a, cam_d], [True, True], stride=1, min_parallax_deg=1.0)[0] > 0.9
