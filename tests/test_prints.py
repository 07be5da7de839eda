"""`fs3d print`: the skin chart, the ridge filter, the rolled-equivalent print, its scoring and the command."""
import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from fingersplat3d.cli import main
from fingersplat3d.errors import EXIT_INCOMPLETE, EXIT_INPUT, InputError
from fingersplat3d.eval.contact import MARGIN
from fingersplat3d.eval.fingerprint import nbis_available
from fingersplat3d.eval.rolled_truth import fit_minutiae_similarity, located_minutiae, placed_minutiae
from fingersplat3d.prints.enhance import gabor_enhance
from fingersplat3d.prints.make import print_reconstruction
from fingersplat3d.prints.skin_chart import finger_frame, skin_chart
from fingersplat3d.scene import Camera, look_at

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "uwa_seed1"


def _ring_cameras(axis: np.ndarray, angles=(-45.0, 0.0, 45.0), distance=120.0, size=(640, 512)):
    """Cameras on a ring about the x axis, looking at the origin from the pad's side (-z) and around."""
    cameras = []
    for degrees in angles:
        turn = np.radians(degrees)
        eye = np.array([0.0, np.sin(turn), -np.cos(turn)]) * distance
        cameras.append(Camera.from_focal(2000.0, *size, look_at(eye, np.zeros(3), [1.0, 0.0, 0.0])))
    return cameras


def _silhouette_axes(cameras, axis):
    """Each camera's image of the 3D axis line through the origin: origin pixel and unit direction toward +axis."""
    found = []
    for camera in cameras:
        uv, _ = camera.project(np.array([[0.0, 0.0, 0.0], 5.0 * axis]))
        direction = uv[1] - uv[0]
        found.append((uv[0], direction / np.linalg.norm(direction)))
    return found


