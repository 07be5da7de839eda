"""Camera projection conventions, Camera.scaled, look_at, and View/Capture validation."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingersplat3d.scene import Camera, Capture, View, look_at


def random_pose(rng: np.random.Generator) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.random(random_state=rng.integers(1 << 30)).as_matrix()
    pose[:3, 3] = rng.normal(scale=5.0, size=3)
    return pose


def off_centre_camera(pose: np.ndarray | None = None) -> Camera:
    K = np.array([[41.5, 0.0, 13.7], [0.0, 39.25, 9.2], [0.0, 0.0, 1.0]])
    return Camera(K, np.eye(4) if pose is None else pose, 32, 24)


@pytest.mark.parametrize("seed", range(5))
def test_project_unproject_round_trip_random_poses(seed):
    rng = np.random.default_rng(seed)
    camera = off_centre_camera(random_pose(rng))
    uv = rng.uniform([-0.5, -0.5], [31.5, 23.5], size=(50, 2))
    depth = rng.uniform(0.5, 20.0, size=50)
    points = camera.unproject(uv, depth)
    uv_back, depth_back = camera.project(points)
    np.testing.assert_allclose(uv_back, uv, atol=1e-9)
    np.testing.assert_allclose(depth_back, depth, rtol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_world_points_project_then_unproject(seed):
    rng = np.random.default_rng(100 + seed)
    camera = off_centre_camera(random_pose(rng))
    points_cam = np.column_stack([rng.normal(size=(40, 2)), rng.uniform(1, 10, 40)])
    points = camera.cam_to_world_points(points_cam)
    np.testing.assert_allclose(camera.world_to_camera(points), points_cam, atol=1e-9)
    uv, depth = camera.project(points)
    np.testing.assert_allclose(camera.unproject(uv, depth), points, atol=1e-9)


def test_principal_point_and_pixel_centres():
    camera = off_centre_camera()
    uv, depth = camera.project(np.array([[0.0, 0.0, 3.0], [1.0, -2.0, 4.0]]))
    np.testing.assert_allclose(uv[0], [13.7, 9.2])
    np.testing.assert_allclose(uv[1], [13.7 + 41.5 / 4, 9.2 - 2 * 39.25 / 4])
    np.testing.assert_allclose(depth, [3.0, 4.0])
    directions = camera.pixel_directions(np.array([[13.7, 9.2]]))
    np.testing.assert_allclose(directions, [[0.0, 0.0, 1.0]], atol=1e-12)


def test_points_behind_camera_get_nan_pixels():
    uv, depth = off_centre_camera().project(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0], [0.1, 0.2, 1.0]]))
    assert np.isnan(uv[:2]).all() and np.isfinite(uv[2]).all()
    np.testing.assert_allclose(depth, [-1.0, 0.0, 1.0])


def test_depth_to_points_round_trip_and_nan():
    rng = np.random.default_rng(7)
    camera = off_centre_camera(random_pose(rng))
    depth = rng.uniform(2, 3, size=(24, 32))
    depth[3, 4] = np.nan
    points = camera.depth_to_points(depth)
    assert points.shape == (24, 32, 3)
    assert np.isnan(points[3, 4]).all()
    uv, z = camera.project(points)
    valid = np.isfinite(depth)
    np.testing.assert_allclose(uv[valid], camera.pixel_grid()[valid], atol=1e-9)
    np.testing.assert_allclose(z[valid], depth[valid], rtol=1e-12)
    with pytest.raises(ValueError):
        camera.depth_to_points(np.ones((23, 32)))


def test_pose_inverse_and_centre():
    rng = np.random.default_rng(3)
    camera = off_centre_camera(random_pose(rng))
    np.testing.assert_allclose(camera.cam_to_world @ camera.world_to_cam, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(camera.world_to_camera(camera.center), 0.0, atol=1e-9)


def test_from_focal_centres_principal_point():
    camera = Camera.from_focal(50.0, 32, 24)
    np.testing.assert_allclose(camera.K[:2, 2], [15.5, 11.5])
    assert camera.size == (32, 24)


@pytest.mark.parametrize("factor", [0.5, 2.0, 0.25, 3.0])
def test_scaled_keeps_pixel_footprints_consistent(factor):
    rng = np.random.default_rng(11)
    camera = off_centre_camera(random_pose(rng))
    small = camera.scaled(factor)
    assert small.size == (round(32 * factor), round(24 * factor))
    np.testing.assert_array_equal(small.world_to_cam, camera.world_to_cam)
    points = camera.unproject(rng.uniform(0, 20, size=(20, 2)), rng.uniform(1, 5, 20))
    uv, _ = camera.project(points)
    uv_small, _ = small.project(points)
    # continuous image coordinates (pixel edges at -0.5) scale exactly
    np.testing.assert_allclose(uv_small + 0.5, (uv + 0.5) * factor, atol=1e-9)


def test_scaled_round_trip_and_identity():
    camera = off_centre_camera()
    np.testing.assert_allclose(camera.scaled(1.0).K, camera.K)
    np.testing.assert_allclose(camera.scaled(2.0).scaled(0.5).K, camera.K, atol=1e-12)


def test_look_at_targets_principal_point_and_up_is_minus_v():
    eye, target, up = np.array([10.0, -3.0, 4.0]), np.array([0.5, 1.0, -2.0]), np.array([0.0, 0.0, 1.0])
    pose = look_at(eye, target, up)
    camera = off_centre_camera(pose)
    np.testing.assert_allclose(camera.center, eye, atol=1e-12)
    uv, depth = camera.project(np.stack([target, target + 0.1 * up]))
    np.testing.assert_allclose(uv[0], camera.K[:2, 2], atol=1e-9)
    np.testing.assert_allclose(depth[0], np.linalg.norm(target - eye))
    assert uv[1, 1] < uv[0, 1]  # up in the world is up (smaller v) in the image
    assert np.isclose(np.linalg.det(pose[:3, :3]), 1.0)


def test_look_at_rejects_parallel_up():
    with pytest.raises(ValueError):
        look_at([0, 0, 0], [0, 0, 1], [0, 0, 1])


@pytest.mark.parametrize("K, pose, size", [
    (np.diag([0.0, 1.0, 1.0]), np.eye(4), (4, 4)),                    # zero focal length
    (np.eye(3), np.diag([1.0, 1.0, -1.0, 1.0]), (4, 4)),              # reflection
    (np.eye(3), np.diag([2.0, 1.0, 1.0, 1.0]), (4, 4)),               # not orthonormal
    (np.full((3, 3), np.nan), np.eye(4), (4, 4)),                     # NaN
    (np.eye(2), np.eye(4), (4, 4)),                                   # wrong shape
    (np.eye(3), np.eye(4), (0, 4)),                                   # empty image
])
def test_camera_validation(K, pose, size):
    with pytest.raises(ValueError):
        Camera(K, pose, *size)


def test_view_validation_and_normalisation():
    image = np.zeros((24, 32, 1), np.float64)
    view = View("a", image)
    assert view.image.shape == (24, 32) and view.image.dtype == np.float32
    assert (view.width, view.height, view.channels) == (32, 24, 1)
    assert View("rgb", np.zeros((24, 32, 3))).channels == 3
    mask_view = View("m", np.zeros((24, 32)), mask=np.ones((24, 32), np.uint8))
    assert mask_view.mask.dtype == bool
    with pytest.raises(ValueError, match="mask"):
        View("a", np.zeros((24, 32)), mask=np.ones((24, 31), bool))
    with pytest.raises(ValueError, match="depth"):
        View("a", np.zeros((24, 32)), depth=np.ones((23, 32)))
    with pytest.raises(ValueError, match="camera"):
        View("a", np.zeros((24, 32)), camera=Camera.from_focal(10, 30, 24))
    with pytest.raises(ValueError):
        View("a", np.zeros((24, 32, 2)))
    with pytest.raises(ValueError):
        View("a", np.zeros(32))
    changed = view.with_(mask=np.ones((24, 32), bool))
    assert changed.mask is not None and view.mask is None


def test_capture_access_and_unique_names():
    views = (View("v0", np.zeros((4, 4)), camera=Camera.from_focal(5, 4, 4)), View("v1", np.zeros((4, 4))))
    capture = Capture(views, {"units": "mm"})
    assert len(capture) == 2 and capture.names == ["v0", "v1"]
    assert capture["v1"] is views[1]
    assert not capture.has_cameras
    with pytest.raises(KeyError):
        capture["nope"]
    with pytest.raises(ValueError, match="unique"):
        Capture((views[0], views[0]))


def _sphere_depth(camera: Camera, centre: np.ndarray, radius: float) -> np.ndarray:
    """The camera-frame depth of the near side of a sphere, NaN off it."""
    rays = camera.pixel_directions(camera.pixel_grid())  # z = 1
    c = camera.rotation @ centre + camera.translation
    a, b, cc = (rays ** 2).sum(-1), -2 * rays @ c, c @ c - radius ** 2
    disc = b ** 2 - 4 * a * cc
    with np.errstate(invalid="ignore"):
        return np.where(disc > 0, (-b - np.sqrt(disc)) / (2 * a), np.nan)


def test_depth_normals_are_a_spheres_normals_facing_the_camera():
    from fingersplat3d.scene import depth_normals

    pose = look_at([30.0, -20.0, -100.0], [0.0, 0.0, 0.0], [0.0, -1.0, 0.0])
    camera = Camera(np.array([[900.0, 0, 150.0], [0, 800.0, 110.0], [0, 0, 1.0]]), pose, 320, 240)
    centre, radius = np.array([2.0, -1.0, 3.0]), 8.0
    depth = _sphere_depth(camera, centre, radius)
    normals = depth_normals(camera, depth)
    has = np.isfinite(depth)
    assert has.sum() > 10_000 and np.array_equal(np.isfinite(normals).all(-1), has)
    points = camera.unproject(camera.pixel_grid()[has], depth[has])
    truth = (points - centre) / radius
    found = normals[has]
    assert np.allclose(np.linalg.norm(found, axis=1), 1.0)
    inner = (np.degrees(np.arccos(np.clip((found * truth).sum(1), -1, 1))))
    assert np.median(inner) < 0.05 and np.quantile(inner, 0.9) < 0.5  # the rim, grazing, is coarser
    assert np.all(((camera.center - points) * found).sum(1) > 0)  # every one faces the camera


def test_depth_normals_of_empty_and_tiny_maps_are_nan_and_finite_elsewhere():
    from fingersplat3d.scene import depth_normals

    camera = Camera.from_focal(100.0, 8, 6, np.eye(4))
    assert np.isnan(depth_normals(camera, np.full((6, 8), np.nan))).all()
    one = np.full((6, 8), np.nan)
    one[3, 4] = 2.0  # a lone pixel has no neighbours: no normal to take
    assert np.isnan(depth_normals(camera, one)).all()
    flat = np.full((6, 8), 5.0)
    flat[0, 0] = np.inf
    normals = depth_normals(camera, np.where(np.isfinite(flat), flat, np.nan))
    assert np.allclose(normals[1:, 1:], [0.0, 0.0, -1.0])  # a plane facing the camera (world = camera frame)
    assert np.isnan(normals[0, 0]).all() and np.isfinite(normals[1:, 1:]).all()
