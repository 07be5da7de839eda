"""fs3d synth: determinism, geometric consistency of the ground truth, minutiae on the image."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from fingersplat3d.errors import InputError
from fingersplat3d.synth import Appearance, SynthConfig, synthesize
from fingersplat3d.synth.ridges import BIFURCATION, ENDING

CLEAN = Appearance(noise=0.0, blur_px=0.0, specular=0.0, glints=0.0, wrinkles=0.0, ridge_contrast=0.35)


@pytest.fixture(scope="module")
def uwa_small():
    return synthesize(3, SynthConfig(size=(320, 256)))


@pytest.fixture(scope="module")
def uwa_clean_full():
    """Full-resolution, noise-free uwa capture: ridge period ~15 px."""
    return synthesize(11, SynthConfig(appearance=CLEAN))


def test_same_seed_same_capture_and_other_seed_differs():
    first = synthesize(5, SynthConfig(size=(160, 128)))
    again = synthesize(5, SynthConfig(size=(160, 128)))
    other = synthesize(6, SynthConfig(size=(160, 128)))
    for a, b in zip(first.capture.views, again.capture.views):
        np.testing.assert_array_equal(a.image, b.image)
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.camera.world_to_cam, b.camera.world_to_cam)
    assert first.minutiae == again.minutiae
    assert not np.array_equal(first.capture.views[1].image, other.capture.views[1].image)


def test_uwa_rig_geometry(uwa_small):
    views = uwa_small.capture.views
    assert [v.name for v in views] == ["left", "center", "right"]
    assert all(v.image.ndim == 2 for v in views), "uwa is grayscale"
    optical_axes = [v.camera.rotation[2] for v in views]
    for a, b in ((0, 1), (1, 2)):
        angle = np.degrees(np.arccos(np.clip(optical_axes[a] @ optical_axes[b], -1, 1)))
        assert angle == pytest.approx(45.0, abs=1e-6)
    # As in UWA's raw frames the tip points left: the finger axis (+x) runs right to left in every
    # image, up to the hand-placed finger's tilt (at most 6 degrees of pitch and yaw).
    assert abs(uwa_small.capture.metadata["poses"]["center"]["roll_deg"]) <= 20
    for view in views:
        assert view.camera.rotation[0] @ np.array([1.0, 0, 0]) < -0.98
        columns = np.nonzero(view.mask.any(axis=0))[0]
        assert columns[-1] == view.width - 1 and columns[0] > 5, "finger enters from the right, tip inside the frame"


def test_cfpose_rig_one_camera_moving_finger():
    result = synthesize(2, SynthConfig(rig="cfpose", size=(160, 200), poses=4))
    views = result.capture.views
    assert len(views) == 4 and all(v.image.ndim == 3 for v in views), "cfpose is RGB by default"
    rolls = [result.capture.metadata["poses"][v.name]["roll_deg"] for v in views]
    assert rolls[0] == 0 and min(rolls) < -10 and max(rolls) > 10
    # The camera stays at one distance from the pivot the finger turns about; the finger is vertical (tip up).
    from fingersplat3d.synth.rigs import _target

    pivot = _target(result.surface.params)
    distances = [np.linalg.norm(v.camera.center - pivot) for v in views]
    assert np.ptp(distances) < 1e-6
    assert views[0].camera.rotation[1] @ np.array([1.0, 0, 0]) < -0.99


def test_depth_is_the_mesh_surface(uwa_small):
    import open3d as o3d

    mesh = uwa_small.surface.to_open3d()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    for view in uwa_small.capture.views:
        points = view.camera.depth_to_points(view.depth)[view.mask]
        distance = scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()
        assert np.all(np.isfinite(view.depth[view.mask])) and np.all(np.isnan(view.depth[~view.mask]))
        assert np.percentile(distance, 99.9) < 2e-3  # mm: float32 ray casting at ~120 mm


def _bilinear(image, uv):
    return cv2.remap(image.astype(np.float32), uv[:, 0].astype(np.float32)[None], uv[:, 1].astype(np.float32)[None],
                     cv2.INTER_LINEAR, borderValue=np.nan)[0]


@pytest.mark.parametrize("pair", [("left", "center"), ("center", "right"), ("left", "right")])
def test_depth_reprojects_between_views_subpixel(uwa_clean_full, pair):
    """Pixel p in A -> 3D by A's depth -> pixel q in B -> 3D by B's depth -> back in A: lands on p."""
    view_a, view_b = (uwa_clean_full.capture[name] for name in pair)
    rng = np.random.default_rng(0)
    # Away from silhouettes and depth edges, where bilinear depth lookups are meaningful.
    interior = cv2.erode(view_a.mask.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    pixels = np.argwhere(interior)[:, ::-1]
    pixels = pixels[rng.choice(len(pixels), 4000, replace=False)].astype(np.float64)
    points = view_a.camera.unproject(pixels, view_a.depth[pixels[:, 1].astype(int), pixels[:, 0].astype(int)])
    uv_b, z_b = view_b.camera.project(points)
    seen_b = _bilinear(view_b.depth, uv_b)
    # Skin seen at a grazing angle by B changes depth by millimetres per pixel: not a sub-pixel test.
    normals = uwa_clean_full.renderings[pair[0]].normal[pixels[:, 1].astype(int), pixels[:, 0].astype(int)]
    to_b = view_b.camera.center - points
    facing_b = (normals * to_b).sum(1) / np.linalg.norm(to_b, axis=1)
    visible = np.isfinite(seen_b) & (np.abs(seen_b - z_b) < 0.05) & (facing_b > 0.3)
    assert visible.mean() > 0.2, "the pair shares a good part of the finger"
    back = view_b.camera.unproject(uv_b[visible], seen_b[visible])
    uv_a, _ = view_a.camera.project(back)
    error = np.linalg.norm(uv_a - pixels[visible], axis=1)
    assert np.median(error) < 0.05 and np.percentile(error, 99) < 0.5


def _image_minutiae(image, mask, period_px):
    """Minutiae found in a rendered image: adaptive binarisation, thinning, crossing number."""
    smooth = cv2.GaussianBlur(image.astype(np.float32), (0, 0), period_px / 8)
    local = cv2.GaussianBlur(smooth, (0, 0), period_px * 0.6)
    ridges = ((smooth > local) & mask).astype(np.uint8) * 255
    skeleton = cv2.ximgproc.thinning(ridges) > 0
    s = skeleton.astype(np.int32)
    ring = [s[:-2, 1:-1], s[:-2, 2:], s[1:-1, 2:], s[2:, 2:], s[2:, 1:-1], s[2:, :-2], s[1:-1, :-2], s[:-2, :-2]]
    crossings = sum(np.abs(ring[k] - ring[(k + 1) % 8]) for k in range(8)) // 2
    core = skeleton[1:-1, 1:-1]
    found = {}
    for kind, number in ((ENDING, 1), (BIFURCATION, 3)):
        rows, cols = np.nonzero(core & (crossings == number))
        found[kind] = np.stack([cols + 1, rows + 1], axis=1).astype(np.float64)
    return found


def test_minutiae_project_onto_ridge_endings_and_bifurcations(uwa_clean_full):
    """Exported per-view minutiae land on endings/bifurcations of the same kind in the rendered photo."""
    result = uwa_clean_full
    view = result.capture["center"]
    kinds = {m["id"]: m["kind"] for m in result.minutiae["minutiae_3d"]}
    normals = {m["id"]: np.asarray(m["normal"]) for m in result.minutiae["minutiae_3d"]}
    xyz = {m["id"]: np.asarray(m["xyz"]) for m in result.minutiae["minutiae_3d"]}
    # Ridge period in pixels at the pad: period_mm * focal / depth.
    period_px = result.pattern.period_mm * view.camera.K[0, 0] / np.nanmedian(view.depth)
    inner = cv2.erode(view.mask.astype(np.uint8), np.ones((int(4 * period_px),) * 2, np.uint8)).astype(bool)
    found = _image_minutiae(view.image, inner, period_px)
    selected = []
    for entry in result.minutiae["views"]["center"]:
        if not entry["visible"]:
            continue
        to_camera = view.camera.center - xyz[entry["id"]]
        facing = normals[entry["id"]] @ to_camera / np.linalg.norm(to_camera)
        u, v = entry["uv"]
        if facing > 0.8 and inner[int(round(v)), int(round(u))]:
            selected.append((np.array(entry["uv"]), ENDING if kinds[entry["id"]] == "ending" else BIFURCATION))
    assert len(selected) >= 15

    def match_rate(offset):
        hits = 0
        for uv, kind in selected:
            candidates = found[kind]
            hits += len(candidates) > 0 and np.min(np.linalg.norm(candidates - (uv + offset), axis=1)) < 0.5 * period_px
        return hits / len(selected)

    assert match_rate(np.zeros(2)) >= 0.75
    # Control: the same test fails for positions moved by a ridge period.
    assert match_rate(np.array([period_px, period_px])) < 0.5 * match_rate(np.zeros(2))


def test_minutiae_visibility_is_consistent(uwa_small):
    for view in uwa_small.capture.views:
        entries = uwa_small.minutiae["views"][view.name]
        assert len(entries) == len(uwa_small.minutiae["minutiae_3d"])
        for entry in entries:
            if entry["visible"]:
                u, v = entry["uv"]
                assert 0 <= u <= view.width - 1 and 0 <= v <= view.height - 1
                assert view.mask[int(round(v)), int(round(u))]
        assert sum(e["visible"] for e in entries) >= 10


def test_finger_shape_within_human_ranges():
    from fingersplat3d.synth.shape import make_finger_surface, random_finger_params

    rng = np.random.default_rng(0)
    for _ in range(5):
        params = random_finger_params(rng)
        surface = make_finger_surface(params)
        body = surface.grid[surface.grid.shape[0] // 2]  # a ring on the body of the finger
        width, height = np.ptp(body[:, 1]), np.ptp(body[:, 2])
        assert 12.5 <= width <= 23.5 and height < 1.05 * width
        # Flatter on the nail side: the nail half is lower than the pad half.
        centre_z = surface.grid[surface.grid.shape[0] // 2, :, 2].mean()
        assert body[:, 2].max() - centre_z < centre_z - body[:, 2].min() + 1.0
        assert _closed_and_consistently_oriented(surface.triangles)


def test_the_default_pad_is_a_half_ellipse_and_wide_shapes_leave_it():
    from dataclasses import replace

    from fingersplat3d.synth.shape import FingerParams, _section, random_finger_params

    # The adult draw is the one it always was (every shipped sample and table rests on it); its pad is a half ellipse.
    adult = random_finger_params(np.random.default_rng(4))
    assert adult.pad_exponent == 2.0
    phi = np.linspace(-np.pi / 2, np.pi / 2, 181)
    y, z = _section(phi, adult).T
    np.testing.assert_allclose((2 * y) ** 2 + (z / (adult.height_ratio * adult.pad_share)) ** 2, 1.0, atol=1e-12)
    # A super-ellipse pad: |2y|^p + |z / depth|^p = 1, fuller than the ellipse at 45 degrees for p > 2.
    boxy = replace(FingerParams(), pad_exponent=3.5)
    y, z = _section(phi, boxy).T
    depth = boxy.height_ratio * boxy.pad_share
    np.testing.assert_allclose(np.abs(2 * y) ** 3.5 + np.abs(z / depth) ** 3.5, 1.0, atol=1e-9)
    assert abs(_section(np.array([np.pi / 4]), boxy)[0, 1]) > abs(_section(np.array([np.pi / 4]), FingerParams())[0, 1])
    # The wide draw starts from the adult one and goes beyond its ranges, deterministically.
    rng_a, rng_b = np.random.default_rng(4), np.random.default_rng(4)
    wide = [random_finger_params(rng_a, "wide") for _ in range(40)]
    assert wide[0].width == adult.width and wide[0].cap == adult.cap
    assert [w.pad_exponent for w in wide] == [random_finger_params(rng_b, "wide").pad_exponent for _ in range(40)]
    exponents, heights, tapers = (np.array([getattr(w, k) for w in wide]) for k in ("pad_exponent", "height_ratio", "taper"))
    assert 1.6 <= exponents.min() and exponents.max() <= 3.5 and exponents.min() < 2.0 < exponents.max()
    assert heights.max() > 0.95 and heights.min() < 0.68 and tapers.min() < 0.0 < tapers.max()
    with pytest.raises(ValueError, match="shapes"):
        random_finger_params(np.random.default_rng(0), "alien")


@pytest.mark.parametrize("pad_exponent, height_ratio, taper, bend", [(1.6, 0.55, -0.25, 6.0), (3.5, 1.05, 0.35, 0.0)])
def test_wide_shapes_at_their_extremes_make_closed_fingers_and_finite_captures(pad_exponent, height_ratio, taper, bend):
    from dataclasses import replace

    from fingersplat3d.synth.shape import FingerParams, make_finger_surface

    params = replace(FingerParams(), pad_exponent=pad_exponent, height_ratio=height_ratio, taper=taper, bend=bend,
                     pad_bulge=0.35)
    surface = make_finger_surface(params, 40, 20, 60)
    assert np.all(np.isfinite(surface.vertices)) and _closed_and_consistently_oriented(surface.triangles)
    body = surface.grid[surface.grid.shape[0] // 2]
    assert np.ptp(body[:, 2]) < 1.5 * np.ptp(body[:, 1])


def test_wide_shapes_capture():
    capture = synthesize(2, SynthConfig(size=(160, 128), shapes="wide")).capture
    adult = synthesize(2, SynthConfig(size=(160, 128))).capture
    for view, other in zip(capture.views, adult.views):
        assert np.all(np.isfinite(view.image)) and view.mask.any()
        assert not np.array_equal(view.mask, other.mask)


def _closed_and_consistently_oriented(triangles):
    """Every directed edge appears once and its reverse once: closed, manifold, coherent winding."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    count = int(triangles.max()) + 1
    forward = np.sort(edges[:, 0].astype(np.int64) * count + edges[:, 1])
    backward = np.sort(edges[:, 1].astype(np.int64) * count + edges[:, 0])
    return bool(np.all(np.diff(forward) > 0) and np.array_equal(forward, backward))


