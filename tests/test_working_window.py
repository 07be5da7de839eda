"""The working window: a large photo whose finger covers little of it is worked on in a window about its centre round
the finger, and every output comes back on the photo's own grid with the cameras the whole photo gives."""
import numpy as np
import pytest

from fingersplat3d.eval import depth_errors, relative_rotation_errors
from fingersplat3d.pipeline import FuseConfig, fuse
from fingersplat3d.scene import Camera, Capture, View, look_at
from fingersplat3d.working_scale import SURVEY_SIDE, working_views
from fingersplat3d.working_window import WINDOW_MAX_SHARE, WINDOW_MIN_MARGIN_PX, Window, box_window, finger_window


def _finger(size, box):
    mask = np.zeros((size[1], size[0]), bool)
    left, top, right, bottom = box
    mask[top:bottom, left:right] = True
    return mask


@pytest.mark.parametrize("box", [(1500, 1200, 2600, 1500), (300, 1000, 1900, 1400), (2000, 2300, 3000, 2800)])
def test_the_window_is_symmetric_about_the_photos_centre_and_holds_the_finger_with_its_margin(box):
    size = (4032, 3024)
    window = finger_window(_finger(size, box), size)
    assert window is not None
    assert 2 * window.left + window.width == size[0] and 2 * window.top + window.height == size[1]
    left, top, right, bottom = box
    margin = WINDOW_MIN_MARGIN_PX
    assert window.left <= left - margin and window.left + window.width >= right + margin
    assert window.top <= top - margin and window.top + window.height >= bottom + margin
    assert window.width * window.height <= WINDOW_MAX_SHARE * size[0] * size[1]


def test_no_window_where_it_would_keep_most_of_the_photo_or_there_is_no_finger():
    size = (4032, 3024)
    assert finger_window(_finger(size, (200, 400, 3800, 2600)), size) is None  # the finger fills the frame
    assert finger_window(_finger(size, (0, 600, 2400, 2400)), size) is None  # out of the frame's side, thick
    assert finger_window(np.zeros((3024, 4032), bool), size) is None
    # a finger running out of the frame's left side: the window reaches both side borders (it never cuts the finger
    # where the photo does not), and keeps the rows round it
    cut = finger_window(_finger(size, (0, 1300, 2400, 1700)), size)
    assert cut is not None and cut.left == 0 and cut.width == size[0] and cut.height < size[1] / 4


def test_a_mask_at_another_resolution_gives_the_photos_window():
    size = (4032, 3024)
    whole = finger_window(_finger(size, (1512, 1260, 2520, 1764)), size)
    survey = finger_window(_finger((1280, 960), (480, 400, 800, 560)), size)  # the same box at 1280/4032
    assert abs(whole.left - survey.left) <= 4 and abs(whole.top - survey.top) <= 4


@pytest.mark.parametrize("box", [(1500, 1200, 2600, 1500), (300, 1000, 1900, 1400), (0, 1300, 2400, 1700)])
def test_the_box_window_holds_the_finger_with_its_margin_and_no_more(box):
    """For the splat fit: round the finger's own box, as small as the margin allows wherever the finger lies."""
    size = (4032, 3024)
    mask = _finger(size, box)
    window, about_centre = box_window(mask, size), finger_window(mask, size)
    left, top, right, bottom = box
    margin = max(WINDOW_MIN_MARGIN_PX, 0.25 * min(right - left, bottom - top))
    assert window.left == max(0, int(np.floor(left - margin))) and window.top == max(0, int(np.floor(top - margin)))
    assert window.left + window.width == min(size[0], int(np.ceil(right + margin)))
    assert window.top + window.height == min(size[1], int(np.ceil(bottom + margin)))
    assert window.width * window.height <= about_centre.width * about_centre.height
    assert box_window(_finger(size, (200, 400, 3800, 2600)), size) is None  # the finger fills the frame
    assert box_window(np.zeros((3024, 4032), bool), size) is None


