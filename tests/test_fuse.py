"""fs3d fuse geometry: cameras and depth recovered from uncalibrated synthetic photos, outputs per contract."""
import itertools
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from fingersplat3d.alignment_status import TWO_VIEWS_WARNING
from fingersplat3d.cli import main
from fingersplat3d.errors import InputError
from fingersplat3d.eval import depth_errors, relative_rotation_errors
from fingersplat3d.eval.poses import rotation_angle_deg
from fingersplat3d.io import read_cameras, read_depth
from fingersplat3d.io.images import read_image
from fingersplat3d.pipeline import FuseConfig, fuse, write_reconstruction
from fingersplat3d.scene import Capture, View
from fingersplat3d.synth import SynthConfig, synthesize

ROOT = Path(__file__).resolve().parents[1]
GEOMETRY = FuseConfig(splat=None)  # these tests are about the geometry; the splat stage has its own


@pytest.fixture(scope="module")
def uwa():
    return synthesize(1, SynthConfig(size=(640, 512))).capture


@pytest.fixture(scope="module")
def reconstruction(uwa):
    return fuse(uwa, GEOMETRY)


def test_fuse_recovers_cameras_and_depth(uwa, reconstruction):
    report = reconstruction.report
    assert report["alignment"]["ok"] and all(report["alignment"]["aligned"].values())
    support = report["alignment"]["backed_by_two_views"]  # the front view is seen by both side views
    assert support["center"] > 0.9 and all(0.3 < share <= 1.0 for share in support.values())
    tips = report["registration"]["tip"]  # synthetic fingers point left, cut by the right border
    assert all(tip["side"] == "left" and "border cuts the other" in tip["why"] for tip in tips.values())
    assert report["registration"]["photometric"] == {}  # the dense photometric refinement is opt-in (--photometric)
    # The synthetic camera's focal is 3.33x the long side, the prior guesses 3x: the pointmaps are drawn again through
    # the fitted focal (photo pixels: this capture is fused at its own resolution or near it).
    redrawn = report["registration"]["pointmaps_redrawn_at_px"]
    assert redrawn == pytest.approx(report["alignment"]["focals_px"][0], rel=0.05)
    errors = relative_rotation_errors([c.world_to_cam for c in reconstruction.cameras],
                                      [v.camera.world_to_cam for v in uwa.views])
    # The 45-degree pairs: measured 3-7 degrees (see the README's table); a broken alignment is tens.
    assert errors[0] < 12 and errors[2] < 12
    for view, depth in zip(uwa.views, reconstruction.depths):
        assert depth.shape == view.depth.shape
        error = depth_errors(depth, view.depth, view.mask)
        assert error.coverage > 0.95
        # A flat finger is ~1.2 mm off after scale and shift; the fuse measured 0.07-0.45 mm.
        assert error.mae < 0.6


def test_reconstruction_folder_contract(reconstruction, tmp_path):
    import open3d as o3d
    import pymeshlab

    out = write_reconstruction(reconstruction, tmp_path / "rec")
    cloud = o3d.io.read_point_cloud(str(out / "fused.ply"))
    assert len(cloud.points) > 1000 and cloud.has_colors() and cloud.has_normals()
    meshset = pymeshlab.MeshSet()
    meshset.load_new_mesh(str(out / "fused.ply"))
    assert meshset.current_mesh().vertex_number() == len(cloud.points)
    cameras = read_cameras(out / "cameras.json")
    assert cameras.units == "arbitrary" and cameras.names == reconstruction.capture.names
    for view in reconstruction.capture.views:
        depth = read_depth(out / "depth" / f"{view.name}.npy")
        assert depth.shape == (view.height, view.width) and depth.dtype == np.float32
        assert np.isnan(depth[~view.mask]).all() and np.isfinite(depth[view.mask]).mean() > 0.95
        assert (out / "depth" / f"{view.name}.png").is_file() and (out / "depth" / f"{view.name}_color.png").is_file()
    report = json.loads((out / "report.json").read_text())
    for stage in ("masks", "pointmaps", "registration", "icp", "fusion"):
        assert report["stages"][stage]["seconds"] >= 0 and report["stages"][stage]["peak_rss_mb"] > 0
    assert report["units"] == "arbitrary" and report["alignment"]["residual_px"] < 3
    overview = read_image(out / "overview.png")  # what the fuse found, at a glance: each view, the rig
    assert overview.ndim == 3 and overview.shape[0] >= 360 and overview.shape[1] > 3 * 360