def test_skin_coordinates_are_arc_lengths():
    from fingersplat3d.synth.shape import FingerParams, make_finger_surface

    surface = make_finger_surface(FingerParams())
    a, b = np.array([6.0, 12.0, 18.0]), np.array([0.0, 3.0, -5.0])
    points = surface.surface_at(a, b)
    assert np.all(np.isfinite(points))
    # Moving 1 mm in a or b moves ~1 mm on the skin (near-isometric on the body).
    for da, db in ((1.0, 0.0), (0.0, 1.0)):
        moved = surface.surface_at(a + da, b + db)
        assert np.allclose(np.linalg.norm(moved - points, axis=1), 1.0, atol=0.03)


@pytest.mark.parametrize("config, words", [
    (SynthConfig(rig="nope"), "unknown rig"),
    (SynthConfig(shapes="alien"), "unknown finger shapes"),
    (SynthConfig(pattern="spiral"), "unknown pattern"),
    (SynthConfig(size=(4, 4)), "image size"),
    (SynthConfig(focal=-3.0), "focal"),
    (SynthConfig(rig="ring"), "angles"),
    (SynthConfig(period_mm=(0.5, 0.4)), "period"),
])
def test_bad_config_is_rejected(config, words):
    with pytest.raises(InputError, match=words):
        synthesize(0, config)


