"""The unseen skin: a finger's section carried round past the arc its views' clouds cover."""
import numpy as np
import pytest

from fingersplat3d.scene import Camera, look_at
from fingersplat3d.unseen_skin import EXTEND_DEG, SEEN_WITHIN_DEG, unseen_skin

RADIUS = 8.0
LENGTH = 40.0


def _cameras(azimuths_deg, distance=60.0, size=(320, 256), focal=500.0):
    """Cameras round the x axis (the finger's), at the given azimuths from +z toward +y."""
    cameras = []
    for azimuth in np.radians(azimuths_deg):
        eye = distance * np.array([0.0, np.sin(azimuth), np.cos(azimuth)])
        cameras.append(Camera.from_focal(focal, size[0], size[1], look_at(eye, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0])))
    return cameras


def _finger(azimuth_low_deg, azimuth_high_deg, count=40000, seed=0):
    """Points of a round finger along x (a cylinder ending in a half sphere at +x) between two azimuths."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-LENGTH / 2, LENGTH / 2 - RADIUS, count)
    phi = np.radians(rng.uniform(azimuth_low_deg, azimuth_high_deg, count))
    return np.column_stack([x, RADIUS * np.sin(phi), RADIUS * np.cos(phi)])


def _masks(cameras):
    """Each camera's silhouette of the whole finger (its points all round, projected and closed)."""
    import cv2

    whole = _finger(-180, 180, 200000, seed=1)
    cap = np.random.default_rng(2).normal(size=(40000, 3))
    cap = cap / np.linalg.norm(cap, axis=1, keepdims=True) * RADIUS
    cap = cap[cap[:, 0] > 0] + [LENGTH / 2 - RADIUS, 0.0, 0.0]
    masks = []
    for camera in cameras:
        uv, _ = camera.project(np.concatenate([whole, cap]))
        mask = np.zeros((camera.height, camera.width), np.uint8)
        pixel = np.round(uv).astype(int)
        inside = (pixel[:, 0] >= 0) & (pixel[:, 0] < camera.width) & (pixel[:, 1] >= 0) & (pixel[:, 1] < camera.height)
        mask[pixel[inside, 1], pixel[inside, 0]] = 1
        masks.append(cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8)).astype(bool))
    return masks


def _azimuths(points):
    return np.degrees(np.arctan2(points[:, 1], points[:, 2]))


def test_the_section_is_carried_round_past_the_seen_arc_and_no_further():
    cameras = _cameras([-25.0, 25.0])
    seen = _finger(-95.0, 95.0)
    skin = unseen_skin(seen, cameras, _masks(cameras))
    assert len(skin) > 500
    radius = np.hypot(skin.points[:, 1], skin.points[:, 2])
    assert np.all(np.abs(radius - RADIUS) < 0.05 * RADIUS)  # on the finger's own section
    beyond = np.abs(_azimuths(skin.points))
    assert beyond.min() > 95.0 - 3.0 and beyond.max() < 95.0 + EXTEND_DEG + 3.0  # next to the arc, within reach
    assert np.all(skin.points[:, 0] < LENGTH / 2 + 1.0) and np.all(skin.points[:, 0] > -LENGTH / 2 - 1.0)
    # each point continues one ring's run on one side of its arc, counted in cells from the arc's end
    assert skin.chain.shape == skin.steps.shape == (len(skin),) and skin.steps.min() >= 1
    assert np.all(skin.steps <= EXTEND_DEG / 2.0 + 1)
    for run in np.unique(skin.chain)[:20]:
        side = _azimuths(skin.points[skin.chain == run])
        assert np.all(side > 0) or np.all(side < 0)  # one side of the arc
    normals_radial = skin.points[:, 1:] / radius[:, None]
    assert np.allclose(np.linalg.norm(skin.normals, axis=1), 1.0, atol=1e-6)
    assert np.all(np.einsum("nk,nk->n", skin.normals[:, 1:], normals_radial) > 0.95)  # outward


def test_no_point_where_a_view_sees_the_skin_squarely():
    cameras = _cameras([-25.0, 25.0])
    skin = unseen_skin(_finger(-95.0, 95.0), cameras, _masks(cameras))
    for camera in cameras:
        toward = camera.center - skin.points
        cosine = np.einsum("nk,nk->n", skin.normals, toward) / np.linalg.norm(toward, axis=1)
        assert np.all(cosine <= np.cos(np.radians(SEEN_WITHIN_DEG)) + 1e-9)