def test_metric_hints_make_millimetres(uwa, reconstruction):
    """Either metric hint scales the fused finger to millimetres: its width comes out a finger's. The scale's own step
    on the module's reconstruction (two more fuses would redo the same registration); ``--px-per-mm`` end to end, units
    and all, is in test_cli_fuse_on_the_shipped_sample."""
    from fingersplat3d.pipeline import _metric_scale

    truth_px_per_mm = uwa.views[0].camera.K[0, 0] / np.nanmedian(uwa.views[0].depth)
    rec = reconstruction
    assert rec.units == "arbitrary" and rec.scale_mm_per_unit is None
    points = np.asarray(rec.cloud.points)
    for config in (FuseConfig(px_per_mm=truth_px_per_mm), FuseConfig(finger_width_mm=16.0)):
        report = {}
        mm_per_unit = _metric_scale(config, rec.cameras, rec.depths, rec.cloud, report)
        assert mm_per_unit > 0
        assert 8 < np.sort(np.ptp(points * mm_per_unit, axis=0))[1] < 30  # the finger's width in millimetres
    assert report["measured_width_units"] * mm_per_unit == pytest.approx(16.0)
    assert _metric_scale(GEOMETRY, rec.cameras, rec.depths, rec.cloud, {}) is None


def test_cli_fuse_on_the_shipped_sample(tmp_path, capsys):
    out = tmp_path / "rec"
    assert main(["fuse", str(ROOT / "data_samples" / "uwa_seed0"), "-o", str(out), "--mesh", "--splat-preset", "fast",
                 "--splat-iterations", "4"]) == 0
    assert "wrote" in capsys.readouterr().out
    import pymeshlab

    meshset = pymeshlab.MeshSet()
    meshset.load_new_mesh(str(out / "mesh.ply"))
    assert meshset.current_mesh().face_number() > 1000
    # gaussians.ply: the standard 3DGS layout, opens in MeshLab, one Gaussian per vertex.
    meshset.load_new_mesh(str(out / "gaussians.ply"))
    report = json.loads((out / "report.json").read_text())
    assert meshset.current_mesh().vertex_number() == report["splat"]["gaussians"] > 1000
    assert report["stages"]["splat"]["seconds"] > 0 and len(report["splat"]["psnr_in_mask_db"]) == 3
    # three views at -45/0/+45 leave little unseen skin next to what they see (a left-out view: tests/test_unseen_skin.py)
    assert 0 <= report["splat"]["unseen_skin_gaussians"] < 0.1 * report["splat"]["gaussians"]
    # one name per setting: the flag, the config field and report.json say the same
    assert report["splat"]["preset"] == "fast" and report["splat"]["differs_from_preset"] == {"iterations": 4}
    # the shading exponent, estimated on the skin two views see, is what gaussians.ply carries
    shading = report["splat"]["shading"]
    assert shading["points"] > 1000 and 0.0 <= shading["facing_exponent"] < 1.0
    assert sorted(shading["exposure_estimate"]) == ["center", "left", "right"]
    from fingersplat3d.io.gaussians_ply import read_gaussians_ply
    assert read_gaussians_ply(out / "gaussians.ply").facing_exponent == pytest.approx(shading["facing_exponent"], abs=1e-4)
    # Novel views on the arc from the leftmost to the rightmost camera.
    assert main(["render", str(out), "--count", "3", "--scale", "0.25"]) == 0
    renders = sorted(p.name for p in (out / "renders").glob("arc_*.png"))
    assert renders == ["arc_00.png", "arc_00_alpha.png", "arc_01.png", "arc_01_alpha.png", "arc_02.png", "arc_02_alpha.png"]
    assert (out / "renders" / "contact_sheet.png").is_file() and (out / "renders" / "depth" / "arc_01.npy").is_file()
    assert main(["render", str(out)]) == 2  # renders/ exists: refuses without --overwrite
    # The same images given as a list of files, with --no-shading: the plain SH degree 0 model, said so in
    # report.json and gaussians.ply.
    files = sorted(str(p) for p in (ROOT / "data_samples" / "uwa_seed0" / "images").glob("*.png"))
    from_files = tmp_path / "from_files"
    assert main(["fuse", *files, "-o", str(from_files), "--icp", "--px-per-mm", "17.8", "--splat-preset", "fast",
                 "--splat-iterations", "2", "--no-shading", "--no-exposures"]) == 0
    files_report = json.loads((from_files / "report.json").read_text())
    plain_report = files_report["splat"]
    assert plain_report["differs_from_preset"] == {"iterations": 2, "facing_shading": False, "match_exposures": False}
    assert not plain_report["shading"]["exposures_matched"] and shading["exposures_matched"]
    assert (plain_report["shading"]["facing_exponent"] == 0.0
            and read_gaussians_ply(from_files / "gaussians.ply").facing_exponent == 0.0)
    # A metric reconstruction says mm in cameras.json (the factor that made it so is in report.json).
    cameras = json.loads((from_files / "cameras.json").read_text())
    assert cameras["units"] == "mm" and cameras["scale_mm_per_unit"] is None
    assert files_report["scale_mm_per_unit"] > 0


