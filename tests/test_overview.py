"""fs3d fuse's overview picture (viz.fuse_overview): each view tinted by what backs its shape, the rig, the turns."""
import numpy as np

from fingersplat3d.scene import Camera
from fingersplat3d.viz import TILE_HEIGHT, fuse_overview


def _ring(count: int, step_deg: float = 45.0) -> list[Camera]:
    """Cameras on a circle about the y axis, 100 units out, all looking at the origin."""
    cameras = []
    for k in range(count):
        angle = np.radians(step_deg * (k - (count - 1) / 2))
        rotation = np.array([[np.cos(angle), 0.0, -np.sin(angle)], [0.0, 1.0, 0.0], [np.sin(angle), 0.0, np.cos(angle)]])
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rotation, [0.0, 0.0, 100.0]
        cameras.append(Camera.from_focal(500.0, 320, 240, pose))
    return cameras


def _pixels_near(picture: np.ndarray, colour) -> int:
    return int((np.abs(picture.astype(int) - np.array(colour)).sum(2) < 40).sum())


def test_views_tinted_by_backing_a_lost_view_framed_and_the_turns_written():
    images = [np.full((240, 320), 0.5, np.float32) for _ in range(3)]
    backing = [np.zeros((60, 80), np.int8), np.ones((60, 80), np.int8), None]  # one view alone, one backed, one lost
    backing[0][:, :40] = -1  # no surface there: the photo as it is
    alignment = {"backed_by_two_views": {"a": 0.0, "b": 1.0}, "turn_sensitivity_deg": {"a-b": 0.9},
                 "focal_probe": {"held": False}}
    cameras = _ring(3)
    picture = fuse_overview(images, ["a", "b", "c"], cameras, backing, alignment)
    assert picture.dtype == np.uint8 and picture.ndim == 3 and picture.shape[0] > TILE_HEIGHT
    amber, green = _pixels_near(picture, (181, 142, 88)), _pixels_near(picture, (97, 160, 110))
    red = _pixels_near(picture, (215, 40, 40))
    assert amber > 0.45 * TILE_HEIGHT * 480  # the right half of view a (480 px wide): the skin only it sees
    assert green > 0.9 * TILE_HEIGHT * 480  # view b, all backed
    assert red > 4 * TILE_HEIGHT  # view c's frame, and the focal's warning
    # With every view placed there is no red at all.
    calm = fuse_overview(images, ["a", "b", "c"], cameras, [backing[1]] * 3,
                         {"focal_probe": None, "turn_sensitivity_deg": None, "backed_by_two_views": None})
    assert _pixels_near(calm, (215, 40, 40)) == 0


def test_one_view_or_parallel_cameras_give_no_rig_drawing_and_no_error():
    images = [np.random.default_rng(0).random((100, 80))]
    single = fuse_overview(images, ["only"], _ring(1), [np.ones((25, 20), np.int8)], {})
    assert single.shape[1] < 2 * TILE_HEIGHT  # the photo alone, no rig tile
    same = _ring(2, step_deg=0.0)  # two cameras looking the same way: no plane of axes to look along
    picture = fuse_overview(images * 2, ["p", "q"], same, [np.ones((25, 20), np.int8)] * 2, {})
    assert np.isfinite(picture).all() and picture.shape[1] < 3 * TILE_HEIGHT


def test_ten_views_wrap_into_rows():
    images = [np.full((240, 320), 0.5, np.float32)] * 10
    picture = fuse_overview(images, [f"p{k}" for k in range(10)], _ring(10, step_deg=9.0),
                            [np.ones((60, 80), np.int8)] * 10, {})
    assert picture.shape[0] > 2 * TILE_HEIGHT + 26  # two rows of photos (five each) and the rig, and the legend
    assert picture.shape[1] < 6 * 480 + 60  # at most five photos wide


def test_turn_lines_wrap_after_their_commas_within_the_tile():
    import cv2

    from fingersplat3d.viz import _wrapped

    line = "f0-f1: 42.6 deg (photo turned -89), moves 0.6 with the focal 10% off"
    assert _wrapped("f1-f2: 87.8 deg", 300, 0.42) == ["f1-f2: 87.8 deg"]
    parts = _wrapped(line, 250, 0.42)
    assert len(parts) == 2 and parts[0].endswith(",") and parts[1].startswith("   moves")
    assert all(cv2.getTextSize(p, cv2.FONT_HERSHEY_SIMPLEX, 0.42, 1)[0][0] <= 250 for p in parts)
    assert _wrapped("one-part-wider-than-the-tile", 10, 0.42) == ["one-part-wider-than-the-tile"]


def test_long_camera_names_stay_inside_the_rig_drawing():
    """File names as long as another group's (``sample2_-45``) beside cameras on either side of the finger: each name
    whole in the drawing (above its dot where there is no room beside it), none cut at the drawing's edge."""
    from fingersplat3d.viz import _label_origin, _rig_tile

    names = ["sample2_-45", "sample2_0", "sample2_47"]
    tile = _rig_tile(_ring(3), names, [True] * 3)
    ink = tile.min(2) < 100  # the names' dark text (the dots are blue, the lines light grey)
    assert ink.any() and not ink[:, :3].any() and not ink[:, -3:].any() and not ink[:3].any() and not ink[-3:].any()
    # cameras all round, names a third of the drawing wide: each name inside it and clear of its dot (radius 6)
    size = 300
    for angle in np.radians(np.arange(0, 360, 15)):
        xy = np.array([np.cos(angle), np.sin(angle)])
        dot = tuple(int(v) for v in np.round(size / 2 + 0.38 * size * xy))
        x, y = _label_origin(dot, xy, (100, 12), size)
        assert 2 <= x and x + 100 <= size - 2 and 14 <= y <= size - 4
        nearest = np.clip(dot, [x, y - 12], [x + 100, y])  # the point of the name's box nearest the dot
        assert np.hypot(*(nearest - np.array(dot))) > 6, (np.degrees(angle), dot, x, y)
    # a short name beside its dot, as before; a name wider than the drawing starts at its edge
    assert _label_origin((36, 150), np.array([-1.0, 0.0]), (20, 12), size) == (2, 156)
    assert _label_origin((264, 150), np.array([1.0, 0.0]), (400, 12), size)[0] == 2
