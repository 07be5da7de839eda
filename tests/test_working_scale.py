"""The working resolution: photos that sample the ridges finely are fused at a set pixels per ridge, and the
outputs come back on the photos' own grid."""
import cv2
import numpy as np
import pytest

from fingersplat3d.align.solve.rig import Rig
from fingersplat3d.errors import InputError
from fingersplat3d.eval import depth_errors, relative_rotation_errors
from fingersplat3d.pipeline import FuseConfig, fuse
from fingersplat3d.scene import Camera, Capture, View, look_at
from fingersplat3d.synth import SynthConfig, synthesize
from fingersplat3d.sampling import map_on_grid, resized_image, resized_mask
from fingersplat3d.working_scale import MIN_SIDE, RIDGE_PX, SPLAT_RIDGE_PX, resized_growth, working_views


@pytest.fixture(scope="module")
def uwa1280():
    return synthesize(1, SynthConfig(size=(1280, 1024))).capture


def _upscaled(view: View, factor: float) -> View:
    size = (round(view.width * factor), round(view.height * factor))
    return View(view.name, cv2.resize(view.image, size, interpolation=cv2.INTER_CUBIC).clip(0, 1))


def test_fine_photos_are_scaled_to_the_asked_pixels_per_ridge(uwa1280):
    views = [View(v.name, v.image) for v in uwa1280.views]  # images only: masks are found
    photo, working, scale = working_views(views, 8.0)
    assert 0.3 < scale.factor < 0.6  # ~18 px per ridge at 1280x1024
    assert scale.period_px * scale.factor == pytest.approx(8.0, rel=0.02)
    for original, p, w in zip(views, photo, working):
        assert p.image is original.image and p.mask.shape == original.image.shape[:2]
        assert (w.width, w.height) == (round(1280 * scale.factor), round(1024 * scale.factor))
        assert w.mask.shape == (w.height, w.width) and w.mask.any()
        # the masks agree: the photo's mask brought down is the working one
        assert (resized_mask(p.mask, (w.width, w.height)) == w.mask).mean() > 0.995


def test_photos_near_the_asked_resolution_or_none_asked_are_kept(uwa640, uwa1280):
    _, working, scale = working_views(uwa640.views, 8.0)  # ~9 px per ridge: not worth a resampling
    assert scale.factor == 1.0 and all(w.image is v.image for w, v in zip(working, uwa640.views))
    _, working, scale = working_views(uwa1280.views, SPLAT_RIDGE_PX)  # ~18 px: the splat fit's default keeps it
    assert scale.factor == 1.0 and all(w.image is v.image for w, v in zip(working, uwa1280.views))
    sizes = [(1280, 1024)] * 3
    assert scale.at(RIDGE_PX, sizes).factor == pytest.approx(RIDGE_PX / scale.period_px) and scale.at(8.0, sizes).factor < 0.6
    assert scale.at(None, [(1280, 1024)] * 3).factor == 1.0
    _, working, scale = working_views(uwa640.views, None)
    assert scale.factor == 1.0 and np.isnan(scale.period_px)
    with pytest.raises(InputError, match="pixels per ridge"):
        working_views(uwa640.views, 0.0)
    flat = [View(v.name, np.where(v.mask, 0.6, 0.05).astype(np.float32)) for v in uwa640.views]
    _, _, scale = working_views(flat, 8.0)  # no ridges to measure: the photos as they are
    assert scale.factor == 1.0 and np.isnan(scale.period_px)


def test_ridge_periods_measured_on_the_survey_copy_or_at_full_resolution(uwa640):
    view = uwa640.views[1]
    _, _, own = working_views([view], 8.0)  # ~9 px per ridge
    # A finger small in a large frame: ~2 px per ridge on the quarter-size survey copy, too fine to see there:
    # measured again on a photo-resolution crop.
    canvas = np.zeros((4096, 5120) + view.image.shape[2:], np.float32)
    canvas[1792:2304, 2240:2880] = view.image
    _, working, scale = working_views([View("small", canvas)], 8.0)
    assert scale.period_px == pytest.approx(own.period_px, rel=0.1) and scale.factor == 1.0
    # A photo 4x finer (2560 px, ~36 px per ridge): surveyed at 1280, scaled to the asked sampling.
    _, working, scale = working_views([_upscaled(view, 4.0)], RIDGE_PX)
    assert scale.period_px == pytest.approx(own.period_px * 4.0, rel=0.1)
    assert working[0].width == round(view.width * 4.0 * scale.factor)
    assert scale.period_px * scale.factor == pytest.approx(RIDGE_PX, rel=1e-6)


def test_the_working_side_never_falls_below_its_floor(uwa640):
    small = [View(v.name, cv2.GaussianBlur(v.image, (0, 0), 1.0)) for v in uwa640.views]
    _, working, scale = working_views(small, 1.0)  # 1 px per ridge asked: held at the floor
    assert min(w.width for w in working) >= MIN_SIDE - 1 and min(w.height for w in working) >= MIN_SIDE - 1