def test_cli_fuse_refuses_bad_input(tmp_path, capsys):
    assert main(["fuse", str(tmp_path / "missing"), "-o", str(tmp_path / "o")]) == 2
    assert "missing" in capsys.readouterr().err
    assert main(["fuse", str(ROOT / "data_samples" / "uwa_seed0"), "-o", str(tmp_path / "o"), "--px-per-mm", "-3"]) == 2
    assert "--px-per-mm" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# Numerical extremes: results stay finite, or fail with a clear message.

def _finite_result(result):
    points = np.asarray(result.cloud.points)
    assert len(points) > 0 and np.isfinite(points).all()
    assert all(np.isfinite(c.K).all() and np.isfinite(c.world_to_cam).all() for c in result.cameras)
    for depth, view in zip(result.depths, result.capture.views):
        assert np.isfinite(depth[view.mask]).any() and not np.isinf(depth).any()


def test_identical_views_are_monocular_mode(uwa):
    view = uwa["center"]
    twins = Capture((View("a", view.image), View("b", view.image)))
    result = fuse(twins, GEOMETRY)
    _finite_result(result)
    assert result.report["alignment"]["mode"] == "monocular"
    assert result.report["pairs"][0]["reason"].startswith("identical images")
    assert depth_errors(result.depths[0], view.depth, view.mask).mae < 0.6


def test_a_photo_given_twice_re_encoded_is_monocular_mode_and_a_moved_one_is_not(uwa):
    """A copy saved again as a JPEG, or with a little noise, is still one picture (no parallax to register); the same
    photo moved by one pixel is another shot."""
    from fingersplat3d.pipeline import _same_picture

    image = uwa["center"].image
    eight = np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)
    again = cv2.imdecode(cv2.imencode(".jpg", eight, [cv2.IMWRITE_JPEG_QUALITY, 70])[1], cv2.IMREAD_UNCHANGED) / 255.0
    noisy = image + np.random.default_rng(0).normal(0, 1.5 / 255, image.shape)
    assert _same_picture(image, again.astype(np.float32)) and _same_picture(image, noisy)
    assert not _same_picture(image, np.roll(image, 1, axis=1)) and not _same_picture(image, image[:-1])
    assert not _same_picture(image, uwa["left"].image)
    for size in ((480, 384), (960, 768), (213, 170)):  # a copy at another size, to the pixel: the same picture
        resized = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        assert _same_picture(image, resized) and _same_picture(resized, image)
    assert not _same_picture(image, cv2.resize(uwa["left"].image, (480, 384), interpolation=cv2.INTER_AREA))
    assert not _same_picture(image, cv2.resize(image, (480, 300)))  # stretched: another picture
    twins = Capture((View("a", image), View("b", again.astype(np.float32))))
    result = fuse(twins, GEOMETRY)
    assert result.report["alignment"]["mode"] == "monocular"
    assert result.report["pairs"][0]["reason"].startswith("identical images")


def test_a_photo_given_twice_beside_others_is_fused_once(uwa):
    """A copy of one photo beside the other photos adds no view of the finger: the capture is fused with each picture
    once (the same cameras as without the copy), and the copy is named in a warning and in the report."""
    views = [uwa[name].with_(camera=None, depth=None) for name in ("left", "center", "right")]
    copy = views[1].with_(name="center-again", image=views[1].image + np.float32(0.5 / 255))
    once = fuse(Capture(tuple(views), uwa.metadata), GEOMETRY)
    twice = fuse(Capture((views[0], views[1], copy, views[2]), uwa.metadata), GEOMETRY)
    assert twice.capture.names == once.capture.names == ["left", "center", "right"]
    assert twice.report["same_picture_as"] == {"center-again": "center"}
    assert any("'center-again' is the same picture as view 'center'" in w for w in twice.report["warnings"])
    for a, b in zip(once.cameras, twice.cameras):
        np.testing.assert_allclose(a.world_to_cam, b.world_to_cam, atol=1e-9)


def test_the_same_photo_moved_registers_but_backs_no_depth(uwa):
    """The same photo moved by a few pixels: another picture, registered at no turn, yet seen from one place: none of
    its surface is backed by a second view, and the run says so."""
    image = uwa["center"].image
    moved = Capture((View("a", image), View("b", np.roll(image, 3, axis=1))))
    result = fuse(moved, GEOMETRY)
    assert result.report["alignment"]["mode"] != "monocular"
    assert all(share == 0.0 for share in result.report["alignment"]["backed_by_two_views"].values())
    assert any("from 5° or more apart" in warning for warning in result.report["warnings"])