def test_a_ring_seen_all_round_needs_nothing_and_too_few_points_give_nothing():
    cameras = _cameras([-25.0, 25.0])
    masks = _masks(cameras)
    assert len(unseen_skin(_finger(-180.0, 180.0), cameras, masks)) == 0
    assert len(unseen_skin(_finger(-95.0, 95.0, count=50), cameras, masks)) == 0
    assert len(unseen_skin(np.full((1000, 3), np.nan), cameras, masks)) == 0


@pytest.mark.parametrize("arc", [60.0, 110.0])
def test_an_arc_too_short_to_draw_its_section_is_not_completed(arc):
    cameras = _cameras([0.0])
    skin = unseen_skin(_finger(-arc / 2, arc / 2), cameras, _masks(cameras))
    assert len(skin) == 0


def test_a_run_of_unseen_skin_is_kept_up_to_its_first_cell_off_the_finger_and_only_when_it_joins_the_arc():
    from fingersplat3d.splat.stage import UNSEEN_START_CELLS, _joined

    chain = np.array([0, 0, 0, 0, 1, 1, 1, 2, 2])
    steps = np.array([3, 1, 2, 4, 1, 2, 3, UNSEEN_START_CELLS + 1, UNSEEN_START_CELLS + 2])
    on_finger = np.array([True, True, False, True, True, True, True, True, True])
    kept = _joined(on_finger, chain, steps)
    # run 0 stops at its step 2 (off the finger): step 1 only; run 1 whole; run 2 starts too far out: none
    assert kept.tolist() == [False, True, False, False, True, True, True, False, False]
    assert _joined(np.zeros(0, bool), np.zeros(0, int), np.zeros(0, int)).shape == (0,)


def test_a_left_out_view_of_the_sample_is_covered_where_the_fitted_views_see_nothing():
    from pathlib import Path

    from fingersplat3d.cli.common import named_captures
    from fingersplat3d.pipeline import FuseConfig, cloud_of_views, fuse, unseen_skin_of
    from fingersplat3d.splat.config import preset
    from fingersplat3d.splat.novel import opacity_share, render_views
    from fingersplat3d.splat.stage import run_splat_stage

    (_, capture), = named_captures([Path(__file__).resolve().parents[1] / "data_samples" / "uwa_seed0"])
    result = fuse(capture, FuseConfig(splat=None))
    views, left_out, train = result.capture.views, 0, [1, 2]
    config = preset("fast", iterations=8)
    cloud = cloud_of_views(result, train)
    unseen = unseen_skin_of(cloud, views, result.cameras, train, config)
    assert unseen is not None and len(unseen) > 100

    mask = views[left_out].mask

    def hole(skin):
        stage = run_splat_stage(views, result.cameras, train, cloud, config, depths=result.depths, unseen=skin)
        render = render_views(stage.gaussians, [("left out", result.cameras[left_out])])[0]
        return render, stage

    (bare, plain), (covered, completed) = hole(None), hole(unseen)
    without, with_skin = (float(((r.alpha < 0.5) & mask).sum() / mask.sum()) for r in (bare, covered))
    added = completed.report["unseen_skin_gaussians"]
    assert plain.report["unseen_skin_gaussians"] == 0 and added > 0
    assert not plain.unseen.any() and int(completed.unseen.sum()) == added and bool(completed.unseen[-added:].all())
    assert with_skin < without - 0.02
    # the completion is the model's last rows (what `fs3d eval quality` splits its scores by): the holes it fills are
    # rendered mostly from them, the skin both models cover mostly from the fitted Gaussians
    share = opacity_share(completed.gaussians, completed.unseen, result.cameras[left_out])
    filled = mask & (bare.alpha < 0.5) & (covered.alpha >= 0.5)
    both = mask & (bare.alpha >= 0.5) & (covered.alpha >= 0.5)
    assert filled.sum() > 100 and (share[filled] >= 0.5).mean() > 0.7
    assert (share[both] < 0.5).mean() > 0.8
