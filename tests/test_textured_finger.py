"""Fingers of another make (experiments/textured_finger.py): the texture measured, the skin wrapped, the truth true."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from fingersplat3d.experiments.textured_finger import (RIDGE_PERIOD_MM, TexturedFinger, random_finger, skin_lookup,
                                                       skin_texture, textured_capture)

PERIOD_PX = 9.0


@pytest.fixture(scope="module")
def texture_file(tmp_path_factory) -> Path:
    """A finger texture like a contactless photo's: an oval of ridges 9 px apart on black, tip up."""
    rows, cols = np.mgrid[0:400, 0:360].astype(np.float64)
    inside = ((cols - 180) / 150) ** 2 + ((rows - 210) / 170) ** 2 < 1
    ridges = 0.5 + 0.2 * np.sin(2 * np.pi * rows / PERIOD_PX)
    image = np.where(inside, ridges, 0.0)
    path = tmp_path_factory.mktemp("texture") / "texture.png"
    cv2.imwrite(str(path), np.round(255 * image).astype(np.uint8))
    return path


def test_the_texture_is_measured_where_its_finger_is_and_scaled_to_a_ridge_period(texture_file):
    texture = skin_texture(texture_file)
    assert texture.px_per_mm == pytest.approx(PERIOD_PX / RIDGE_PERIOD_MM, rel=0.08)
    assert 40 <= texture.first_row < 100 and 320 < texture.last_row <= 380
    middle = (texture.first_row + texture.last_row) // 2
    assert texture.centre[middle] == pytest.approx(180, abs=2) and texture.half_width[middle] == pytest.approx(144, abs=6)
    assert texture.mean == pytest.approx(0.5, abs=0.02)


def test_the_skin_fades_to_its_mean_where_the_texture_grazes_or_ends(texture_file):
    texture = skin_texture(texture_file)
    along = np.linspace(3.0, 8.0, 200)
    pad, flat = skin_lookup(texture, along, np.zeros_like(along))
    assert pad.std() > 0.1 and not flat.any()  # the ridges on the pad's middle; no relief asked
    far_round, _ = skin_lookup(texture, along, np.full_like(along, 40.0))  # toward the nail
    beyond, _ = skin_lookup(texture, np.full(5, 500.0), np.zeros(5))  # past the texture's last row
    assert np.allclose(far_round, texture.mean) and np.allclose(beyond, texture.mean)
    grey, slopes = skin_lookup(texture, np.array([-50.0, 0.0, 1e6]), np.array([-1e6, 0.0, 1e6]), relief_mm=0.1)
    assert np.all(np.isfinite(grey)) and np.all(np.isfinite(slopes))


def test_ridges_of_a_relief_slope_across_them_as_high_as_they_are(texture_file):
    texture = skin_texture(texture_file)
    along = np.linspace(3.0, 8.0, 400)  # the test texture's ridges run round the finger: they slope along it
    _, low = skin_lookup(texture, along, np.zeros_like(along), relief_mm=0.05)
    _, high = skin_lookup(texture, along, np.zeros_like(along), relief_mm=0.1)
    assert np.abs(low[:, 1]).max() < 0.1 * np.abs(low[:, 0]).max()
    assert np.allclose(high, 2 * low)
    # a sine of amplitude h over a period p slopes at most 2 pi h / p: here h ~ half the relief
    assert 0.3 < np.abs(high[:, 0]).max() / (2 * np.pi * 0.05 / RIDGE_PERIOD_MM) < 2.0


def test_the_capture_holds_a_true_camera_depth_and_mask_in_every_view(texture_file):
    texture = skin_texture(texture_file)
    capture = textured_capture(random_finger(np.random.default_rng(3)), texture, size=(200, 160), seed=3)
    assert [v.name for v in capture.views] == ["v0", "v1", "v2"]
    for view in capture.views:
        assert view.image.shape == view.mask.shape == view.depth.shape == (160, 200)
        assert np.array_equal(np.isfinite(view.depth), view.mask) and 0.2 < view.mask.mean() < 0.8
        assert view.image[view.mask].mean() > view.image[~view.mask].mean() + 0.1
        assert np.all(view.depth[view.mask] > 30) and np.all(view.depth[view.mask] < 80)  # the ring is 54 mm away
    # The truth agrees with itself: the front view's skin seen by a side camera lands on that camera's depth.
    front, side = capture["v1"], capture["v2"]
    points = front.camera.depth_to_points(front.depth)[front.mask]
    uv, z = side.camera.project(points)
    col, row = np.rint(uv).astype(int).T
    inside = (col >= 0) & (col < 200) & (row >= 0) & (row < 160)
    seen = np.zeros(len(z), bool)
    seen[inside] = side.mask[row[inside], col[inside]]
    gap = np.abs(side.depth[row[seen], col[seen]] - z[seen])
    assert seen.mean() > 0.3 and np.median(gap) < 0.1  # mm: visible skin, and hidden skin lies behind it
    assert np.mean(gap < 0.3) > 0.6