def test_two_views_90_degrees_apart_register_through_the_unwrapped_texture(uwa):
    # Keypoint matchers find nothing right here; the unwrapped ridge texture still overlaps.
    views = (uwa["left"].with_(camera=None, depth=None), uwa["right"].with_(camera=None, depth=None))
    result = fuse(Capture(views), GEOMETRY)
    _finite_result(result)
    assert result.registered and result.report["pairs"][0]["ok"]
    errors = relative_rotation_errors([c.world_to_cam for c in result.cameras], [uwa["left"].camera.world_to_cam,
                                                                                 uwa["right"].camera.world_to_cam])
    assert errors[0] < 8  # two views keep the bas-relief ambiguity (measured 3.3 degrees)
    # ... and cannot fix the focal: the warning says what would
    assert any("--focal-px" in warning for warning in result.report["warnings"])


def test_views_of_different_fingers_are_not_registered(capsys):
    finger_a = synthesize(1, SynthConfig(size=(640, 512))).capture
    finger_b = synthesize(4, SynthConfig(size=(640, 512))).capture
    views = (finger_a["center"].with_(camera=None, depth=None), finger_b["left"].with_(name="other", camera=None, depth=None))
    result = fuse(Capture(views), GEOMETRY)
    _finite_result(result)
    assert not result.registered and result.report["alignment"]["not_registered"] == ["other"]
    assert result.report["alignment"]["backed_by_two_views"]["other"] is None
    assert "could not be registered" in capsys.readouterr().err


def test_single_image_and_tiny_images():
    tiny = synthesize(2, SynthConfig(size=(48, 40)))
    result = fuse(Capture(tiny.capture.views[:1]), GEOMETRY)
    _finite_result(result)
    result = fuse(tiny.capture, GEOMETRY)  # too small to match ridges: monocular fallback, still finite
    _finite_result(result)


def test_few_pixel_mask_is_a_clear_error(uwa):
    view = uwa["center"]
    mask = np.zeros_like(view.mask)
    mask[100:103, 100:103] = True
    with pytest.raises(InputError, match="center"):
        fuse(Capture((view.with_(mask=mask), uwa["left"])), GEOMETRY)


def test_extreme_focal_guesses_stay_finite(uwa):
    from fingersplat3d.pointmaps.prior import PriorBackend

    for factor in (1e-2, 1e3):
        pointmaps = PriorBackend(focal_factor=factor).predict_views(uwa.views)
        assert all(np.isfinite(pm.points[pm.valid]).all() for pm in pointmaps)


@pytest.mark.slow
@pytest.mark.parametrize("odd_one", ["mirrored", "other finger"])
def test_real_views_that_do_not_belong_are_not_registered(odd_one, tmp_path):
    """A left-right mirrored side view, or another finger's side view, beside two real views of one finger:
    exit 3 naming that view, never a confident model (real dev captures; skipped where they are absent)."""
    import cv2

    data = Path(__file__).resolve().parents[2] / "shared" / "data" / "uwa-real-dev"
    if not data.is_dir():
        pytest.skip("the real dev captures are not here")
    odd = tmp_path / "odd.png"
    if odd_one == "mirrored":
        cv2.imwrite(str(odd), cv2.imread(str(data / "2_2_8_1_1.jpg"), cv2.IMREAD_UNCHANGED)[:, ::-1])
    else:
        cv2.imwrite(str(odd), cv2.imread(str(data / "1_1_2_1_1.jpg"), cv2.IMREAD_UNCHANGED))
    code = main(["fuse", str(data / "2_2_8_1_0.jpg"), str(odd), str(data / "2_2_8_1_2.jpg"), "-o", str(tmp_path / "out"),
                 "--no-splat"])
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert code == 3 and report["alignment"]["not_registered"] == ["odd"]


@pytest.mark.slow  # 50 s; the default suite refuses another finger on synthetic views
def test_a_front_view_of_another_finger_is_refused_where_its_chart_vote_passed(tmp_path):
    """The front view of finger 1 beside the side views of finger 2: the chart vote takes the front-side pair (32
    patches at a 45-degree turn, 2.3 times the runner-up) and its first guess finds 64 matches on one epipolar
    geometry. Through the model the views agree at 5 % of their common points (one finger: 18 % or more), so the
    guided round drops the pair: exit 3 naming both of finger 2's views, none placed by the other finger's."""
    data = Path(__file__).resolve().parents[2] / "shared" / "data" / "uwa-real-dev"
    if not data.is_dir():
        pytest.skip("the real dev captures are not here")
    code = main(["fuse", str(data / "1_1_2_1_0.jpg"), str(data / "2_2_7_1_1.jpg"), str(data / "2_2_7_1_2.jpg"), "-o",
                 str(tmp_path / "out"), "--no-splat"])
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert code == 3 and report["alignment"]["not_registered"] == ["2_2_7_1_1", "2_2_7_1_2"], report["pairs"]
    front_side = report["pairs"][0]
    assert not front_side["ok"] and "different fingers" in front_side["reason"], front_side
    assert front_side["agreement"] and max(front_side["agreement"]) < 0.125  # measured 0.05


