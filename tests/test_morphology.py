"""The one disc of the masks' morphology (fingersplat3d.segment.morphology)."""
import numpy as np
import pytest

from fingersplat3d.segment.morphology import dilated, disc, eroded, outline


@pytest.mark.parametrize("radius", [0, 1, 2, 5, 12])
def test_disc_is_a_symmetric_disc_of_its_radius(radius):
    element = disc(radius)
    assert element.shape == (2 * radius + 1,) * 2 and element.dtype == np.uint8
    assert element[radius, radius] == 1 and element[radius].all() and element[:, radius].all()
    assert np.array_equal(element, element[::-1]) and np.array_equal(element, element[:, ::-1])
    if radius >= 2:  # round: the corners are left out
        assert element[0, 0] == 0 and element[-1, -1] == 0
        assert abs(int(element.sum()) - np.pi * (radius + 0.5) ** 2) < 0.2 * element.size


def test_a_negative_radius_is_refused():
    with pytest.raises(ValueError):
        disc(-1)


def test_eroded_and_dilated_move_a_square_by_the_radius():
    mask = np.zeros((60, 60), bool)
    mask[20:40, 20:40] = True
    for radius in (0, 1, 3):
        inner, outer = eroded(mask, radius), dilated(mask, radius)
        assert inner.dtype == bool and outer.dtype == bool
        assert inner.sum() == (20 - 2 * radius) ** 2  # a square's sides move in by the radius
        rows = np.flatnonzero(outer[:, 30])
        assert (rows.min(), rows.max()) == (20 - radius, 39 + radius)
        assert (inner <= mask).all() and (mask <= outer).all()
    assert eroded(mask, 3, iterations=2).sum() == (20 - 12) ** 2


def test_a_mask_at_the_frame_is_not_eaten_from_it():
    mask = np.zeros((30, 30), bool)
    mask[:, :15] = True
    assert eroded(mask, 2)[:, 0].all()


def test_outline_is_the_8_connected_rim_and_not_the_frame():
    mask = np.zeros((40, 40), bool)
    mask[10:30, 5:25] = True
    rim = outline(mask)
    assert rim.dtype == bool and (rim <= mask).all()
    assert rim.sum() == 4 * 20 - 4  # a square's one-pixel rim
    assert not rim[11:29, 6:24].any()
    disk = np.hypot(*np.mgrid[-20:21, -20:21]) <= 15
    inner = disk & ~outline(disk)  # what is left has all eight neighbours in the disc: the rim's diagonal steps are in it
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            assert np.roll(np.roll(disk, dy, 0), dx, 1)[inner].all()
    assert (disk & ~eroded(disk, 1)).sum() < outline(disk).sum()  # the cross of disc(1) leaves diagonal steps out
    touching = np.zeros((20, 20), bool)
    touching[:, :8] = True
    assert not outline(touching)[:, 0].any() and outline(touching)[:, 7].all()
    assert not outline(np.zeros((5, 5), bool)).any()