def test_a_camera_carried_into_a_window_and_back_is_the_same_camera():
    window = Window(700, 1100, 1500, 600, 4032, 3024)  # off the photo's centre
    pose = look_at([5.0, -3.0, -100.0], [0, 0, 0], [0, -1, 0])
    photo = Camera.from_focal(3000.0, 4032, 3024, pose)
    inside = window.camera_in_window(photo)
    assert inside.size == (1500, 600) and inside.K[0, 2] == pytest.approx(photo.K[0, 2] - 700)
    back = window.camera_on_photo(inside)
    np.testing.assert_allclose(back.K, photo.K)
    np.testing.assert_allclose(back.world_to_cam, photo.world_to_cam)
    with pytest.raises(ValueError):
        window.camera_in_window(Camera.from_focal(3000.0, 640, 512, pose))


def test_a_window_cameras_projection_is_the_photos_shifted_by_its_corner():
    window = Window(1000, 800, 2032, 1424, 4032, 3024)
    pose = look_at([5.0, -3.0, -100.0], [0, 0, 0], [0, -1, 0])
    inside = Camera.from_focal(3000.0, 2032, 1424, pose)
    photo = window.camera_on_photo(inside)
    assert photo.size == (4032, 3024) and photo.K[0, 2] == pytest.approx(2015.5) and photo.K[1, 2] == pytest.approx(1511.5)
    points = np.random.default_rng(0).normal(0.0, 5.0, (20, 3))
    uv_inside, depth_inside = inside.project(points)
    uv_photo, depth_photo = photo.project(points)
    np.testing.assert_allclose(uv_photo, uv_inside + [1000, 800], atol=1e-9)
    np.testing.assert_allclose(depth_photo, depth_inside)
    with pytest.raises(ValueError):
        window.camera_on_photo(Camera.from_focal(3000.0, 640, 512, pose))
    values = np.ones((1424, 2032), np.float32)
    padded = window.padded(values)
    assert padded.shape == (3024, 4032) and np.isnan(padded[:800]).all() and (window.cut(padded) == 1).all()


def _on_canvas(view: View, size, with_mask: bool) -> View:
    """The view pasted at the centre of a larger dark canvas: the same camera with a larger frame (its principal
    point still at the centre), the finger now a small part of the photo."""
    height, width = view.image.shape[:2]
    top, left = (size[1] - height) // 2, (size[0] - width) // 2
    image = np.zeros((size[1], size[0]) + view.image.shape[2:], np.float32)
    image[top:top + height, left:left + width] = view.image
    mask = None
    if with_mask:
        mask = np.zeros((size[1], size[0]), bool)
        mask[top:top + height, left:left + width] = view.mask
    return View(view.name, image, mask)


def test_working_views_cut_large_photos_to_their_windows_and_leave_small_ones_whole(uwa640):
    size = (1920, 1440)
    assert max(size) > SURVEY_SIDE
    photos = [_on_canvas(v, size, with_mask=False) for v in uwa640.views]
    photo, working, scale = working_views(photos, windows=True)
    assert scale.windowed and len(scale.windows) == 3
    for p, w, window in zip(photo, working, scale.windows):
        assert window is not None and (w.width, w.height) == window.size  # the ridges kept at the photo's sampling
        assert p.mask.shape == (1440, 1920) and not p.mask[~np.pad(np.ones((window.height, window.width), bool),
                                                              ((window.top,) * 2, (window.left,) * 2))].any()
        assert w.mask.sum() == pytest.approx(window.cut(p.mask).sum(), rel=0.02)
    report = scale.as_report([(v.width, v.height) for v in photos])
    assert report["windows"][0] == scale.windows[0].as_report() and report["sizes"][0] == list(scale.windows[0].size)
    # photos of the survey's size or smaller, or a windowing not asked for: whole
    assert not working_views(uwa640.views, windows=True)[2].windowed
    assert not working_views(photos)[2].windowed