def test_ring_rig_extreme_sizes_stay_finite():
    tiny = synthesize(1, SynthConfig(rig="ring", angles=(-90.0, 0.0, 90.0), size=(16, 12)))
    for view in tiny.capture.views:
        assert np.all(np.isfinite(view.image)) and view.mask.any()


def test_camera_distance_keeps_the_framing_and_changes_the_perspective():
    close = synthesize(4, SynthConfig(size=(160, 128), distance_mm=50.0)).capture
    far = synthesize(4, SynthConfig(size=(160, 128), distance_mm=400.0)).capture
    for near_view, far_view in zip(close.views, far.views):
        near_cam, far_cam = near_view.camera, far_view.camera
        assert far_cam.K[0, 0] / near_cam.K[0, 0] == pytest.approx(8.0, rel=1e-9)  # same field at the finger
        area = near_view.mask.sum(), far_view.mask.sum()
        assert 0.75 < area[0] / area[1] < 1.33
        relief = [np.nanmax(d[m]) - np.nanmin(d[m]) for d, m in ((near_view.depth, near_view.mask), (far_view.depth, far_view.mask))]
        near_depth = [np.nanmedian(near_view.depth[near_view.mask]), np.nanmedian(far_view.depth[far_view.mask])]
        # the same finger: the same relief in mm, at an eighth of the distance
        assert relief[0] == pytest.approx(relief[1], rel=0.25) and near_depth[1] / near_depth[0] > 5
    with pytest.raises(InputError, match="camera distance"):
        synthesize(0, SynthConfig(size=(160, 128), distance_mm=5.0))