def _tilted_crop(view: View, degrees: float, columns: slice, margin: int = 0) -> View:
    """The view's photo turned in its plane and cut at both ends of the finger, with no camera, mask or depth;
    ``margin`` black columns either side cut it inside the frame instead of at its edges."""
    import cv2

    rows, cols = view.image.shape[:2]
    turn = cv2.getRotationMatrix2D((cols / 2, rows / 2), degrees, 1.0)
    return View(view.name, np.pad(cv2.warpAffine(view.image, turn, (cols, rows))[:, columns], ((0, 0), (margin, margin))))


@pytest.mark.slow
@pytest.mark.parametrize("seed, columns, margin", [(3, slice(170, 600), 0), (5, slice(170, 600), 0), (3, slice(230, 470), 0),
                                                   (5, slice(230, 470), 0), (3, slice(230, 470), 48), (5, slice(230, 470), 48)])
def test_crops_without_a_fingertip_register(seed, columns, margin):
    """Photos turned in their plane and cut across the finger at both ends (no tip outline): every view
    registers, all agree on the tip end, and the 45-degree turns stay as right as with the tip (~1 degree).
    The 240-px crops are shorter along the finger than across it (210-365 px): before the axis ran between the
    frame's cuts, their longest direction was taken for the finger's and no view registered. Cut inside the frame
    (a black margin), no outline tells their ends from their sides: the capture's lengths do (capture_axes; before,
    no view registered; measured 0.1-1.0 degrees)."""
    truth = synthesize(seed, SynthConfig(size=(640, 512))).capture
    crops = Capture(tuple(_tilted_crop(view, 8.0, columns, margin) for view in truth.views), {})
    result = fuse(crops, GEOMETRY)
    assert result.report["alignment"]["ok"]
    tips = result.report["registration"]["tip"]
    assert len({tip["side"] for tip in tips.values()}) == 1 and all("neither end" in tip["why"] for tip in tips.values())
    # The turn in the image plane changes the axis of each relative rotation, not its angle.
    angles = [[rotation_angle_deg(a[:3, :3], b[:3, :3]) for a, b in itertools.combinations(poses, 2)]
              for poses in ([c.world_to_cam for c in result.cameras], [v.camera.world_to_cam for v in truth.views])]
    assert np.max(np.abs(np.subtract(*angles))) < 3.0  # measured 0.05-1.0; through mirrored charts, tens of degrees


def _turn_errors_deg(poses, rolls):
    """Each pair's rotation angle against the difference of its rolls, degrees (renders rolled about one axis)."""
    return [abs(rotation_angle_deg(poses[a][:3, :3], poses[b][:3, :3]) - abs(roll_b - roll_a))
            for (a, b), (roll_a, roll_b) in zip(itertools.combinations(range(len(rolls)), 2),
                                                itertools.combinations(rolls, 2))]


def test_two_views_of_a_flat_finger_turn_at_least_as_far_as_their_silhouettes_allow(impose_dev):
    """Another group's flat finger (its silhouettes an ellipse 0.39 as deep as wide) at rolls 0 and 47, two views and
    the focal fitted: the pointmap prior's rounder section had made the turn 29.8 degrees; the narrower view's width
    holds it at or above its bound from the pad-facing view (acos of the widths' ratio, 43 degrees; measured 43.2).
    It is warned as held there: the photos do not fix it (before, its curvature had said so)."""
    from fingersplat3d.io.datasets import load_any

    rolls = (0, 47)
    result = fuse(load_any([impose_dev / f"sample2_{roll}.png" for roll in rolls])[0], GEOMETRY)
    assert result.report["alignment"]["ok"]
    turn = rotation_angle_deg(result.cameras[0].world_to_cam[:3, :3], result.cameras[1].world_to_cam[:3, :3])
    bound = result.report["alignment"]["turn_at_least_deg"]
    assert 40.0 < turn < 49.0 and turn > max(bound.values()) - 0.5
    assert result.report["alignment"]["turn_held_at_bound"] == ["p0-p47"]  # and said so: the bound, not the photos
    assert any("held at the least turn" in warning for warning in result.report["warnings"])


