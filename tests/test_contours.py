"""Silhouette contours as correspondences: on the true model they sit on the outline, on the side a view sees."""
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from fingersplat3d.align.correspond.contours import contour_correspondences
from fingersplat3d.io.capture import read_capture
from fingersplat3d.segment.silhouette import silhouette_frame

SAMPLE = Path(__file__).resolve().parents[1] / "data_samples" / "uwa_seed0"


def _truth():
    capture = read_capture(SAMPLE)
    views = [capture[name] for name in ("left", "center", "right")]
    alignment = SimpleNamespace(depths=[v.depth for v in views], focals=[float(v.camera.K[0, 0]) for v in views],
                                world_to_cam=[v.camera.world_to_cam for v in views])
    return views, alignment


def _in_b(views, a, b, uv_a):
    """Where view b sees view a's pixels ``uv_a`` on a's own depth (nearest pixel)."""
    depth = views[a].depth[np.rint(uv_a[:, 1]).astype(int), np.rint(uv_a[:, 0]).astype(int)]
    return views[b].camera.project(views[a].camera.unproject(uv_a, depth))[0]


def _across_error(views, a, b, uv_a, uv_b, information):
    projected = _in_b(views, a, b, uv_a)
    normal = np.array([np.linalg.eigh(i)[1][:, -1] for i in information])
    return np.abs(np.einsum("ni,ni->n", projected - uv_b, normal))


def test_on_the_true_model_a_side_view_reaches_the_front_outline_on_its_own_side_only():
    views, alignment = _truth()
    masks = [v.mask for v in views]
    uv_a, uv_b, information = contour_correspondences(alignment, masks, 0, 1, period_px=8.0)
    assert len(uv_a) >= 10
    assert np.median(_across_error(views, 0, 1, uv_a, uv_b, information)) < 1.0
    frame = silhouette_frame(masks[1])
    _, t = frame.coordinates(uv_b)
    sides = np.sign(t - np.median(frame.sections.centre))
    assert abs(sides.sum()) == len(sides)  # one side: the left camera does not see the front camera's far rim
    # The two side cameras see opposite rims of the front view.
    other, _, _ = contour_correspondences(alignment, masks, 2, 1, period_px=8.0)
    _, t_other = frame.coordinates(contour_correspondences(alignment, masks, 2, 1, period_px=8.0)[1])
    assert len(other) >= 10 and np.sign(np.median(t_other - np.median(frame.sections.centre))) == -sides[0]
    assert np.allclose(np.trace(information, axis1=1, axis2=2), 1.0)  # unit weight across the edge, none along it


def test_on_the_true_model_the_targets_sit_on_the_outline_not_inside_it():
    """The surface's outermost point lands on the outline itself, as much beyond it as short of it: a target a pixel
    inside (stop 72 and before) set the side cameras 0.7-1.0 degrees off with exact matches."""
    views, alignment = _truth()
    masks = [v.mask for v in views]
    for a, b in ((0, 1), (2, 1), (1, 0), (1, 2), (0, 2), (2, 0)):
        uv_a, uv_b, _ = contour_correspondences(alignment, masks, a, b, period_px=8.0)
        projected = _in_b(views, a, b, uv_a)
        frame = silhouette_frame(masks[b])
        stations, t = frame.coordinates(uv_b)
        outward = np.sign(t - frame.sections.at(stations)[1])[:, None] * frame.normal
        beyond = np.einsum("ni,ni->n", projected - uv_b, outward)  # > 0: a's point outside b's outline
        assert len(uv_a) >= 10 and abs(np.median(beyond)) < 0.25, (a, b, np.median(beyond))  # measured within 0.06 px


def test_a_relief_too_deep_or_too_flat_is_told_by_the_outline():
    views, alignment = _truth()
    masks = [v.mask for v in views]
    depth = views[0].depth
    median = np.nanmedian(depth)

    def error(relief):
        changed = SimpleNamespace(**{**vars(alignment), "depths": [median + relief * (depth - median)] + alignment.depths[1:]})
        uv_a, uv_b, information = contour_correspondences(changed, masks, 0, 1, period_px=8.0)
        return np.median(_across_error([views[0].with_(depth=changed.depths[0])] + views[1:], 0, 1, uv_a, uv_b, information))

    true = error(1.0)
    assert error(1.6) > 3 * true and error(0.7) > 2 * true  # measured: 1.0 px, 4.0 px, 2.9 px


