"""The finger's axis in 3D from registered cameras and each view's tilt in depth (align/axis_tilt.py), the prior drawn
tilted (pointmaps/prior.py), and a pitched finger's registration redrawing its pointmaps with it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fingersplat3d.align.axis_tilt import MIN_PLANE_SPREAD, tilt_deg, view_tilts
from fingersplat3d.errors import InputError
from fingersplat3d.pointmaps.prior import PriorBackend, tilted_height
from fingersplat3d.segment.axis_planes import planes_meet
from fingersplat3d.scene import Camera, View, look_at
from fingersplat3d.synth.rigs import rotation_about

SIZE = (640, 512)
FOCAL = 1200.0


def _ring(angles_deg, distance=100.0):
    """Cameras on a ring about the world x axis, looking at the origin (as the UWA rig about a level finger)."""
    cameras = []
    for angle in np.radians(angles_deg):
        eye = distance * np.array([0.0, -math.sin(angle), -math.cos(angle)])
        cameras.append(Camera.from_focal(FOCAL, *SIZE, look_at(eye, np.zeros(3), np.array([0.0, -1.0, 0.0]))))
    return cameras


def _image_axis(camera, direction):
    """The finger axis (through the origin along ``direction``) as each photo shows it: (unit direction, a point)."""
    uv, _ = camera.project(np.stack([-5.0 * direction, 5.0 * direction]))
    step = uv[1] - uv[0]
    return step / np.linalg.norm(step), uv[0]


def _pitched(deg):
    return rotation_about([0.0, 1.0, 0.0], deg) @ np.array([1.0, 0.0, 0.0])


def axis_direction(normals):
    return planes_meet(normals, MIN_PLANE_SPREAD)


def test_the_axis_is_where_the_views_planes_meet_and_open_where_they_coincide():
    direction = np.array([0.6, 0.0, 0.8])
    normals = np.array([[0.0, 1.0, 0.0], [-0.8, 0.0, 0.6], [-0.8 / math.sqrt(2), 1 / math.sqrt(2), 0.6 / math.sqrt(2)]])
    found = axis_direction(normals)
    assert abs(abs(found @ direction) - 1.0) < 1e-12
    assert axis_direction(normals[:1]) is None  # one plane holds every direction in it
    assert axis_direction(np.stack([normals[0], normals[0]])) is None  # two views from one place
    close = np.array([[0.0, 1.0, 0.0], [0.0, math.cos(0.05), math.sin(0.05)]])  # planes 3 degrees apart
    assert axis_direction(close) is None and math.tan(0.025) < MIN_PLANE_SPREAD
    assert axis_direction(np.array([[np.nan, 0, 0], [0, 1.0, 0]])) is None


def test_a_view_the_axis_would_put_beyond_45_degrees_is_drawn_level():
    """A registration that puts the finger pointing into a camera gives that view no tilt (the prior would refuse a
    gradient of a finger seen nearly end on, and the registration is what is wrong)."""
    from fingersplat3d.align.axis_tilt import MAX_TILT_DEG

    cameras = _ring([-45.0, 0.0, 45.0])
    direction = _pitched(60.0)
    axes = [_image_axis(camera, direction) for camera in cameras]
    tilts = view_tilts([np.linalg.inv(c.world_to_cam) for c in cameras], [FOCAL] * 3, [SIZE] * 3, axes, [True] * 3)
    assert tilts[1] is None  # the front camera sees the axis 60 degrees out of its plane
    assert all(t is None or tilt_deg(t) <= MAX_TILT_DEG for t in tilts)


@pytest.mark.parametrize("pitch", [0.0, 7.0, -12.0, 20.0])
def test_each_views_tilt_is_the_axis_angle_out_of_its_photo_plane(pitch):
    """Three cameras ±45° about a finger pitched toward them: each view's tilt is the angle its axis makes with the
    image plane, and the gradient points the way the axis recedes, at the scale of one unit a pixel at one focal."""
    cameras = _ring([-45.0, 0.0, 45.0])
    direction = _pitched(pitch)
    axes = [_image_axis(camera, direction) for camera in cameras]
    tilts = view_tilts([np.linalg.inv(c.world_to_cam) for c in cameras], [FOCAL] * 3, [SIZE] * 3, axes, [True] * 3)
    for camera, tilt, (axis, _) in zip(cameras, tilts, axes):
        local = camera.rotation @ direction
        assert tilt_deg(tilt) == pytest.approx(math.degrees(math.asin(abs(local[2]))), abs=1e-6)
        # a step of one pixel along the image axis changes depth by the gradient's share, in units of depth / focal
        near, far = camera.world_to_camera(np.stack([np.zeros(3), 0.01 * direction]))
        pixels = camera.project(np.stack([np.zeros(3), 0.01 * direction]))[0]
        measured = (far[2] - near[2]) / near[2] * FOCAL / np.linalg.norm(pixels[1] - pixels[0])
        assert tilt @ (pixels[1] - pixels[0]) / np.linalg.norm(pixels[1] - pixels[0]) == pytest.approx(measured, rel=0.02, abs=1e-4)
    # the image axis's sign is the silhouette's choice: either way, the same gradient
    flipped = [(-axis, point) for axis, point in axes]
    again = view_tilts([np.linalg.inv(c.world_to_cam) for c in cameras], [FOCAL] * 3, [SIZE] * 3, flipped, [True] * 3)
    assert all(np.allclose(a, b) for a, b in zip(tilts, again))


def test_views_not_aligned_get_no_tilt_and_one_view_leaves_the_axis_open():
    cameras = _ring([-45.0, 0.0, 45.0])
    direction = _pitched(10.0)
    axes = [_image_axis(camera, direction) for camera in cameras]
    poses = [np.linalg.inv(c.world_to_cam) for c in cameras]
    tilts = view_tilts(poses, [FOCAL] * 3, [SIZE] * 3, axes, [True, False, True])
    assert tilts[1] is None and tilts[0] is not None and tilts[2] is not None
    assert view_tilts(poses, [FOCAL] * 3, [SIZE] * 3, axes, [True, False, False]) == [None, None, None]
    for lost in (math.nan, math.inf, 0.0, -5.0):  # a fit that lost its focal: that view gives no plane, no error
        assert view_tilts(poses, [lost, FOCAL, FOCAL], [SIZE] * 3, axes, [True] * 3)[0] is None
    assert tilt_deg(None) is None


def test_the_prior_drawn_tilted_ramps_its_depth_about_the_masks_median_pixel():
    mask = np.zeros((120, 200), bool)
    mask[40:80, 20:180] = True
    height = np.where(mask, 10.0, 0.0).astype(np.float32)
    tilted = tilted_height(height, mask, (0.1, -0.05))
    rows, cols = np.nonzero(mask)
    expected = 10.0 - (0.1 * (cols - np.median(cols)) - 0.05 * (rows - np.median(rows)))
    assert np.allclose(tilted[rows, cols], expected, atol=1e-5) and np.all(tilted[~mask] == 0.0)
    assert tilted.dtype == height.dtype
    assert tilted_height(height, np.zeros_like(mask), (1.0, 1.0)) is height
    # through the backend: the depth along the finger ramps by the gradient, the median pixel's stays
    view = View("v", np.full(mask.shape, 0.5, np.float32), mask=mask)
    level, = PriorBackend(focal_px=800.0).predict_views([view])
    ramped, = PriorBackend(focal_px=800.0, view_tilts=((0.2, 0.0),)).predict_views([view])
    difference = ramped.depth[60, 150] - ramped.depth[60, 50] - (level.depth[60, 150] - level.depth[60, 50])
    assert difference == pytest.approx(0.2 * 100, rel=1e-4)
    assert PriorBackend(focal_px=800.0, view_tilts=(None,)).predict_views([view])[0].depth.tobytes() == level.depth.tobytes()


@pytest.mark.parametrize("tilt", [(math.nan, 0.0), (0.0, math.inf), (9.0, 0.0)])
def test_the_prior_refuses_a_tilt_that_is_not_a_fingers(tilt):
    with pytest.raises(InputError, match="view_tilts"):
        PriorBackend(view_tilts=(tilt,))


class _Asked(Exception):
    pass


def _asking(focal, tilts):
    raise _Asked(focal, tilts)


@pytest.mark.parametrize("aligned, tilt_deg_, focal, expected", [
    (3, 5.0, 3000.0, (None, True)),  # focal held where it was: the tilt alone is drawn
    (3, 5.0, 3600.0, (3600.0, True)),  # both
    (3, 2.0, 3600.0, (3600.0, False)),  # a tilt under redraw_tilt_deg: the focal alone
    (3, 2.0, 3000.0, None),  # neither: nothing redrawn
    (2, 8.0, 3000.0, None),  # two views: never (their turn moves with any new start)
])
def test_the_pointmaps_are_redrawn_with_the_tilt_with_three_views_where_it_reaches_the_threshold(aligned, tilt_deg_, focal,
                                                                                              expected):
    from fingersplat3d.align.register import _redrawn
    from fingersplat3d.align.registration_config import RegistrationConfig
    from fingersplat3d.align.solve.global_opt import GlobalAlignment

    depths = [np.full((8, 8), 3000.0, np.float32)] * 3
    alignment = GlobalAlignment([np.eye(4)] * 3, [focal] * 3, depths, [1.0] * 3, [1.0] * 3, 0.1, 0.01, [(0, 1), (0, 2)],
                                [True] * aligned + [False] * (3 - aligned), 0)
    tilts = [np.array([math.tan(math.radians(tilt_deg_)), 0.0]) if k < aligned else None for k in range(3)]
    config = RegistrationConfig()
    assert config.redraw_tilt_deg == 3.0
    if expected is None:
        assert _redrawn(alignment, depths, [3000.0] * 3, ([], None), _asking, config, tilts) is None
        return
    with pytest.raises(_Asked) as asked:
        _redrawn(alignment, depths, [3000.0] * 3, ([], None), _asking, config, tilts)
    drawn_focal, drawn_tilts = asked.value.args
    assert drawn_focal == expected[0] and (drawn_tilts is not None) == expected[1]
    if expected[1]:  # each view's gradient, as plain numbers (the prior's setting)
        assert all(tilt == pytest.approx((math.tan(math.radians(tilt_deg_)), 0.0)) for tilt in drawn_tilts)
    from dataclasses import replace
    off = replace(config, redraw_tilt_deg=0.0)  # 0: the tilt is never drawn
    if expected[0] is None:
        assert _redrawn(alignment, depths, [3000.0] * 3, ([], None), _asking, off, tilts) is None


def test_a_finger_lying_tilted_in_the_rig_is_found_so_and_drawn_tilted():
    """The shipped sample uwa_seed1: its finger lies yawed and rolled in the rig, its axis 1.6 / 5.1 / 8.9 degrees out
    of the three photos' planes (from the true cameras). The registered cameras give the same tilts, and the
    pointmaps are drawn again with them."""
    from pathlib import Path

    from fingersplat3d.segment.silhouette import capture_finger_axes
    from fingersplat3d.io.capture import read_capture
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.scene import Capture

    capture = read_capture(Path(__file__).resolve().parents[1] / "data_samples" / "uwa_seed1")
    views = capture.views
    truth = view_tilts([np.linalg.inv(v.camera.world_to_cam) for v in views], [v.camera.K[0, 0] for v in views],
                       [(v.width, v.height) for v in views], capture_finger_axes([v.mask for v in views]), [True] * 3)
    blind = Capture(tuple(v.with_(camera=None, depth=None) for v in views), capture.metadata)
    registration = fuse(blind, FuseConfig(splat=None)).report["registration"]
    found = registration["axis_tilt_deg"]
    for view, true_tilt in zip(views, truth):
        assert found[view.name] == pytest.approx(tilt_deg(true_tilt), abs=1.0)  # measured within 0.2 degrees
    assert registration["pointmaps_tilted"] and max(found.values()) > 5.0