def test_a_fuse_in_windows_answers_on_the_photos_grid_with_the_whole_photos_cameras(uwa640):
    """The sample's views on a canvas three times their area: fused in windows of about a tenth of it, the turns, the
    focal and the depth are the true ones, on the photos' grid, nothing outside the windows."""
    size = (1920, 1440)
    big = Capture(tuple(_on_canvas(v, size, with_mask=True) for v in uwa640.views), uwa640.metadata)
    result = fuse(big, FuseConfig(splat=None))
    windows = result.report["working_resolution"]["windows"]
    assert all(w is not None and w[2] * w[3] < 0.3 * size[0] * size[1] for w in windows)
    assert result.registered
    truths = [v.camera.world_to_cam for v in uwa640.views]
    assert max(relative_rotation_errors([c.world_to_cam for c in result.cameras], truths)) < 2  # measured 0.3 degrees
    for camera, depth, truth, window in zip(result.cameras, result.depths, uwa640.views, windows):
        assert camera.size == size and camera.K[0, 2] == pytest.approx((size[0] - 1) / 2)
        assert camera.K[0, 0] == pytest.approx(truth.camera.K[0, 0], rel=0.1)
        assert depth.shape == (size[1], size[0])
        left, top, width, height = window
        outside = np.ones(depth.shape, bool)
        outside[top:top + height, left:left + width] = False
        assert np.isnan(depth[outside]).all()
        t, l = (size[1] - truth.height) // 2, (size[0] - truth.width) // 2
        error = depth_errors(depth[t:t + truth.height, l:l + truth.width], truth.depth, truth.mask)
        assert error.coverage > 0.95 and error.mae < 0.3


def test_a_photo_too_large_to_segment_again_takes_its_survey_mask_carried_into_the_window(uwa640):
    """Above MASK_SIDE_MAX the whole photo's working mask is the survey copy's resized; in a window it is the survey
    copy's carried onto the window's grid, the same outline."""
    from fingersplat3d.working_scale import MASK_SIDE_MAX

    size = (2800, 2100)
    assert max(size) > MASK_SIDE_MAX
    truth = [_on_canvas(v, size, with_mask=True) for v in uwa640.views]
    photo, working, scale = working_views([View(v.name, v.image) for v in truth], windows=True)
    window = scale.windows[0]
    assert window is not None and all(w is window for w in scale.windows)
    for t, p, w in zip(truth, photo, working):
        true = window.cut(t.mask)
        assert w.mask.shape == true.shape
        assert (w.mask & true).sum() / (w.mask | true).sum() > 0.95  # the survey copy's outline, at 0.46x
        assert not p.mask[:window.top].any() and (window.cut(p.mask) == w.mask).all()


def test_the_splat_fit_works_in_each_fingers_own_box_with_the_geometrys_cameras(uwa640):
    """The splat fit takes the cameras as given, so it works in each finger's box rather than the geometry's window
    about the photo's centre: its cameras come back on the photo's grid as the geometry's, its depths nothing outside
    the box, and the photos fitted as well as in the geometry's windows."""
    from fingersplat3d.splat.config import SplatConfig

    size = (1920, 1440)
    big = Capture(tuple(_on_canvas(v, size, with_mask=True) for v in uwa640.views), uwa640.metadata)
    splat = SplatConfig(iterations=20, densify_from=1000)
    result = fuse(big, FuseConfig(splat=splat))
    windows = result.report["working_resolution"]["windows"]
    boxes = result.report["working_resolution"]["splat"]["windows"]
    for (left, top, width, height), (l, t, w, h) in zip(windows, boxes):
        assert left <= l and top <= t and l + w <= left + width and t + h <= top + height
    assert sum(w * h for _, _, w, h in boxes) < sum(w * h for _, _, w, h in windows)
    for camera, focal in zip(result.cameras, result.report["alignment"]["focals_px"]):  # the geometry's, as fitted
        assert camera.size == size and camera.K[0, 2] == pytest.approx((size[0] - 1) / 2)
        assert camera.K[1, 2] == pytest.approx((size[1] - 1) / 2) and camera.K[0, 0] == pytest.approx(focal, rel=1e-6)
    truths = [v.camera.world_to_cam for v in uwa640.views]
    assert max(relative_rotation_errors([c.world_to_cam for c in result.cameras], truths)) < 2
    for depth, (l, t, w, h) in zip(result.splat_depths, boxes):
        assert depth.shape == (size[1], size[0])
        outside = np.ones(depth.shape, bool)
        outside[t:t + h, l:l + w] = False
        assert np.isnan(depth[outside]).all() and np.isfinite(depth[~outside]).mean() > 0.05
    assert min(result.report["splat"]["psnr_in_mask_db"].values()) > 25
