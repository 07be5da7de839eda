"""Pairwise pointmaps -> global-alignment input: exact pointmaps give the true relative pose and real correspondences."""
from pathlib import Path

import numpy as np
import pytest

from fingersplat3d.align.register import RegistrationConfig
from fingersplat3d.align.solve.global_opt import GlobalAlignConfig, global_align
from fingersplat3d.align.solve.pointmap_pairs import register_pointmap_pair
from fingersplat3d.eval import relative_rotation_errors
from fingersplat3d.io import read_capture
from fingersplat3d.pipeline import FuseConfig, fuse
from fingersplat3d.pointmaps import PairPointmaps, Pointmap, register_backend
from fingersplat3d.scene import Camera, Capture, View

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def capture():
    """The 640x512 sample at half resolution (every other pixel; the principal point moves 0.25 px)."""
    full = read_capture(ROOT / "data_samples" / "uwa_seed0")
    views = []
    for view in full.views:
        image, mask, depth = view.image[::2, ::2], view.mask[::2, ::2], view.depth[::2, ::2]
        camera = Camera.from_focal(view.camera.K[0, 0] / 2, image.shape[1], image.shape[0], view.camera.world_to_cam)
        views.append(View(view.name, image, mask, camera, depth))
    return Capture(tuple(views), full.metadata)


def _own_points(view) -> np.ndarray:
    height, width = view.depth.shape
    v, u = np.mgrid[:height, :width]
    K = view.camera.K
    depth = view.depth
    return np.stack([(u - K[0, 2]) / K[0, 0] * depth, (v - K[1, 2]) / K[1, 1] * depth, depth], -1).astype(np.float32)


def _own(view, index) -> Pointmap:
    points = _own_points(view)
    confidence = np.where(np.isfinite(points).all(-1), 3.0, 0.0).astype(np.float32)
    return Pointmap(index, points, confidence, float(view.camera.K[0, 0]))


def _pair(capture, i, j, scale) -> PairPointmaps:
    """Exact X^{i,i}, X^{j,i} in a pair frame scaled by ``scale`` (as a network's own scale)."""
    vi, vj = capture.views[i], capture.views[j]
    j_to_i = vi.camera.world_to_cam @ np.linalg.inv(vj.camera.world_to_cam)
    points_j = _own_points(vj) @ j_to_i[:3, :3].T.astype(np.float32) + j_to_i[:3, 3].astype(np.float32)
    conf = lambda p: np.where(np.isfinite(p).all(-1), 2.0, 0.0).astype(np.float32)  # noqa: E731
    return PairPointmaps(i, j, scale * _own_points(vi), scale * points_j, conf(_own_points(vi)), conf(points_j))


@pytest.mark.parametrize("symmetric", [True, False])
def test_exact_pointmaps_give_the_true_pose_and_visible_correspondences(capture, symmetric):
    a, b = 0, 1
    views = capture.views
    result = register_pointmap_pair(_own(views[a], a), _own(views[b], b), _pair(capture, a, b, 0.37),
                                    _pair(capture, b, a, 2.5) if symmetric else None,
                                    mask_a=views[a].mask, mask_b=views[b].mask, rng=0)
    assert result.ok, result.reason
    truth = views[a].camera.world_to_cam @ np.linalg.inv(views[b].camera.world_to_cam)
    assert abs(result.b_to_a.scale - 1) < 1e-6
    assert np.allclose(result.b_to_a.rotation, truth[:3, :3], atol=1e-6)
    assert np.allclose(result.b_to_a.translation, truth[:3, 3], atol=1e-4 * np.linalg.norm(truth[:3, 3]))
    assert result.residual < 1e-6
    pairs = result.correspondences
    assert (pairs.a, pairs.b) == (a, b) and np.allclose(pairs.b_to_a, truth, atol=1e-4)
    assert 500 < len(pairs.weight) <= (3000 if symmetric else 1500) and (pairs.weight > 0).all()
    # Each correspondence is the same surface point: b's pixel, moved to a and projected, lands where a sees it.
    # One side of each correspondence is a pixel centre (where the point came from), the other a projection.
    from_b = np.all(pairs.uv_b == np.round(pairs.uv_b), axis=1)
    assert from_b.sum() > 50 and (symmetric == ((~from_b).sum() > 50))
    groups = ((pairs.uv_b[from_b], pairs.uv_a[from_b], b, a), (pairs.uv_a[~from_b], pairs.uv_b[~from_b], a, b))
    for uv_here, uv_there, here, there in groups[:2 if symmetric else 1]:
        points = _own_points(views[here])[uv_here[:, 1].astype(int), uv_here[:, 0].astype(int)]
        move = views[there].camera.world_to_cam @ np.linalg.inv(views[here].camera.world_to_cam)
        moved = points @ move[:3, :3].T + move[:3, 3]
        projected = moved[:, :2] / moved[:, 2:] * views[there].camera.K[0, 0] + views[there].camera.K[:2, 2]
        assert np.median(np.linalg.norm(projected - uv_there, axis=1)) < 1e-3
        seen = views[there].depth[np.round(uv_there[:, 1]).astype(int), np.round(uv_there[:, 0]).astype(int)]
        gap = np.abs(seen - moved[:, 2]) / moved[:, 2]  # 0 where the point is what the other view sees there
        assert np.median(gap) < 1e-3 and gap.max() < 0.025  # none hidden behind the finger (its thickness: ~12 %)