def _oval(half_width=9.0, pad_depth=6.0, roll_deg=0.0, spread_deg=240.0, length=30.0, count=60000, seed=0):
    """Points on a finger of oval section about +x (``half_width`` across, ``pad_depth`` deep), rolled by ``roll_deg``
    about its axis, seen over ``spread_deg`` about its own pad; and the pad's direction."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-length / 2, length / 2, count)
    phi = np.radians(rng.uniform(-spread_deg / 2, spread_deg / 2, count))
    roll = np.radians(roll_deg)
    turn = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(roll), -np.sin(roll)], [0.0, np.sin(roll), np.cos(roll)]])
    points = np.stack([x, half_width * np.sin(phi), -pad_depth * np.cos(phi)], 1) @ turn.T
    return points, turn @ np.array([0.0, 0.0, -1.0])


def _cylinder(radius=8.0, length=30.0, spread_deg=240.0, count=60000, seed=0):
    """Points on a cylinder about +x (tip at x = length / 2), azimuth spread about the pad (-z)."""
    return _oval(radius, radius, 0.0, spread_deg, length, count, seed)[0]


def test_the_axis_comes_from_the_silhouettes_and_points_to_the_tip():
    axis = np.array([np.cos(0.1), np.sin(0.1), 0.0])
    cameras = _ring_cameras(np.array([1.0, 0.0, 0.0]))
    points = _cylinder()
    frame = finger_frame(points, cameras, _silhouette_axes(cameras, axis))
    assert frame.axis_from == "silhouettes"
    assert np.degrees(np.arccos(np.clip(frame.axis @ axis, -1, 1))) < 0.5
    flipped = finger_frame(points, cameras, [(o, -d) for o, d in _silhouette_axes(cameras, axis)])
    assert flipped.axis @ axis < -0.99  # the tip is where the silhouettes say
    assert abs(frame.pad @ frame.axis) < 1e-9 and np.allclose(np.cross(frame.axis, frame.pad), frame.side)
    assert frame.pad @ np.array([0.0, 0.0, -1.0]) > 0.95  # toward the cameras: the pad


def test_one_view_falls_back_to_the_points_longest_direction():
    cameras = _ring_cameras(np.array([1.0, 0.0, 0.0]), angles=(0.0,))
    frame = finger_frame(_cylinder(), cameras, _silhouette_axes(cameras, np.array([1.0, 0.0, 0.0])))
    assert frame.axis_from == "points" and frame.axis[0] > 0.99


def test_the_chart_of_a_cylinder_is_its_arc_lengths():
    radius = 8.0
    points = _cylinder(radius)
    cameras = _ring_cameras(np.array([1.0, 0.0, 0.0]))
    frame = finger_frame(points, cameras, _silhouette_axes(cameras, np.array([1.0, 0.0, 0.0])))
    chart = skin_chart(points, frame)
    valid = chart.valid
    assert valid.sum() > 0.5 * valid.size * 240 / 360
    nodes = chart.points[valid]
    phi = np.arctan2(nodes[:, 1], -nodes[:, 2])  # from the pad (-z)
    body = np.abs(phi) < np.radians(100)
    # b: arc length around from the pad's centre line; a: along the axis, toward the base, from one ring for all.
    assert np.allclose(np.abs(chart.b[valid][body]), radius * np.abs(phi[body]), atol=0.05 * radius)
    inner = body & (np.abs(nodes[:, 0]) < 12)
    offset = chart.a[valid][inner] + nodes[inner, 0]
    assert np.ptp(offset) < 0.5 and np.nanmin(chart.a[valid]) <= 0.0 <= np.nanmax(chart.a[valid])
    assert np.all(np.isfinite(chart.normals[valid]))
    radial = chart.points[valid] - frame.origin
    radial -= (radial @ frame.axis)[:, None] * frame.axis
    assert np.all((chart.normals[valid] * radial).sum(1) > 0)  # outward


def test_rows_of_the_chart_are_rings_where_the_surface_stops_raggedly():
    # Side views lose the skin before the pad's centre does: the surface ends further back at the sides. A rolled
    # print lays each ring along one row, so a point's a must not depend on where its meridian happens to stop.
    radius = 8.0
    points = _cylinder(radius)
    phi = np.arctan2(points[:, 1], -points[:, 2])
    points = points[points[:, 0] < 15.0 - 6.0 * (1.0 - np.cos(phi))]
    cameras = _ring_cameras(np.array([1.0, 0.0, 0.0]))
    chart = skin_chart(points, finger_frame(points, cameras, _silhouette_axes(cameras, np.array([1.0, 0.0, 0.0]))))
    nodes = chart.points[chart.valid]
    inner = np.abs(nodes[:, 0]) < 5  # every meridian's nodes here, clear of where any of them stops
    offset = chart.a[chart.valid][inner] + nodes[inner, 0]
    assert inner.sum() > 100 and np.ptp(offset) < 0.5


@pytest.mark.parametrize("roll_deg", [-20.0, 0.0, 12.0, 25.0])
def test_the_prints_centre_line_is_the_sections_mirror_line_whatever_the_fingers_roll(roll_deg):
    # The cameras look at the pad from -z; the finger lies rolled in front of them. The print's centre line (b = 0)
    # is the pad's own, so a finger gives one print whatever its roll in the rig (measured: tools/bench_print.py).
    points, pad = _oval(roll_deg=roll_deg, spread_deg=270.0)  # three cameras 45 degrees apart see ~270 degrees
    cameras = _ring_cameras(np.array([1.0, 0.0, 0.0]))
    chart = skin_chart(points, finger_frame(points, cameras, _silhouette_axes(cameras, np.array([1.0, 0.0, 0.0]))))
    assert np.degrees(np.arccos(np.clip(chart.frame.pad @ pad, -1, 1))) < 1.5
    assert chart.frame.pad_from == ("mirror line" if abs(roll_deg) > 1 else chart.frame.pad_from)
    nodes, b = chart.points[chart.valid], chart.b[chart.valid]
    across = np.cross(np.array([1.0, 0.0, 0.0]), pad)  # b grows toward the finger's own side
    assert np.corrcoef(nodes @ across, b)[0, 1] > 0.95


def test_a_surface_seen_only_over_its_pad_keeps_the_cameras_centre_line():
    # Renders cropped to the pad (another group's, 120 degrees of skin): the flanks are not seen past their widest
    # point, the section's widths cannot be read, and the radii alone are misled by the relief: no mirror line.
    points, _ = _oval(roll_deg=15.0, spread_deg=120.0)
    cameras = _ring_cameras(np.array([1.0, 0.0, 0.0]))
    frame = finger_frame(points, cameras, _silhouette_axes(cameras, np.array([1.0, 0.0, 0.0])))
    chart = skin_chart(points, frame)
    assert chart.frame.pad_from == "cameras" and chart.frame.pad @ frame.pad > np.cos(np.radians(1.0))


def test_a_round_section_keeps_the_cameras_pad():
    points = _cylinder()
    cameras = _ring_cameras(np.array([1.0, 0.0, 0.0]))
    frame = finger_frame(points, cameras, _silhouette_axes(cameras, np.array([1.0, 0.0, 0.0])))
    chart = skin_chart(points, frame)
    assert chart.frame.pad_from == "cameras" and np.allclose(chart.frame.pad, frame.pad)


def test_the_mirror_search_is_finite_at_the_extremes():
    from fingersplat3d.prints.skin_chart import mirror_offset

    assert mirror_offset(np.full((20, 180), np.nan)) is None
    assert mirror_offset(np.full((20, 180), 7.0)) is None  # round: no line stands out
    one = np.full((20, 180), np.nan)
    one[:, 90] = 7.0
    assert mirror_offset(one) is None  # a single meridian pairs only with itself
    wide = np.full((20, 180), np.nan)
    phi = -np.pi + (np.arange(180) + 0.5) * np.radians(2.0)
    wide[:, 30:150] = (1e6 * np.hypot(np.sin(phi + 0.2), 0.6 * np.cos(phi + 0.2)))[30:150]  # huge radii stay finite
    found = mirror_offset(wide)
    assert found is not None and abs(found + 0.2) < np.radians(1.0)


def test_too_few_points_make_no_chart():
    cameras = _ring_cameras(np.array([1.0, 0.0, 0.0]))
    with pytest.raises(InputError, match="too few"):
        finger_frame(_cylinder(count=50), cameras, _silhouette_axes(cameras, np.array([1.0, 0.0, 0.0])))


def test_the_ridge_filter_removes_pores_and_keeps_ridges():
    rng = np.random.default_rng(0)
    period = 9.0
    y, x = np.mgrid[0:200, 0:200].astype(np.float32)
    ridges = np.cos(2 * np.pi * (x + 0.1 * y) / period).astype(np.float32)
    noisy = ridges + (rng.random(ridges.shape) < 0.02).astype(np.float32) * -3.0 + rng.normal(0, 0.5, ridges.shape).astype(np.float32)
    mask = np.zeros(ridges.shape, bool)
    mask[20:180, 20:180] = True
    out = gabor_enhance(noisy, mask, period)
    inner = np.zeros_like(mask)
    inner[40:160, 40:160] = True
    corr = lambda a, b: np.corrcoef(a[inner], b[inner])[0, 1]  # noqa: E731
    assert corr(out, ridges) > 0.95 > corr(noisy, ridges)
    assert np.all(np.isfinite(out)) and np.all(out[~mask] == 0)
    assert 0.7 < np.sqrt(np.mean(out[inner] ** 2)) < 1.3
    assert np.all(np.isfinite(gabor_enhance(np.zeros((50, 50), np.float32), np.ones((50, 50), bool), period)))


def test_the_similarity_fit_finds_a_turned_scaled_print_among_false_minutiae():
    rng = np.random.default_rng(3)
    true_xy = rng.uniform(50, 450, (70, 2))
    true_deg = rng.uniform(0, 360, 70)
    turn, scale, shift = np.radians(3.0), 1.03, np.array([25.0, -18.0])
    rotation = scale * np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    found_xy = true_xy @ rotation.T + shift + rng.normal(0, 2.0, true_xy.shape)
    found_deg = (true_deg + 3.0 + rng.normal(0, 5, 70)) % 360
    keep = rng.random(70) < 0.85  # mindtct misses some, finds others that are not there
    found_xy = np.vstack([found_xy[keep], rng.uniform(0, 520, (30, 2))])
    found_deg = np.concatenate([found_deg[keep], rng.uniform(0, 360, 30)])
    fitted = fit_minutiae_similarity(true_xy, true_deg, found_xy, found_deg, shift + np.array([30.0, 20.0]))
    assert np.hypot(*fitted[:, 0]) == pytest.approx(scale, abs=0.01)
    mask = np.ones((560, 560), bool)
    score = located_minutiae(true_xy, true_deg, found_xy, found_deg, mask, shift + np.array([30.0, 20.0]))
    assert score.inside == 70 and 0.75 < score.located_share <= keep.mean() + 0.05
    assert abs(score.turn_deg - 3.0) < 0.5
    # Several starts: the fit that locates most counts, wherever the right start is among them.
    starts = np.array([shift + [150.0, -130.0], shift + [30.0, 20.0], shift + [-140.0, 90.0]])
    several = located_minutiae(true_xy, true_deg, found_xy, found_deg, mask, starts)
    assert several.located == score.located
    assert located_minutiae(true_xy, true_deg, found_xy, found_deg, mask, starts[[0]]).located < score.located


def test_placed_minutiae_scores_the_prints_geometry_after_one_similarity():
    rng = np.random.default_rng(4)
    rows, cols = np.mgrid[0:300, 0:260].astype(np.float64)
    print_points = np.stack([cols * 0.05, rows * 0.05, np.zeros_like(cols)], -1)  # a flat print, 0.05 mm a pixel
    mask = np.ones((300, 260), bool)
    print_points[:, :20] = np.nan
    where = rng.uniform([40, 40], [240, 280], (60, 2))  # (x, y) print pixels
    xyz = np.column_stack([where * 0.05, np.full(60, 0.2)])  # 0.2 mm off the surface
    turn, scale = np.radians(-4.0), 0.97
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]]) / scale
    true_xy = (where - 100.0) @ rotation.T + np.array([300.0, 40.0])  # the true print: turned, scaled, shifted
    true_xy[:10] += rng.choice([-1.0, 1.0], (10, 2)) * 20.0  # ten the chart put in the wrong place
    far = np.array([[5.0, 5.0, 3.0]])  # off the print's surface: not inside
    score = placed_minutiae(print_points, mask, np.vstack([xyz, far]), np.vstack([true_xy, [[0.0, 0.0]]]), max_gap=1.0)
    assert score.inside == 60 and score.located == 50
    assert score.scale == pytest.approx(scale, abs=0.01) and score.turn_deg == pytest.approx(4.0, abs=0.2)
    blank = placed_minutiae(np.full((50, 50, 3), np.nan), np.zeros((50, 50), bool), xyz, true_xy, max_gap=1.0)
    assert blank.inside == 0 and np.isnan(blank.located_share)


def test_the_rolled_print_of_a_true_model_is_a_500_ppi_print_of_its_skin():
    result, scale_from, source = print_reconstruction(SAMPLE)
    assert scale_from == "cameras (mm)"
    assert result.image.dtype == np.uint8 and np.all(result.image[~result.mask] == 255)
    assert result.mask.sum() > 50_000 and source.ndim == 2
    period_mm = json.loads((SAMPLE / "minutiae.json").read_text())["ridge_period_mm"]
    assert result.period_px == pytest.approx(period_mm * 500 / 25.4, rel=0.2)  # ~500 ppi
    assert result.coverage_deg >= 150  # three views 45 degrees apart
    # Cut to its skin: MARGIN white pixels on every side, not the chart's whole finger (the crease and beyond).
    rows, cols = np.flatnonzero(result.mask.any(1)), np.flatnonzero(result.mask.any(0))
    assert (rows[0], cols[0]) == (MARGIN, MARGIN)
    assert (result.mask.shape[0] - 1 - rows[-1], result.mask.shape[1] - 1 - cols[-1]) == (MARGIN, MARGIN)
    assert result.image.shape == result.mask.shape == result.points.shape[:2]
    assert cols[0] < result.origin_px[0] < cols[-1]  # the pad's centre line, moved with the cut
    points = result.points[result.mask]
    assert np.all(np.isfinite(points)) and np.all(np.isnan(result.points[~result.mask]))
    assert sum(result.view_share.values()) == pytest.approx(1.0)
    # Neighbouring print pixels are neighbouring skin: 1 px at 500 ppi is 0.05 mm.
    step = np.linalg.norm(np.diff(result.points, axis=1), axis=-1)
    assert np.nanmedian(step) == pytest.approx(25.4 / 500, rel=0.15)
    # Its chart puts the skin where the finger's true rolled print has it: the true minutiae within 8 px after one
    # similarity (93 %; 83 % centred on the cameras' direction, 17 degrees off this finger's pad; not all: the
    # generator counts rows from the tip's pole, the chart from one ring).
    truth = json.loads((SAMPLE / "minutiae.json").read_text())
    xy = {m["id"]: m["xy"] for m in truth["rolled_print"]["minutiae"]}
    both = [m for m in truth["minutiae_3d"] if m["id"] in xy]
    placed = placed_minutiae(result.points, result.mask, np.array([m["xyz"] for m in both]),
                             np.array([xy[m["id"]] for m in both]), max_gap=1.0)
    assert placed.inside > 40 and placed.located_share > 0.88 and placed.scale == pytest.approx(1.0, abs=0.03)


@pytest.mark.skipif(not nbis_available(), reason="needs nbis-py (NIST mindtct)")
def test_the_rolled_print_of_a_true_model_finds_the_true_minutiae():
    from fingersplat3d.eval.contact import ContactImage
    from fingersplat3d.eval.fingerprint import analyse
    from fingersplat3d.eval.rolled_truth import SEARCH_PX, START_PEAKS, template_shift

    result, _, _ = print_reconstruction(SAMPLE)
    found = analyse(ContactImage(result.image, np.array([[1.0, 0, 0], [0, 1.0, 0]]), 9.0, 1.0), nfiq2=False)
    truth = json.loads((SAMPLE / "minutiae.json").read_text())["rolled_print"]
    true_image = cv2.imread(str(SAMPLE / "rolled_print.png"), cv2.IMREAD_GRAYSCALE)
    xy = np.array([m["xy"] for m in truth["minutiae"]])
    degrees = np.array([m["angle_deg"] for m in truth["minutiae"]])
    score = located_minutiae(xy, degrees, found.minutiae[:, :2], found.minutiae[:, 2], result.mask,
                             template_shift(result.image, true_image, count=START_PEAKS))
    assert score.inside > 40
    assert score.located_share > 0.5  # 74 % measured on this 640x512 sample
    peaks = template_shift(result.image, true_image, count=3)
    assert peaks.shape == (3, 2) and np.array_equal(peaks[0], template_shift(result.image, true_image))
    assert np.all(np.linalg.norm(peaks[1:] - peaks[0], axis=1) >= SEARCH_PX)
    assert score.scale == pytest.approx(1.0, abs=0.05)


def _recon_without_depth(tmp_path: Path) -> Path:
    folder = tmp_path / "nodepth"
    folder.mkdir()
    (folder / "cameras.json").write_text((SAMPLE / "cameras.json").read_text())
    return folder


def test_fs3d_print_writes_prints_and_lists_what_failed(tmp_path, capsys):
    not_rec = tmp_path / "empty"
    not_rec.mkdir()
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((200, 300), 128, np.uint8))
    out = tmp_path / "prints"
    inputs = [SAMPLE, SAMPLE / "images" / "center.png", not_rec, _recon_without_depth(tmp_path), blank]  # a path not there: below
    status = main(["print", *map(str, inputs), "-o", str(out), "--no-nfiq2"])
    assert status == EXIT_INCOMPLETE
    err = capsys.readouterr().err
    assert "3 of 5 inputs gave no print" in err and "Traceback" not in err
    rows = {row["name"]: row for row in csv.DictReader((out / "prints.csv").open())}
    assert rows["uwa_seed1"]["status"] == "done" and rows["uwa_seed1"]["kind"] == "rolled"
    assert float(rows["uwa_seed1"]["coverage_deg"]) >= 150
    assert rows["uwa_seed1"]["centred_on"] == "mirror line"  # the sample's finger lies rolled 17 degrees in its rig
    assert rows["center"]["status"] == "done" and rows["center"]["kind"] == "photo"
    assert "not a reconstruction folder" in rows["empty"]["reason"]
    assert "no depth maps" in rows["nodepth"]["reason"]
    assert rows["blank"]["status"] == "failed"
    for name in ("uwa_seed1", "center"):
        printed = cv2.imread(str(out / f"{name}.png"), cv2.IMREAD_UNCHANGED)
        assert printed.dtype == np.uint8 and printed.ndim == 2
        assert (out / "masks" / f"{name}.png").is_file() and (out / "pictures" / f"{name}.png").is_file()
    points = np.load(out / "points" / "uwa_seed1.npy")
    assert points.shape == cv2.imread(str(out / "uwa_seed1.png")).shape[:2] + (3,) and points.dtype == np.float32
    # An existing output folder is refused (nothing written), unless --overwrite.
    assert main(["print", str(SAMPLE), "-o", str(out)]) == EXIT_INPUT
    assert "already exists" in capsys.readouterr().err
    assert main(["print", str(SAMPLE / "images" / "left.png"), "-o", str(out), "--overwrite", "--no-nfiq2"]) == 0
    assert [row["name"] for row in csv.DictReader((out / "prints.csv").open())] == ["left"]


@pytest.mark.skipif(not nbis_available(), reason="needs nbis-py (NFIQ2)")
def test_a_print_smaller_than_nfiq2_scores_is_said_to_be_too_small():
    from fingersplat3d.prints.make import _scores

    y, x = np.mgrid[0:400, 0:400].astype(np.float32)
    ridges = (127.5 + 100 * np.cos(2 * np.pi * (x + 0.3 * y) / 9.0)).astype(np.uint8)
    small = np.full((400, 400), 255, np.uint8)
    small[150:270, 140:240] = ridges[150:270, 140:240]  # 100 x 120 px of ridges: 5 x 6 mm at 500 ppi
    scores = _scores(small, nfiq2=True)
    assert scores["status"] == "too small" and "100x120 px" in scores["reason"] and scores["nfiq2"] == ""
    assert "status" not in _scores(ridges, nfiq2=True)  # 400 x 400 px of ridges: scored
    assert _scores(small, nfiq2=False) == {}  # not asked for: nothing said


def test_fs3d_print_lists_a_print_too_small_for_nfiq2_and_still_writes_it(tmp_path, capsys, monkeypatch):
    import fingersplat3d.prints.make as make

    monkeypatch.setattr(make, "_scores", lambda image, nfiq2, centre_x=None: {
        "nfiq2": "", "status": "too small", "reason": "its ridge area is 90x80 px, smaller than NFIQ2 scores"})
    out = tmp_path / "prints"
    assert main(["print", str(SAMPLE / "images" / "center.png"), "-o", str(out)]) == EXIT_INCOMPLETE
    err = capsys.readouterr().err
    assert "center: print too small: its ridge area is 90x80 px" in err and "1 print(s) too small for NFIQ2" in err
    assert "gave no print" not in err and "Traceback" not in err
    row = next(csv.DictReader((out / "prints.csv").open()))
    assert row["status"] == "too small" and (out / "center.png").is_file()


def test_fs3d_print_refuses_bad_arguments(tmp_path, capsys):
    assert main(["print", str(SAMPLE), "-o", str(tmp_path / "o"), "--ppi", "0"]) == EXIT_INPUT
    assert main(["print", str(SAMPLE), "-o", str(tmp_path / "o"), "--px-per-mm", "nan"]) == EXIT_INPUT
    assert not (tmp_path / "o").exists()
    capsys.readouterr()
    # A wrong path is bad input before any print is made (it had been a row of prints.csv and exit 4).
    assert main(["print", str(SAMPLE), str(tmp_path / "no_such.png"), "-o", str(tmp_path / "o")]) == EXIT_INPUT
    assert "no_such.png: no such file or folder" in capsys.readouterr().err and not (tmp_path / "o").exists()


def test_ridge_coherence_tells_ridges_from_noise():
    from fingersplat3d.prints.enhance import ridge_coherence

    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:160, 0:320].astype(np.float32)
    image = np.cos(2 * np.pi * (x + 0.2 * y) / 9.0).astype(np.float32)
    image[:, 160:] = rng.normal(0, 1, (160, 160))
    coherence = ridge_coherence(image, np.ones(image.shape, bool), 9.0)
    assert np.median(coherence[40:120, 20:120]) > 0.8 > 0.3 > np.median(coherence[40:120, 200:300])
    assert np.all(np.isfinite(ridge_coherence(np.zeros((40, 40), np.float32), np.ones((40, 40), bool), 9.0)))


def test_fs3d_print_mirror_flips_the_print(tmp_path):
    photo = SAMPLE / "images" / "center.png"
    assert main(["print", str(photo), "-o", str(tmp_path / "a"), "--no-nfiq2"]) == 0
    assert main(["print", str(photo), "-o", str(tmp_path / "b"), "--no-nfiq2", "--mirror"]) == 0
    plain = cv2.imread(str(tmp_path / "a" / "center.png"), cv2.IMREAD_GRAYSCALE)
    mirrored = cv2.imread(str(tmp_path / "b" / "center.png"), cv2.IMREAD_GRAYSCALE)
    assert np.array_equal(plain[:, ::-1], mirrored)


def test_fs3d_print_of_a_photo_on_a_bright_background(tmp_path):
    """A phone-style photo (the finger on a bright desk) gives the same print area as on the rig's dark background."""
    from fingersplat3d.segment.masks import finger_mask

    photo = cv2.imread(str(SAMPLE / "images" / "center.png"))
    mask = finger_mask(photo.astype(np.float32) / 255.0)
    soft = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 1.0)[..., None]
    desk = 210.0 + np.random.default_rng(0).normal(0, 6, photo.shape)
    (tmp_path / "dark").mkdir()
    (tmp_path / "bright").mkdir()
    cv2.imwrite(str(tmp_path / "dark" / "finger.png"), photo)
    cv2.imwrite(str(tmp_path / "bright" / "finger.png"), (soft * photo + (1 - soft) * desk).clip(0, 255).astype(np.uint8))
    areas = {}
    for kind in ("dark", "bright"):
        out = tmp_path / f"prints_{kind}"
        assert main(["print", str(tmp_path / kind / "finger.png"), "-o", str(out), "--no-nfiq2"]) == 0
        row = next(csv.DictReader((out / "prints.csv").open()))
        assert row["status"] == "done"
        areas[kind] = float(row["area_mm2"])
    assert areas["bright"] == pytest.approx(areas["dark"], rel=0.15)


