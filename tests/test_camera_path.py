"""Novel-view arcs: equal steps about the rig axis, exact ends, order-independent, degenerate rigs."""
from __future__ import annotations

import numpy as np
import pytest

from fingersplat3d.scene import Camera
from fingersplat3d.splat.camera_path import arc_cameras, cameras_at_angles, rig_geometry
from fingersplat3d.synth.rigs import ring_rig, rotation_about, uwa_rig
from fingersplat3d.synth.shape import FingerParams

PARAMS = FingerParams()
SIZE = (160, 128)
TRUE_AXIS = np.array([1.0, 0.0, 0.0])  # ring_rig turns about the finger axis, +x


def ring_cameras(angles) -> list[Camera]:
    return [view.camera for view in ring_rig(PARAMS, angles, SIZE)]


def angle_about_axis(camera: Camera, reference: Camera, axis: np.ndarray = TRUE_AXIS) -> float:
    """Signed angle (degrees) of ``camera`` relative to ``reference``; the rotation must be about ``axis``."""
    relative = camera.rotation.T @ reference.rotation  # world-frame rotation taking reference to camera
    skew = relative - relative.T
    sine_axis = 0.5 * np.array([skew[2, 1], skew[0, 2], skew[1, 0]])  # sin(angle) * rotation axis
    assert np.allclose(np.cross(sine_axis, axis), 0.0, atol=1e-9), "rotation is not about the axis"
    return float(np.rad2deg(np.arctan2(sine_axis @ axis, (np.trace(relative) - 1.0) / 2.0)))


def assert_same_camera(a: Camera, b: Camera, atol: float = 1e-6) -> None:
    assert a.size == b.size
    assert np.allclose(a.K, b.K, atol=atol)
    assert np.allclose(a.world_to_cam, b.world_to_cam, atol=atol), (a.world_to_cam, b.world_to_cam)


def test_rig_geometry_of_the_uwa_rig():
    cameras = [view.camera for view in ring_rig(PARAMS, (-45.0, 0.0, 45.0), SIZE)]
    rig = rig_geometry(cameras)
    assert np.allclose(rig.axis, TRUE_AXIS, atol=1e-9)
    assert np.allclose(rig.angles_deg, [-45.0, 0.0, 45.0], atol=1e-9)
    assert list(rig.order) == [0, 1, 2]
    for camera in cameras:  # the pivot is on every optical axis
        direction = camera.rotation[2]
        offset = rig.pivot - camera.center
        assert np.linalg.norm(offset - (offset @ direction) * direction) < 1e-9


def test_uwa_rig_points_the_tip_left_and_keeps_left_to_right_order():
    # UWA's raw frames show the tip to the left: image right is -x, and "left" is the leftmost camera.
    cameras = [view.camera for view in uwa_rig(PARAMS, SIZE)]
    rig = rig_geometry(cameras)
    assert np.allclose(rig.axis, -TRUE_AXIS, atol=1e-9) and list(rig.order) == [0, 1, 2]
    assert np.allclose(rig.angles_deg, [-45.0, 0.0, 45.0], atol=1e-9)


def test_arc_of_twelve_covers_the_rig_in_equal_steps():
    cameras = [view.camera for view in ring_rig(PARAMS, (-45.0, 0.0, 45.0), SIZE)]
    arc = arc_cameras(cameras, 12)
    assert len(arc) == 12
    angles = np.array([angle_about_axis(camera, cameras[1]) for camera in arc])
    assert np.allclose(angles, np.linspace(-45.0, 45.0, 12), atol=1e-6)
    assert_same_camera(arc[0], cameras[0], 0)
    assert_same_camera(arc[-1], cameras[2], 0)
    # every arc camera is the ring camera at its angle (the rig is a perfect ring)
    expected = ring_cameras(np.linspace(-45.0, 45.0, 12))
    for camera, truth in zip(arc, expected):
        assert_same_camera(camera, truth)