def test_the_true_rolled_print_maps_like_a_frontal_photo_of_the_pad():
    from fingersplat3d.synth.rolled import PRINT_PPI

    result = synthesize(2, SynthConfig(rig="cfpose", size=(320, 400), poses=2))
    rolled = result.rolled
    assert rolled.ppi == PRINT_PPI and rolled.image.dtype == np.uint8 and rolled.image.shape == rolled.mask.shape
    assert np.all(rolled.image[~rolled.mask] == 255) and rolled.image[rolled.mask].mean() < 200  # ridges dark inside
    ids = [m["id"] for m in result.minutiae["minutiae_3d"]]
    assert [m["id"] for m in rolled.minutiae] == ids == [m["id"] for m in result.minutiae["rolled_print"]["minutiae"]]
    xy = np.array([m["xy"] for m in rolled.minutiae])
    inside = rolled.mask[np.clip(np.rint(xy[:, 1]).astype(int), 0, rolled.mask.shape[0] - 1),
                         np.clip(np.rint(xy[:, 0]).astype(int), 0, rolled.mask.shape[1] - 1)]
    assert inside.mean() > 0.95
    # Near the pad centre the frontal shot (p1) sees the skin nearly flat: print -> photo is a similarity
    # without reflection, at the photo's pixels per mm, and the minutiae directions turn with it.
    frontal = {m["id"]: m for m in result.minutiae["views"]["p1"] if m["visible"]}
    centre = [m for m in result.minutiae["minutiae_3d"] if abs(m["skin_ab_mm"][1]) < 4.0 and m["id"] in frontal]
    assert len(centre) >= 5
    by_id = {m["id"]: m for m in rolled.minutiae}
    source = np.array([by_id[m["id"]]["xy"] for m in centre])
    target = np.array([frontal[m["id"]]["uv"] for m in centre])
    matrix, _ = cv2.estimateAffinePartial2D(source, target, method=cv2.LMEDS)
    scale = np.hypot(matrix[0, 0], matrix[1, 0])
    fitted = source @ matrix[:, :2].T + matrix[:, 2]
    camera = result.capture["p1"].camera
    photo_px_per_mm = camera.K[0, 0] / np.median([np.linalg.norm(camera.center - np.array(m["xyz"])) for m in centre])
    assert scale * rolled.px_per_mm == pytest.approx(photo_px_per_mm, rel=0.15)
    assert np.median(np.linalg.norm(fitted - target, axis=1)) < 0.3 * photo_px_per_mm  # within 0.3 mm
    turn = np.degrees(np.arctan2(matrix[1, 0], matrix[0, 0]))
    difference = [(frontal[m["id"]]["angle_deg"] - by_id[m["id"]]["angle_deg"] - turn + 180) % 360 - 180 for m in centre]
    assert np.median(np.abs(difference)) < 15
