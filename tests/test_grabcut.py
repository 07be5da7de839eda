"""GrabCut coarse to fine (segment/grabcut.py): the cut at half the size, finished at the full size,
the given sure labels kept, small images cut once."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from fingersplat3d.segment.grabcut import COARSE_MIN_SIDE, _coarse_labels, _cut_once, _grab_cut


def _scene(size: tuple[int, int], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A skin-coloured ellipse with ridges on a grey desk with noise: ``(colour8, true mask)``."""
    height, width = size
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[:height, :width]
    truth = ((cols - 0.55 * width) / (0.3 * width)) ** 2 + ((rows - 0.5 * height) / (0.32 * height)) ** 2 < 1.0
    desk = np.array([190, 195, 200], np.float64) + 12.0 * rng.normal(size=(height, width, 3))
    ridges = 25.0 * np.sin(2 * np.pi * (cols + 0.3 * rows) / 7.0)[..., None]
    skin = np.array([150, 120, 110], np.float64) + ridges + 6.0 * rng.normal(size=(height, width, 3))
    colour = np.where(truth[..., None], skin, desk)
    return np.clip(colour, 0, 255).astype(np.uint8), truth


def _labels(truth: np.ndarray) -> np.ndarray:
    """The seeds the segmentation gives GrabCut: the border ring sure background, a core of the finger sure, the rest
    probable background."""
    labels = np.full(truth.shape, cv2.GC_PR_BGD, np.uint8)
    labels[cv2.erode(truth.view(np.uint8), np.ones((25, 25), np.uint8)).view(bool)] = cv2.GC_FGD
    labels[:4], labels[-4:], labels[:, :4], labels[:, -4:] = (cv2.GC_BGD,) * 4
    return labels


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return np.count_nonzero(a & b) / np.count_nonzero(a | b)


@pytest.mark.parametrize("size", [(240, 320), (241, 333)])
def test_coarse_to_fine_finds_the_finger_as_the_single_cut_does(size):
    colour8, truth = _scene(size)
    labels = _labels(truth)
    given = labels.copy()
    found = _grab_cut(colour8, labels)
    once = _cut_once(colour8, given.copy(), 5)
    assert found.shape == truth.shape and _iou(found, truth) > 0.97 and _iou(found, once) > 0.97
    # the outline within a couple of pixels of the true one, odd sizes too
    wrong = found ^ truth
    assert np.count_nonzero(wrong) < 2.0 * np.count_nonzero(cv2.morphologyEx(truth.view(np.uint8), cv2.MORPH_GRADIENT,
                                                                         np.ones((3, 3), np.uint8)))
    # the given sure labels are kept, and the labels left say what was found
    assert (labels[given == cv2.GC_BGD] == cv2.GC_BGD).all() and (labels[given == cv2.GC_FGD] == cv2.GC_FGD).all()
    assert np.array_equal(found, (labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD))


def test_a_small_image_is_cut_once_and_a_sure_line_a_pixel_wide_survives_the_coarse_labels():
    colour8, truth = _scene((COARSE_MIN_SIDE - 1, 2 * COARSE_MIN_SIDE))
    labels = _labels(truth)
    assert np.array_equal(_grab_cut(colour8, labels.copy()), _cut_once(colour8, labels.copy(), 5))
    labels = np.full((9, 12), cv2.GC_PR_FGD, np.uint8)
    labels[:, 5] = cv2.GC_BGD  # a column a pixel wide at an odd index
    labels[3, 3] = cv2.GC_FGD
    coarse = _coarse_labels(labels, (4, 6))
    assert (coarse[:, 2] == cv2.GC_BGD).all() and coarse[1, 1] == cv2.GC_FGD
    assert (coarse[:, [0, 4, 5]] == cv2.GC_PR_FGD).all()


def test_labels_that_leave_one_side_empty_at_half_size_are_cut_at_full_size():
    """A sure finger seed of one pixel: at half the size every pixel would be finger or every one background, and
    GrabCut cannot start without both; the cut falls back to the full size, as before."""
    colour8, truth = _scene((200, 260))
    labels = np.full(truth.shape, cv2.GC_PR_FGD, np.uint8)
    labels[:, :] = cv2.GC_BGD
    labels[100, 140] = cv2.GC_FGD
    found = _grab_cut(colour8, labels)
    assert found[100, 140] and np.count_nonzero(found) == 1
