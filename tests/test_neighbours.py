"""A neighbouring finger joined to the finger's mask is cut away; a mask of one finger comes back to the bit."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from fingersplat3d.segment.masks import finger_mask, mask_iou
from fingersplat3d.segment.neighbours import one_finger

HEIGHT, WIDTH = 256, 320


def finger(top: int, bottom: int, tip: int = 40, slope: float = 0.0) -> np.ndarray:
    """A finger pointing left, cut by the right border: a rectangle whose left end is a half disc, its edges
    tilted by ``slope`` pixels per column."""
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    shift = slope * (cols - WIDTH / 2)
    top_edge, bottom_edge = top + shift, bottom + shift
    radius = 0.5 * (bottom - top)
    centre_row = 0.5 * (top_edge + bottom_edge)
    body = (cols >= tip + radius) & (rows >= top_edge) & (rows <= bottom_edge)
    cap = (cols - tip - radius) ** 2 + (rows - centre_row) ** 2 <= radius ** 2
    return body | cap


@pytest.mark.parametrize("mask", [
    finger(60, 180),
    finger(60, 180, slope=0.08),
    finger(-40, 200),  # cut along its side by the frame
    finger(60, 180, tip=-100),  # a crop: no tip in the frame
    np.zeros((HEIGHT, WIDTH), bool),
    np.ones((HEIGHT, WIDTH), bool),
], ids=["finger", "tilted", "side-cut", "no tip", "empty", "full"])
def test_a_mask_of_one_finger_comes_back_to_the_bit(mask):
    rng = np.random.default_rng(0)
    ragged = mask.copy()
    if mask.any() and not mask.all():  # an outline a pixel ragged, as found masks are
        edge = mask & ~cv2.erode(mask.view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
        ragged[edge & (rng.random(mask.shape) < 0.3)] = False
    assert np.array_equal(one_finger(ragged), ragged)


def test_a_neighbour_touching_near_the_frame_is_cut_away():
    """The neighbour below, cut by the frame's bottom to a strip, touches the finger right of column 200 (a seam no
    opening parts: discs straddle it); left of it they are apart, the finger's outline is clear there and gives the
    line it is cut along."""
    main = finger(96, 216, slope=0.02)
    neighbour = finger(222, 400, tip=70) & ~main
    touching = main | neighbour
    touching[210:224, 200:] = True  # the seam closed where they touch
    kept = one_finger(touching)
    assert mask_iou(kept, main) > 0.98
    assert np.count_nonzero(kept & neighbour) < 0.02 * np.count_nonzero(neighbour)


def test_a_neighbour_joined_by_a_neck_is_cut_away_whole():
    """A neighbour as wide as the finger, joined through a neck: the opening parts them; the larger is kept."""
    main = finger(20, 130)
    neighbour = finger(150, 240, tip=120)
    joined = main | neighbour
    joined[125:155, 250:262] = True
    kept = one_finger(joined)
    assert mask_iou(kept, main) > 0.97 and not (kept & neighbour).any()


@pytest.fixture(scope="module")
def rendered_pair():
    """Two ``fs3d synth`` fingers at 320x256 (rendered once for the module)."""
    from fingersplat3d.synth import SynthConfig, synthesize

    return tuple(synthesize(seed, SynthConfig(size=(320, 256))).capture for seed in (1, 4))


def with_neighbour_below(view, other, hidden_px: int, scene: np.ndarray | None = None) -> np.ndarray:
    """``view``'s photo with ``other``'s finger drawn below its finger, its top ``hidden_px`` hidden behind the
    finger's rim; elsewhere ``scene`` (None: ``other``'s own photo, its dark background)."""
    size = view.mask.shape[::-1]
    rows, other_rows = np.nonzero(view.mask)[0], np.nonzero(other.mask)[0]
    below = np.float32([[1, 0, 0], [0, 1, int(rows.max() - other_rows.min() - hidden_px)]])
    shifted = cv2.warpAffine(other.image, below, size)
    if scene is not None:
        shifted = np.where(cv2.warpAffine(other.mask.view(np.uint8), below, size).view(bool), shifted, scene)
    return np.where(view.mask, view.image, shifted).astype(np.float32)


@pytest.mark.parametrize("background", ["dark", "desk"])
def test_a_rendered_neighbour_behind_the_finger_is_left_out_of_its_mask(rendered_pair, background):
    """``fs3d synth`` fingers: another finger below, its top 5 px hidden behind the finger's rim. The mask held both
    (IoU with the finger 0.80-0.84); measured now 0.987-0.998 where their outlines part over a quarter of the finger,
    as in the centre view (docs/measurements.md, "A neighbouring finger in the frame")."""
    from fingersplat3d.experiments.backgrounds import bright_desk

    finger_view, other = (capture["center"] for capture in rendered_pair)
    if background == "dark":
        scene = np.full(finger_view.image.shape, 0.02, np.float32)
    else:
        scene = bright_desk(finger_view.image.shape + (3,), np.random.default_rng(1)).mean(axis=2).astype(np.float32)
    found = finger_mask(with_neighbour_below(finger_view, other, 5, scene), name="center")
    assert mask_iou(found, finger_view.mask) > 0.97


def test_a_dim_finger_beside_a_brighter_neighbour_is_found(rendered_pair):
    """A finger whose shaded flank is as dim as a neighbour below it is bright: the first split of the histogram falls
    between the skins, and the class taken for the background holds skin too (it was refused as "no finger found").
    That class is split again where the skin does not stand out from it, and the neighbour joined to the mask is cut
    away (measured IoU 0.994; docs/measurements.md, "A neighbouring finger in the frame"). A noise-only image still
    has no finger (tests/test_segment.py): its dark class is one level with a tail, not two."""
    finger_view, other = (capture["left"] for capture in rendered_pair)
    found = finger_mask(with_neighbour_below(finger_view, other, 10), name="left")
    assert mask_iou(found, finger_view.mask) > 0.97