def test_camera_resized_keeps_pixel_centres():
    camera = Camera.from_focal(900.0, 1280, 1024, look_at([0, 0, -5], [0, 0, 0], [0, -1, 0]))
    small = camera.resized((640, 512))
    points = np.random.default_rng(0).normal(size=(50, 3))
    uv, _ = camera.project(points)
    uv_small, _ = small.project(points)
    assert np.allclose(uv_small, (uv + 0.5) * 0.5 - 0.5)
    assert small.K[0, 2] == pytest.approx((640 - 1) / 2) and small.K[0, 0] == pytest.approx(450.0)
    back = small.resized((1280, 1024))
    assert np.allclose(back.K, camera.K) and np.array_equal(back.world_to_cam, camera.world_to_cam)
    assert camera.scaled(0.5).K == pytest.approx(small.K)


def test_maps_come_back_without_bleeding_across_the_rim():
    depth = np.full((40, 50), np.nan, np.float32)
    depth[10:30, 12:40] = 7.0
    mask = np.zeros((80, 100), bool)
    mask[20:60, 24:80] = True
    up = map_on_grid(depth, (100, 80), mask)
    assert np.isnan(up[~mask]).all()
    inside = up[mask]
    assert np.isfinite(inside).mean() > 0.98 and np.allclose(inside[np.isfinite(inside)], 7.0)
    assert np.isnan(map_on_grid(np.full((4, 5), np.nan, np.float32), (10, 8))).all()  # nothing to spread: NaN
    huge = map_on_grid(np.full((4, 5), 3e38, np.float32), (10, 8))  # extremes stay finite
    assert np.isfinite(huge).all()


def test_rig_scaled_to_the_working_resolution():
    rig = Rig(("a", "b"), ((1280, 1024), (1024, 1280)), np.stack([np.eye(3)] * 2), np.zeros((2, 3)), 1700.0)
    small = rig.scaled(0.5)
    assert small.sizes == ((640, 512), (512, 640)) and small.focal == pytest.approx(850.0)
    assert small.turns_for(1, (640, 512)) == (1, 3) and rig.scaled(1.0) is rig


def test_fuse_of_fine_photos_answers_on_their_own_grid(uwa1280):
    blind = Capture(tuple(View(v.name, v.image) for v in uwa1280.views), uwa1280.metadata)
    result = fuse(blind, FuseConfig(splat=None, ridge_px=8.0))
    working = result.report["working_resolution"]
    assert working["factor"] < 0.6 and working["sizes"][0] == [round(1280 * working["factor"]), round(1024 * working["factor"])]
    assert result.registered
    errors = relative_rotation_errors([c.world_to_cam for c in result.cameras], [v.camera.world_to_cam for v in uwa1280.views])
    assert max(errors) < 5  # measured within 1 degree (docs/measurements.md); a broken alignment is tens
    for view, truth, camera, depth in zip(result.capture.views, uwa1280.views, result.cameras, result.depths):
        assert camera.size == (1280, 1024) and depth.shape == (1024, 1280) and view.mask.shape == (1024, 1280)
        # the focal is in photo pixels: close to the true one, not to half of it
        assert camera.K[0, 0] == pytest.approx(truth.camera.K[0, 0], rel=0.35)
        error = depth_errors(depth, truth.depth, truth.mask)
        assert error.coverage > 0.95 and error.mae < 0.6
    assert max(result.report["alignment"]["focals_px"]) == pytest.approx(result.cameras[0].K[0, 0], rel=1e-6)


def test_a_photo_that_is_anothers_shrunk_is_grown_onto_its_pixels():
    assert resized_growth([(1280, 1024), (640, 512), (1024, 1280)]) == (1.0, 2.0, 1.0)  # either way up
    assert resized_growth([(1280, 1024), (853, 683)]) == pytest.approx((1.0, 1280 / 853))
    assert resized_growth([(1280, 1024)] * 3) == ()
    assert resized_growth([(1280, 1024), (1024, 1024)]) == ()  # another sides' ratio: a crop, or another camera
    assert resized_growth([(1280, 1024), (1270, 1016)]) == ()  # a few pixels off: the same size
    # with the ridges measured: shrunk where its ridges are as much narrower, else cut from a larger photo
    assert resized_growth([(1280, 1024), (640, 512), (1280, 1024)], [14.0, 7.3, 15.0]) == (1.0, 2.0, 1.0)
    assert resized_growth([(1280, 1024), (640, 512), (1280, 1024)], [14.0, 13.1, 15.0]) == ()
    assert resized_growth([(1280, 1024), (640, 512)], [14.0, float("nan")]) == ()  # nothing to tell them apart by