def _photo_placed(folder: Path, flat: bool):
    """The share of the true minutiae the front photo shows that its print puts within 8 px of their place on the
    finger's true rolled print, after one similarity (``placed_minutiae`` on the print's map back to the photo)."""
    from fingersplat3d.eval.contact import contact_like
    from fingersplat3d.io.capture import read_capture
    from fingersplat3d.prints.make import photo_pixels, unrolled_photo

    view = next(v for v in read_capture(folder).views if v.name == "center")
    truth = json.loads((folder / "minutiae.json").read_text())
    rolled_xy = {m["id"]: m["xy"] for m in truth["rolled_print"]["minutiae"]}
    shown = [m for m in truth["views"]["center"] if m["visible"] and m["id"] in rolled_xy]
    uv = np.array([[*m["uv"], 0.0] for m in shown])
    xy = np.array([rolled_xy[m["id"]] for m in shown])
    if flat:
        made = contact_like(view.image, view.mask)
        mask = made.image < 255
        photo = made.photo_pixels()
    else:
        made, camera = unrolled_photo(view.image, view.mask)
        mask = made.mask
        assert np.all(made.image[~mask] == 255) and made.coverage_deg > 90
        photo = photo_pixels(made, camera)
        assert np.isfinite(photo[mask]).all() and np.isnan(photo[~mask]).all()
    on_photo = np.where(mask[..., None], np.concatenate([photo, np.zeros(mask.shape + (1,))], -1), np.nan)
    return placed_minutiae(on_photo, mask, uv, xy, max_gap=1.5)