@pytest.mark.slow
@pytest.mark.parametrize("rows", [slice(None), slice(330, 560)])
def test_another_groups_crops_register_whole_or_cut_short(impose_dev, rows, tmp_path):
    """Another group's renders (IMPOSE, rolls -45 / 0 / 47 about the finger's axis, cut at both ends inside the frame),
    as published and cut again to 230 rows, shorter along the finger than across it (290-390 px): every view
    registers and each pair turns by the difference of its rolls. Cut short, only the capture tells the finger's ends
    from its sides (capture_axes; before, one view of three registered). Measured: 0.2 / 0.1 / 0.2 and 0.1 / 0.0 / 0.1
    degrees off."""
    import cv2

    rolls = (-45, 0, 47)
    for roll in rolls:
        image = cv2.imread(str(impose_dev / f"sample2_{roll}.png"), cv2.IMREAD_GRAYSCALE)
        cut = np.zeros_like(image)
        cut[rows] = image[rows]
        cv2.imwrite(str(tmp_path / f"sample2_{roll}.png"), cut)
    out = tmp_path / "out"
    assert main(["fuse", *(str(tmp_path / f"sample2_{roll}.png") for roll in rolls), "-o", str(out), "--no-splat"]) == 0
    from fingersplat3d.io.cameras import read_cameras

    poses = [camera.world_to_cam for camera in read_cameras(out / "cameras.json").cameras.values()]
    assert max(_turn_errors_deg(poses, rolls)) < 1.0


@pytest.mark.slow
@pytest.mark.parametrize("rolls", [(-18, 0, 47), (-18, 0, 48)])
def test_a_close_pair_and_a_far_view_of_a_flat_finger_register(impose_dev, rolls):
    """Another group's flat finger at rolls -18 / 0 / 47: the close pair's ~2,000 first matches and the far view's ~80,
    through cylinder charts that compress the turn across a flat pad, had put the first alignment 10-20 degrees off and
    left the far view unregistered. Grown through the charts corrected by their own matches
    (align/correspond/chart_growth.py), the far pairs start from ~600-800 matches: measured 0.24 / 0.22 / 0.02 degrees.
    At 48 degrees the far pairs' first matches (60 and 80) grow only through a lower correction than the cubic (the
    cubic alone lost the view): measured 0.24 / 0.21 / 0.02."""
    from fingersplat3d.io.datasets import load_any

    result = fuse(load_any([impose_dev / f"sample2_{roll}.png" for roll in rolls])[0], GEOMETRY)
    assert result.report["alignment"]["ok"]
    poses = [camera.world_to_cam for camera in result.cameras]
    assert max(_turn_errors_deg(poses, rolls)) < 1.0


@pytest.mark.slow
def test_a_view_beside_two_views_from_one_place_registers_as_two_views_would(impose_dev):
    """Another group's renders at rolls -13 / 47 / 48: the last two see the finger from one place (1 degree apart), so
    for the bas-relief the capture is two views, and the silhouette contours, which three distinct views need, had
    pulled the turn instead of the surface: measured 3.92 degrees off with them, 0.16 without (align/register.py,
    distinct_viewpoints)."""
    from fingersplat3d.io.datasets import load_any

    rolls = (-13, 47, 48)
    result = fuse(load_any([impose_dev / f"sample2_{roll}.png" for roll in rolls])[0], GEOMETRY)
    assert result.report["alignment"]["ok"]
    assert max(_turn_errors_deg([camera.world_to_cam for camera in result.cameras], rolls)) < 2.0


@pytest.mark.slow
def test_photos_on_a_bright_background_are_fused(uwa):
    """Phone-style photos: the finger on a bright desk, no dark background (segment/any_background.py). Measured
    with seed 1: masks IoU 0.99, pair rotations 0.3-0.7 degrees off, depth 0.07-0.13 mm (dark: 0.07-0.16)."""
    from fingersplat3d.experiments.backgrounds import bright_desk, on_background
    from fingersplat3d.segment.masks import mask_iou

    rng = np.random.default_rng(0)
    views = [View(view.name, on_background(view.image, view.mask, bright_desk(view.image.shape, rng))) for view in uwa.views]
    result = fuse(Capture(tuple(views), uwa.metadata), GEOMETRY)
    assert result.registered
    assert all(mask_iou(found.mask, view.mask) > 0.95 for found, view in zip(result.capture.views, uwa.views))
    errors = relative_rotation_errors([c.world_to_cam for c in result.cameras], [v.camera.world_to_cam for v in uwa.views])
    assert max(errors) < 3
    assert all(depth_errors(depth, view.depth, view.mask).mae < 0.6 for depth, view in zip(result.depths, uwa.views))