def test_the_finger_is_the_shape_it_is_given():
    texture_free = TexturedFinger(width=16.0, pad_depth=8.0, nail_depth=8.0, pad_exponent=2.0, nail_exponent=2.0,
                                  taper=0.0, bend=0.0)
    from fingersplat3d.experiments.textured_finger import _surface

    vertices, triangles, along, around, (along_t, around_t) = _surface(texture_free)
    behind_cap = vertices[:, 0] > texture_free.cap + 1
    radius = np.hypot(vertices[behind_cap, 1], vertices[behind_cap, 2])
    assert np.allclose(radius, 8.0, atol=1e-6)  # a round section of the given width
    assert triangles.min() >= 0 and triangles.max() < len(vertices)
    ring = behind_cap & (np.abs(vertices[:, 0] - vertices[behind_cap, 0].max()) < 1e-9)
    assert np.abs(around[ring]).max() == pytest.approx(np.pi * 8.0, rel=0.02)  # round the section from the pad's middle
    assert along.min() == 0.0 and along.max() > texture_free.length
    off_pole = vertices[:, 0] > 0  # the pole's ring is one point: no way round it
    assert np.allclose(np.linalg.norm(along_t, axis=1), 1)
    assert np.allclose(np.linalg.norm(around_t[off_pole], axis=1), 1)
    assert np.allclose(along_t[behind_cap & ring], [1, 0, 0], atol=1e-6)  # along the straight, untapered finger
    assert np.allclose((around_t * vertices).sum(1)[behind_cap], 0, atol=1e-6)  # round the round section


@pytest.fixture(scope="module")
def labyrinth_file(tmp_path_factory) -> Path:
    """A finger texture with features of its own: noise band-passed at a 9 px period, ridges of one width that wind
    and end, on an oval on black."""
    rng = np.random.default_rng(0)
    noise = rng.normal(size=(400, 360)).astype(np.float32)
    band = cv2.GaussianBlur(noise, (0, 0), 0.15 * PERIOD_PX) - cv2.GaussianBlur(noise, (0, 0), 0.3 * PERIOD_PX)
    ridges = 0.5 + 0.2 * np.tanh(band / band.std())
    rows, cols = np.mgrid[0:400, 0:360]
    inside = ((cols - 180) / 150) ** 2 + ((rows - 210) / 170) ** 2 < 1
    path = tmp_path_factory.mktemp("labyrinth") / "texture.png"
    cv2.imwrite(str(path), np.round(255 * np.where(inside, ridges, 0.0)).astype(np.uint8))
    return path


def test_another_makes_finger_is_fused_from_its_photos_alone(labyrinth_file):
    """Three views of a finger this project did not draw (a texture of its own, a shape apart from fs3d synth's): the
    photos alone register within a degree and give depth within a few tenths of a millimetre (measured at 640x512,
    8 seeds: 0.16 degrees, 0.076 mm; tools/bench_textured.py)."""
    from fingersplat3d.experiments.geometry import score_geometry
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.scene import Capture

    capture = textured_capture(random_finger(np.random.default_rng(2)), skin_texture(labyrinth_file), size=(480, 384),
                               seed=2)
    blind = Capture(tuple(v.with_(camera=None, depth=None, mask=None) for v in capture.views), capture.metadata)
    scores = score_geometry(fuse(blind, FuseConfig(splat=None)), {v.name: v for v in capture.views})
    assert scores["registered_all"]
    assert scores["rotation_max_deg"] < 1.0 and scores["depth_mae_mm"] < 0.3
    # Split by a second view's backing: the skin two views see is measured from the photos and truer than the skin one
    # view alone sees, whose depth is the pointmap's guess; the whole view's figure lies between the two.
    two, one = scores["depth_two_views_mm"], scores["depth_one_view_mm"]
    assert 0 < two < scores["depth_mae_mm"] < one