def test_a_photo_cut_about_its_centre_is_not_taken_for_one_shrunk(uwa1280):
    """A photo cut from a larger one at its sides' ratio keeps its ridges as wide as the others' (and its focal in
    pixels): worked on as it is, where the same photo shrunk to that size is grown."""
    views = [View(v.name, v.image) for v in uwa1280.views]
    cut = views[1].image[128:896, 160:1120]  # 960 x 768 about the centre
    shrunk = resized_image(views[1].image, (960, 768))
    _, working, scale = working_views([views[0], View("cut", cut), views[2]])
    assert scale.growth == () and (working[1].width, working[1].height) == scale.size((960, 768), 1)
    _, working, scale = working_views([views[0], View("shrunk", shrunk), views[2]])
    assert scale.growth == pytest.approx((1.0, 1280 / 960, 1.0))
    assert (working[1].width, working[1].height) == (working[0].width, working[0].height)


def test_a_capture_with_one_photo_at_half_the_others_size_fuses_on_each_photos_grid(uwa1280):
    """One camera's photo shrunk to half (a smaller size set on it, a copy made to send): its focal is half the others'
    in its own pixels, which the fit, holding one focal for all, could not take (the real capture 1_1_4_1 with its
    side view halved: exit 3); grown onto the others' pixels, it registers (that capture's turns within 0.52 deg of
    its whole photos', docs/measurements.md), and everything comes back on its own grid."""
    views = [View(v.name, v.image) for v in uwa1280.views]
    views[1] = View(views[1].name, resized_image(views[1].image, (640, 512)))
    result = fuse(Capture(tuple(views), uwa1280.metadata), FuseConfig(splat=None))
    working = result.report["working_resolution"]
    assert working["photos_grown"] == [1.0, 2.0, 1.0] and working["sizes"][1] == working["sizes"][0]
    assert result.registered
    errors = relative_rotation_errors([c.world_to_cam for c in result.cameras],
                                      [v.camera.world_to_cam for v in uwa1280.views])
    assert max(errors) < 2  # measured 0.17-0.34 deg over three seeds (none registered before); a broken alignment: tens
    assert result.cameras[1].size == (640, 512) and result.depths[1].shape == (512, 640)
    assert result.capture.views[1].mask.shape == (512, 640)
    assert result.cameras[1].K[0, 0] == pytest.approx(0.5 * result.cameras[0].K[0, 0], rel=1e-3)
    assert result.cameras[0].K[0, 0] == pytest.approx(uwa1280.views[0].camera.K[0, 0], rel=0.1)
    focals = result.report["alignment"]["focals_px"]
    assert focals[1] == pytest.approx(0.5 * focals[0], rel=1e-3)


def test_the_measured_period_is_handed_on_only_when_it_is_the_registrations_own(uwa640, uwa1280):
    from fingersplat3d.align.correspond.texture import as_gray, estimate_ridge_period

    _, working, scale = working_views(uwa640.views, RIDGE_PX)  # kept as it is: the same images, masks, estimate
    own = float(np.median([estimate_ridge_period(as_gray(v.image), v.mask) for v in working]))
    assert scale.working_period_px() == own
    _, _, scaled = working_views(uwa1280.views, 8.0)  # scaled: the registration measures it on its own images
    assert scaled.factor < 1 and scaled.working_period_px() is None
    assert working_views(uwa640.views, None)[2].working_period_px() is None  # nothing measured


def test_a_view_blurred_beyond_its_ridges_is_named_and_the_sharp_ones_are_not(uwa1280):
    """The fuse warns of a view whose photo shows no ridges (out of focus: the registration works on ridges); the
    ridge periods are the working-resolution survey's, the rule is texture.no_ridges."""
    from fingersplat3d.pipeline import _ridgeless

    views = list(uwa1280.views)
    views[1] = views[1].with_(image=cv2.GaussianBlur(views[1].image, (0, 0), 12.0))  # ~18 px ridges at 1280x1024
    photos, _, scale = working_views(views)
    said = _ridgeless(Capture(tuple(photos), {}), scale)
    assert len(said) == 1 and repr(views[1].name) in said[0] and "no ridges" in said[0]
    sharp, _, sharp_scale = working_views(uwa1280.views)
    assert _ridgeless(Capture(tuple(sharp), {}), sharp_scale) == []
    unmeasured, _, unmeasured_scale = working_views(views, ridge_px=None)  # --ridge-px 0: nothing measured, no word
    assert _ridgeless(Capture(tuple(unmeasured), {}), unmeasured_scale) == []