def test_a_photos_print_unrolled_lays_its_skin_where_the_rolled_print_has_it():
    """The photo foreshortens the skin toward the finger's sides; unrolled through the surface its silhouette gives, the
    minutiae it shows land where the finger's true rolled print has them. On this sample (the finger rolled 17 degrees
    in its rig) 86 % within 8 px after one similarity, against 29 % for the photo scaled and turned alone."""
    flat, unrolled = _photo_placed(SAMPLE, flat=True), _photo_placed(SAMPLE, flat=False)
    assert unrolled.inside >= 40
    assert unrolled.located_share > 0.7 and unrolled.located_share > flat.located_share + 0.2
    assert unrolled.scale == pytest.approx(1.0, abs=0.15)  # ~500 ppi from the ridge period


def test_a_photos_unrolled_print_refuses_a_bad_mask():
    from fingersplat3d.prints.make import unrolled_photo

    image = np.full((64, 80), 0.5, np.float32)
    with pytest.raises(InputError, match="empty"):
        unrolled_photo(image, np.zeros((64, 80), bool))
    with pytest.raises(InputError, match="does not match"):
        unrolled_photo(image, np.ones((32, 80), bool))


def test_fs3d_print_of_a_photo_unrolled_or_flat(tmp_path):
    photo = SAMPLE / "images" / "center.png"
    widths = {}
    for flag, kind in ((), "photo"), (("--flat",), "photo flat"):
        out = tmp_path / kind.replace(" ", "_")
        assert main(["print", str(photo), "-o", str(out), "--no-nfiq2", *flag]) == 0
        row = next(csv.DictReader((out / "prints.csv").open()))
        assert row["status"] == "done" and row["kind"] == kind
        assert (row["coverage_deg"] != "") == (kind == "photo")
        widths[kind] = int(row["width_px"])
        # Each inked print pixel's photo pixel lies on the photo's finger: minutiae can be carried back.
        printed = cv2.imread(str(out / "center.png"), cv2.IMREAD_GRAYSCALE)
        xy = np.load(out / "photo_xy" / "center.npy")
        assert xy.shape == printed.shape + (2,) and xy.dtype == np.float32
        inked = printed < 255
        assert np.isfinite(xy[inked]).all() and np.isnan(xy[~cv2.imread(str(out / "masks" / "center.png"), 0).astype(bool)]).all()
        finger = cv2.imread(str(SAMPLE / "masks" / "center.png"), cv2.IMREAD_GRAYSCALE) > 127
        u, v = np.rint(xy[inked]).astype(int).T
        assert np.mean(finger[v.clip(0, finger.shape[0] - 1), u.clip(0, finger.shape[1] - 1)]) > 0.95
    assert widths["photo"] > 1.1 * widths["photo flat"]  # the sides laid flat, not foreshortened


def test_the_print_window_keeps_the_skin_and_a_margin_within_the_canvas():
    from fingersplat3d.prints.rolled import _print_window

    mask = np.zeros((50, 60), bool)
    mask[20:30, 25:40] = True
    rows, cols = _print_window(mask)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (20 - MARGIN, 30 + MARGIN, 25 - MARGIN, 40 + MARGIN)
    mask[:, 55:] = True  # skin to the canvas's edges: the window stops there
    rows, cols = _print_window(mask)
    assert (rows.start, rows.stop, cols.stop) == (0, 50, 60)
    assert _print_window(np.zeros((5, 5), bool)) == (slice(None), slice(None))  # nothing inked: the canvas as it is