def test_no_surface_or_no_outline_gives_none():
    views, alignment = _truth()
    masks = [v.mask for v in views]
    empty = SimpleNamespace(**{**vars(alignment), "depths": [np.full_like(alignment.depths[0], np.nan)] + alignment.depths[1:]})
    assert len(contour_correspondences(empty, masks, 0, 1, period_px=8.0)[0]) == 0
    assert len(contour_correspondences(alignment, [masks[0], np.zeros_like(masks[1]), masks[2]], 0, 1, period_px=8.0)[0]) == 0


def test_the_registration_adds_contours_from_three_views_or_two_with_the_focal_held():
    from fingersplat3d.align.register import (CONTOUR_MIN_VIEWS, CONTOUR_MIN_VIEWS_FOCAL_HELD, RegistrationConfig,
                                              _contours, _Prepared)
    from fingersplat3d.align.solve.global_opt import GlobalAlignConfig

    views, alignment = _truth()
    prepared = _Prepared(textures=[], masks=[v.mask for v in views], grays=[], period=8.0)
    three = _contours(SimpleNamespace(**vars(alignment), aligned=[True, True, True]), prepared, RegistrationConfig())
    assert CONTOUR_MIN_VIEWS == 3 and len(three) >= 4  # each side camera against the front outline, and back
    assert all(np.all(pair.information_a == 0) for pair in three)  # one way: a -> b
    two = _contours(SimpleNamespace(**vars(alignment), aligned=[True, True, False]), prepared, RegistrationConfig())
    off = _contours(SimpleNamespace(**vars(alignment), aligned=[True, True, True]), prepared,
                    RegistrationConfig(contour_weight=0.0))
    assert two == [] and off == []
    # With the focal held (--focal-px, EXIF) two views' turn no longer slides with it: their contours join.
    held = RegistrationConfig(global_align=GlobalAlignConfig(optimize_focal=False))
    two_held = _contours(SimpleNamespace(**vars(alignment), aligned=[True, True, False]), prepared, held)
    assert CONTOUR_MIN_VIEWS_FOCAL_HELD == 2 and len(two_held) == 2  # left against the front outline, and back
    assert {(pair.a, pair.b) for pair in two_held} == {(0, 1), (1, 0)}
    # Two photos from one place are still one viewpoint.
    same_place = SimpleNamespace(**{**vars(alignment), "world_to_cam": [alignment.world_to_cam[1]] * 3},
                                 aligned=[True, True, False])
    assert _contours(same_place, prepared, held) == []


def test_the_alignment_keeps_every_contour_row_though_its_target_lies_off_the_other_pointmap():
    """A target on the outline is where b's pointmap may hold no depth; the rows are one-way (b's end weighs nothing),
    so the alignment keeps them all, where two-way matches there are dropped."""
    from fingersplat3d.align.register import RegistrationConfig, _contours, _Prepared
    from fingersplat3d.align.solve.global_opt import _correspondences

    views, alignment = _truth()
    prepared = _Prepared(textures=[], masks=[v.mask for v in views], grays=[], period=8.0)
    pairs = _contours(SimpleNamespace(**vars(alignment), aligned=[True, True, True]), prepared, RegistrationConfig())
    rows = sum(len(pair.uv_a) for pair in pairs)
    off_b = sum(int((~np.isfinite(views[p.b].depth[np.rint(p.uv_b[:, 1]).astype(int), np.rint(p.uv_b[:, 0]).astype(int)])).sum())
                for p in pairs)
    assert off_b > 0  # some targets lie just beyond b's depth
    kept = _correspondences(alignment.depths, pairs, [True] * 3)
    assert len(kept.uv_a) == rows and np.isfinite(kept.z_b).all()
    two_way = [replace(pair, information_a=pair.information_b) for pair in pairs]
    assert len(_correspondences(alignment.depths, two_way, [True] * 3).uv_a) < rows