@pytest.mark.slow
def test_phone_like_photos_turned_in_their_plane_are_fused(uwa, tmp_path):
    """Phone-like JPEG files: each view turned in its own plane (up to 35 degrees), on a streaked bright desk,
    quality 85, through the CLI. An in-plane turn is a camera roll: it changes each relative rotation but not the
    angle between two cameras' optical axes, which must come out within 2 degrees of the truth (measured on seeds
    0-2 at 1280x1024: 0.09-0.97)."""
    import cv2

    rng = np.random.default_rng(7)
    paths = []
    for view in uwa.views:
        height, width = view.mask.shape
        rows, cols = np.mgrid[0:height, 0:width]
        desk = 0.75 + 0.06 * np.sin(cols / 37.0 + 3 * np.sin(rows / 90.0)) + 0.02 * rng.normal(size=(height, width))
        soft = cv2.GaussianBlur(view.mask.astype(np.float32), (0, 0), 1.5)
        photo = soft * view.image + (1 - soft) * desk
        turn = cv2.getRotationMatrix2D((width / 2, height / 2), rng.uniform(-35, 35), 1.0)
        photo = cv2.warpAffine(photo.astype(np.float32), turn, (width, height), borderMode=cv2.BORDER_REFLECT)
        paths.append(tmp_path / f"{view.name}.jpg")
        cv2.imwrite(str(paths[-1]), np.clip(photo * 255, 0, 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 85])
    assert main(["fuse", *map(str, paths), "-o", str(tmp_path / "out"), "--no-splat"]) == 0
    found = read_cameras(tmp_path / "out" / "cameras.json")
    axes = lambda poses: [pose[2, :3] for pose in poses]  # noqa: E731  optical axes in the world
    truth, solved = axes([v.camera.world_to_cam for v in uwa.views]), axes([found.cameras[v.name].world_to_cam for v in uwa.views])
    for a, b in itertools.combinations(range(3), 2):
        angle = lambda x, y: np.degrees(np.arccos(np.clip(x @ y, -1, 1)))  # noqa: E731
        assert abs(angle(solved[a], solved[b]) - angle(truth[a], truth[b])) < 2.0


def test_a_known_focal_is_kept_and_fixes_the_turn_of_two_views(uwa):
    """Two views cannot fix the focal (their optical axes meet at the finger), and their turn follows it: given the
    true focal, the turn comes out right where the fitted focal left it several degrees off (measured 6.4 -> 0.4)."""
    two = Capture(tuple(v.with_(camera=None, depth=None) for v in uwa.views[:2]), uwa.metadata)
    focal = float(uwa.views[0].camera.K[0, 0])
    result = fuse(two, FuseConfig(splat=None, focal_px=focal))
    assert result.registered
    assert all(c.K[0, 0] == pytest.approx(focal) for c in result.cameras)  # in the photos' pixels, as given
    error = relative_rotation_errors([c.world_to_cam for c in result.cameras], [v.camera.world_to_cam for v in uwa.views[:2]])
    assert max(error) < 1.5
    assert not any("--focal-px" in warning for warning in result.report["warnings"])
    # ... and the run still says what two views cannot check: the section their turn rests on
    assert any(warning.startswith(TWO_VIEWS_WARNING) for warning in result.report["warnings"])


def test_two_views_with_the_focal_held_take_the_silhouette_contours():
    """With the focal held, two views' turn no longer slides with it, so the silhouette contours join their alignment
    and shape the skin only one of them sees (align/register.py, CONTOUR_MIN_VIEWS_FOCAL_HELD): seed 2's left and
    centre views, whole-view depth error (mean of the two, worst) 0.111 (0.115) mm without them, 0.036 (0.043)
    with them; the turn 0.25 degrees off without them, 0.30 with them (six kinds of pairs, 3-5 seeds each:
    docs/measurements.md)."""
    capture = synthesize(2, SynthConfig(size=(640, 512))).capture
    views = [capture["left"], capture["center"]]
    two = Capture(tuple(v.with_(camera=None, depth=None) for v in views), capture.metadata)
    result = fuse(two, FuseConfig(splat=None, focal_px=float(views[0].camera.K[0, 0])))
    assert result.registered
    assert max(relative_rotation_errors([c.world_to_cam for c in result.cameras],
                                        [v.camera.world_to_cam for v in views])) < 1.0
    assert all(depth_errors(depth, view.depth, view.mask).mae < 0.075 for depth, view in zip(result.depths, views))


@pytest.mark.parametrize("factor", [1e-3, 1e4])
def test_extreme_known_focals_stay_finite(uwa, factor):
    two = Capture(tuple(v.with_(camera=None, depth=None) for v in uwa.views[:2]), uwa.metadata)
    _finite_result(fuse(two, FuseConfig(splat=None, focal_px=factor * float(uwa.views[0].camera.K[0, 0]))))