def test_shuffled_inputs_give_the_same_arc():
    cameras = ring_cameras([-45.0, -10.0, 0.0, 30.0, 45.0])
    arc = arc_cameras(cameras, 7)
    rng = np.random.default_rng(0)
    for _ in range(3):
        shuffled = [cameras[i] for i in rng.permutation(len(cameras))]
        for a, b in zip(arc, arc_cameras(shuffled, 7)):
            assert_same_camera(a, b, 1e-9)


def test_cameras_at_angles_reproduce_ring_cameras():
    cameras = ring_cameras([-45.0, 0.0, 45.0])
    turned = cameras_at_angles(cameras, [22.5, -30.0, 0.0])
    truth = ring_cameras([22.5, -30.0, 0.0])
    for camera, expected in zip(turned, truth):
        assert_same_camera(camera, expected)
    # another reference: rotating the left camera by +45 gives the centre one
    assert_same_camera(cameras_at_angles(cameras, [45.0], reference=0)[0], cameras[1])
    assert_same_camera(cameras_at_angles(cameras, [-45.0], reference=cameras[1])[0], cameras[0])


def test_two_cameras_and_an_asymmetric_rig():
    cameras = ring_cameras([10.0, 70.0])
    arc = arc_cameras(cameras, 4)
    assert_same_camera(arc[0], cameras[0], 0)
    assert_same_camera(arc[-1], cameras[1], 0)
    for camera, truth in zip(arc, ring_cameras([10.0, 30.0, 50.0, 70.0])):
        assert_same_camera(camera, truth)


def test_arbitrary_world_frame():
    """A rig moved by a rigid transform gives the moved arc (nothing depends on world axes)."""
    rotation = rotation_about([0.3, -1.0, 0.6], 75.0)
    motion = np.eye(4)
    motion[:3, :3], motion[:3, 3] = rotation, [5.0, -3.0, 20.0]
    inverse = np.linalg.inv(motion)

    def move(camera: Camera) -> Camera:
        return Camera(camera.K, camera.world_to_cam @ inverse, camera.width, camera.height)

    cameras = ring_cameras([-45.0, 0.0, 45.0])
    moved = [move(camera) for camera in cameras]
    for a, b in zip(arc_cameras(moved, 5), arc_cameras(cameras, 5)):
        assert_same_camera(a, move(b))
    assert np.allclose(rig_geometry(moved).axis, rotation @ TRUE_AXIS, atol=1e-9)


def test_shared_size_and_interpolated_focal():
    cameras = ring_cameras([-45.0, 0.0, 45.0])
    wide = Camera.from_focal(200.0, SIZE[0], SIZE[1], cameras[2].world_to_cam)
    arc = arc_cameras([cameras[0], cameras[1], wide], 5)  # angles -45, -22.5, 0, 22.5, 45
    assert arc[2].K[0, 0] == pytest.approx(cameras[1].K[0, 0])
    assert arc[3].K[0, 0] == pytest.approx(0.5 * (cameras[1].K[0, 0] + 200.0))
    other_size = Camera.from_focal(100.0, 64, 48, cameras[2].world_to_cam)
    with pytest.raises(ValueError, match="size"):
        arc_cameras([cameras[0], other_size])


def test_degenerate_rigs_raise():
    cameras = ring_cameras([-45.0, 0.0, 45.0])
    with pytest.raises(ValueError, match="at least 2"):
        arc_cameras(cameras[:1])
    with pytest.raises(ValueError, match="same orientation"):
        arc_cameras([cameras[0], cameras[0]])
    with pytest.raises(ValueError, match="same orientation"):
        cameras_at_angles([cameras[1], cameras[1]], [10.0])
    with pytest.raises(ValueError):
        arc_cameras(cameras, count=1)


def test_a_camera_stored_portrait_is_turned_back_before_the_arc():
    cameras = [view.camera for view in ring_rig(PARAMS, (-45.0, 0.0, 45.0), SIZE)]
    from fingersplat3d.splat.camera_path import _quarter_turn

    portrait = list(cameras)
    portrait[1] = _quarter_turn(cameras[1], 1)  # the middle image stored turned by 90 degrees
    assert portrait[1].size == cameras[1].size[::-1]
    for a, b in zip(arc_cameras(portrait, 7), arc_cameras(cameras, 7)):
        assert_same_camera(a, b, 1e-6)