def test_pointmaps_of_different_scenes_are_refused(capture):
    views = capture.views
    pair = _pair(capture, 0, 1, 1.0)
    rng = np.random.default_rng(0)  # view 1's points scattered in their bounding box: no rigid motion explains them
    finite = pair.points_j[np.isfinite(pair.points_j).all(-1)]
    scattered = rng.uniform(finite.min(0), finite.max(0), pair.points_j.shape).astype(np.float32)
    wrong = PairPointmaps(0, 1, pair.points_i, np.where(np.isfinite(pair.points_j), scattered, np.nan),
                          pair.confidence_i, pair.confidence_j)
    result = register_pointmap_pair(_own(views[0], 0), _own(views[1], 1), wrong)
    assert not result.ok and "disagree" in result.reason


def test_unrelated_pointmaps_fail_without_raising(capture):
    views = capture.views
    pair = _pair(capture, 0, 1, 1.0)
    flat = np.zeros_like(pair.points_i)
    flat[..., 2] = 5.0  # all points coincide: no similarity
    broken = PairPointmaps(0, 1, flat, pair.points_j, pair.confidence_i, pair.confidence_j)
    result = register_pointmap_pair(_own(views[0], 0), _own(views[1], 1), broken)
    assert not result.ok and result.correspondences is None and "do not align" in result.reason


class _GroundTruthPairs:
    """A pairwise backend that returns exact pointmaps (each pair in its own arbitrary scale)."""

    name = "groundtruth-pairs"

    def __init__(self, capture):
        self.capture = capture

    def predict_views(self, views):
        return [_own(view, index) for index, view in enumerate(views)]

    def predict_pairs(self, views, pairs):
        return [_pair(self.capture, i, j, 0.5 + 0.1 * (i + 2 * j)) for a, b in pairs for i, j in ((a, b), (b, a))]


def test_global_alignment_from_pairwise_pointmaps_recovers_the_cameras(capture):
    views = capture.views
    own = [_own(view, index) for index, view in enumerate(views)]
    pairs = []
    for a, b in ((0, 1), (0, 2), (1, 2)):
        result = register_pointmap_pair(own[a], own[b], _pair(capture, a, b, 0.8), _pair(capture, b, a, 1.3),
                                        mask_a=views[a].mask, mask_b=views[b].mask, rng=a + b)
        pairs.append(result.correspondences)
    alignment = global_align([p.depth for p in own], [p.focal for p in own], pairs,
                             GlobalAlignConfig(polish_iterations=60, polish_rounds=1))
    assert all(alignment.aligned)
    errors = relative_rotation_errors(alignment.world_to_cam, [v.camera.world_to_cam for v in views])
    assert max(errors) < 1.0  # degrees


@pytest.mark.slow
def test_fuse_aligns_views_from_pairwise_pointmaps(capture):
    register_backend("groundtruth-pairs", lambda: _GroundTruthPairs(capture))
    config = FuseConfig(backend="groundtruth-pairs", splat=None,
                        registration=RegistrationConfig(global_align=GlobalAlignConfig(iterations=40, polish_iterations=20)))
    result = fuse(capture, config)
    assert all(record["method"] == "pointmaps" and record["ok"] for record in result.report["pairs"])
    assert result.report["alignment"]["ok"]
    errors = relative_rotation_errors([c.world_to_cam for c in result.cameras], [v.camera.world_to_cam for v in capture.views])
    assert max(errors) < 1.5  # degrees (measured 0.6-0.7); the 45-degree pairs of the minutiae path are 3-7 degrees off (README)