def test_a_known_focal_is_refused_where_it_cannot_be_used(uwa, tmp_path, capsys):
    from fingersplat3d.align.solve.rig import Rig
    from fingersplat3d.pointmaps.prior import PriorBackend

    rig = Rig(tuple(uwa.names), tuple((v.width, v.height) for v in uwa.views), np.stack([np.eye(3)] * len(uwa)),
              np.zeros((len(uwa), 3)), 900.0)
    with pytest.raises(InputError, match="holds its own focal"):
        fuse(uwa, FuseConfig(splat=None, focal_px=900.0), rig=rig)
    with pytest.raises(InputError, match="focal_px"):
        PriorBackend(focal_px=float("nan"))
    sample = str(ROOT / "data_samples" / "uwa_seed0")
    assert main(["fuse", sample, "-o", str(tmp_path / "o"), "--focal-px", "0"]) == 2
    assert "--focal-px" in capsys.readouterr().err
    assert main(["fuse", sample, "-o", str(tmp_path / "o"), "--focal-px", "900", "--backend", "dust3r",
                 "--checkpoint", str(tmp_path / "none.pth")]) == 2
    assert "--focal-px" in capsys.readouterr().err
    assert main(["batch", sample, "-o", str(tmp_path / "o"), "--rig", str(tmp_path / "rig.json"), "--focal-px", "900"]) == 2
    assert "--focal-px" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


STEADY, LOOSE = np.full((3, 3), 0.01), np.array([[np.nan, 0.2, 0.9], [0.2, np.nan, 0.4], [0.9, 0.4, np.nan]])


@pytest.mark.parametrize("bases, probe, moves, warned", [
    (("taper", "other views", "other views"), {"held": True}, None, True),  # every view cut at both ends, focal fitted
    (("taper", "other views", "other views"), {"held": True}, LOOSE, True),  # one pair follows the focal
    (("taper", "other views", "other views"), {"held": True}, STEADY, False),  # no turn follows it (orthographic)
    (("outline", "other views", "other views"), {"held": True}, LOOSE, False),  # one view's outline closes at the tip
    (("taper", "taper", "taper"), None, None, True),  # the focal given (no probe): real crops still 2-7° off
    (("outline", "taper", "taper"), None, None, False),  # ... where one view shows the tip, not
    (("taper", "taper", "taper"), "rig", None, False),  # a rig holds the poses (no curvature reported)
])
def test_a_capture_without_a_visible_tip_is_warned(bases, probe, moves, warned):
    from types import SimpleNamespace

    from fingersplat3d.alignment_status import NO_TIP_SENSITIVITY_DEG, NO_TIP_WARNING, warn_without_tip
    from fingersplat3d.segment.silhouette import TIP_BASES

    assert np.nanmax(STEADY) < NO_TIP_SENSITIVITY_DEG < np.nanmax(LOOSE)
    names = ["left", "center", "right"]
    report = {"views": names, "warnings": [],
              "registration": {"tip": {n: {"side": "left", "why": TIP_BASES[b]} for n, b in zip(names, bases)}}}
    curvature = None if probe == "rig" else np.full((3, 3), 0.05)
    alignment = SimpleNamespace(aligned=[True, True, True], focal_probe=None if probe == "rig" else probe,
                                turn_sensitivity_deg=moves, turn_uncertainty_deg=curvature)
    warn_without_tip(alignment, report)
    said = [w for w in report["warnings"] if w.startswith(NO_TIP_WARNING)]
    assert bool(said) == warned
    if said:  # the remedy: the focal where it was fitted, a rig or the tip where it was given
        assert ("--focal-px" in said[0]) == (probe is not None) and ("--rig" in said[0])


@pytest.mark.parametrize("shares, probe, warned", [
    ((0.94, 0.95, 0.97), {"held": True}, True),  # a tight crop, focal fitted
    ((0.94, 0.95, 0.97), None, True),  # the focal given does not fix the section
    ((0.94, 0.3, 0.97), {"held": True}, False),  # one view shows the finger's width over most of its length
    ((None, None, None), {"held": True}, False),  # whole views: the report names no cut sides
    ((0.94, 0.95, 0.97), "rig", False),  # a rig holds the poses (no curvature reported)
])
def test_a_capture_the_frame_cuts_along_the_sides_is_warned(shares, probe, warned):
    from types import SimpleNamespace

    from fingersplat3d.alignment_status import SIDES_CUT_WARNING, TIGHT_CROP_SHARE, warn_sides_cut

    if warned:
        assert min(shares) >= TIGHT_CROP_SHARE
    names = ["left", "center", "right"]
    tips = {n: {"side": "left", "why": "outline"} | ({} if share is None else {"sides_cut": share})
            for n, share in zip(names, shares)}
    report = {"views": names, "warnings": [], "registration": {"tip": tips}}
    alignment = SimpleNamespace(aligned=[True, True, True], focal_probe=None if probe == "rig" else probe,
                                turn_uncertainty_deg=None if probe == "rig" else np.full((3, 3), 0.05))
    warn_sides_cut(alignment, report)
    assert any(w.startswith(SIDES_CUT_WARNING) for w in report["warnings"]) == warned