def test_the_splat_fits_on_its_own_grid_and_everything_comes_back_on_the_photos(uwa1280):
    """The geometry at 8 px per ridge, the splat fit at SPLAT_RIDGE_PX (the photos' own ~18 px per ridge, kept): the
    report names both grids, and the cameras, depth maps and focals are the photos' whatever grid made them."""
    from fingersplat3d.splat.config import preset

    capture = Capture(tuple(View(v.name, v.image) for v in uwa1280.views), uwa1280.metadata)
    result = fuse(capture, FuseConfig(splat=preset("fast", iterations=20), ridge_px=8.0))
    working = result.report["working_resolution"]
    assert working["factor"] < 0.6 and working["splat"]["factor"] == 1.0
    assert working["splat"]["sizes"][0] == [1280, 1024]
    assert result.registered
    for camera, depth, splat_depth in zip(result.cameras, result.depths, result.splat_depths):
        assert camera.size == (1280, 1024) and depth.shape == splat_depth.shape == (1024, 1280)
    assert result.report["alignment"]["focals_px"][0] == pytest.approx(result.cameras[0].K[0, 0], rel=1e-6)
    assert result.report["splat"]["budget"] > 0


def test_the_splat_grid_is_carried_onto_from_the_geometrys_either_way():
    from fingersplat3d.pipeline import _on_splat_grid
    from fingersplat3d.working_scale import WorkingScale

    rng = np.random.default_rng(0)
    mask = np.zeros((640, 800), bool)
    mask[160:480, 120:680] = True
    photos = Capture(tuple(View(name, rng.random((640, 800)).astype(np.float32), mask) for name in ("a", "b")), {})
    scale = WorkingScale(0.4, 20.0, 8.0, (20.0, 20.0), True)
    pose = look_at([0, 0, -5], [0, 0, 0], [0, -1, 0])
    cameras = [Camera.from_focal(150.0, 320, 256, pose)] * 2
    working = Capture(tuple(View(v.name, resized_image(v.image, (320, 256)), resized_mask(v.mask, (320, 256))) for v in photos.views), {})
    depth = np.where(working.views[0].mask, 3.0, np.nan).astype(np.float32)
    report = {"registration": {"pointmaps_redrawn_at_px": 150.0}}
    capture, fit, moved, (depths,), grow = _on_splat_grid(photos, working, scale, 12.0, cameras, ([depth, depth],), report)
    assert fit.factor == pytest.approx(0.6) and grow == [1.5, 1.5]  # 12 px per ridge of 20: 480x384
    assert [(v.width, v.height) for v in capture.views] == [(480, 384)] * 2 and all(v.mask.shape == (384, 480) for v in capture.views)
    assert moved[0].size == (480, 384) and moved[0].K[0, 0] == pytest.approx(225.0)
    assert depths[0].shape == (384, 480) and np.nanmax(np.abs(depths[0] - 3.0)) < 1e-5
    assert report["registration"]["pointmaps_redrawn_at_px"] == pytest.approx(225.0)
    capture, fit, moved, _, grow = _on_splat_grid(photos, working, scale, None, cameras, ([depth, depth],), {})
    assert fit.factor == 1.0 and capture.views[0] is photos.views[0] and moved[0].size == (800, 640) and grow == [2.5, 2.5]
    same = _on_splat_grid(photos, working, scale, 8.0, cameras, ([depth, depth],), {})  # one grid: as it is
    assert same[0] is working and same[1] is scale and same[4] == [1.0, 1.0]


def test_a_rig_calibration_works_every_capture_at_the_first_readable_ones_resolution(uwa1280, tmp_path):
    """``fs3d rig calibrate`` pools focal lengths in working pixels, so its captures share one working resolution:
    the first capture that can be read sets it (one with a missing frame is passed over), whatever the others' own."""
    from fingersplat3d.cli.rig import shared_factor
    from fingersplat3d.io.jobs import CaptureJob, load_job

    jobs = {}
    for name, size in (("fine", 1.0), ("coarse", 0.8)):  # ~18 and ~14 px per ridge
        folder = tmp_path / name
        folder.mkdir()
        files = []
        for view in uwa1280.views:
            image = view.image if size == 1.0 else resized_image(view.image, (round(view.width * size), round(view.height * size)))
            files.append(str(folder / f"{view.name}.png"))
            cv2.imwrite(files[-1], np.round(255 * np.clip(image, 0, 1)).astype(np.uint8))
        jobs[name] = CaptureJob(name, tuple(files))
    own = {name: working_views(load_job(job).views, RIDGE_PX)[2].factor for name, job in jobs.items()}
    assert own["fine"] < 0.8 and own["coarse"] == 1.0  # each alone at its own: scaled, and kept
    broken = CaptureJob("broken", (), problem="frame 1 is missing")
    assert shared_factor([broken, jobs["fine"], jobs["coarse"]], RIDGE_PX) == own["fine"]
    assert shared_factor([jobs["coarse"], jobs["fine"]], RIDGE_PX) == own["coarse"]
    assert shared_factor([broken], RIDGE_PX) == 1.0
