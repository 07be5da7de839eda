"""Ridge texture: the period from the ridge area only, glints removed, a band-pass without halos."""
import numpy as np
import pytest

from fingersplat3d.align.correspond.texture import estimate_ridge_period, ridge_texture, suppress_glints


def striped_finger(period_tip=8.0, period_body=20.0, rows=160, cols=480, radius=50):
    """A horizontal capsule cut by the right border, tip at the left: ridges near the tip, wrinkles behind."""
    v, u = np.mgrid[:rows, :cols].astype(np.float64)
    tip = 60.0
    mask = ((np.abs(v - rows / 2) <= radius) & (u >= tip)) | ((u - tip) ** 2 + (v - rows / 2) ** 2 <= radius ** 2)
    ridge_area = u < tip + 1.2 * 2 * radius
    stripes = np.where(ridge_area, np.sin(2 * np.pi * v / period_tip), np.sin(2 * np.pi * (u + v) / period_body))
    image = np.where(mask, 0.5 + 0.2 * stripes, 0.02).astype(np.float32)
    return image, mask


def test_period_comes_from_the_ridges_near_the_tip_not_the_wrinkles_behind():
    image, mask = striped_finger()
    assert abs(estimate_ridge_period(image, mask) - 8.0) < 0.3


def test_glints_are_replaced_and_ridges_kept():
    image, mask = striped_finger()
    speckled = image.copy()
    rng = np.random.default_rng(0)
    import cv2

    rows, cols = np.nonzero(cv2.erode(mask.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0)  # off the outline
    pick = rng.choice(len(rows), 30, replace=False)
    speckled[rows[pick], cols[pick]] = 1.0
    cleaned = suppress_glints(speckled, mask)
    assert np.abs(cleaned[rows[pick], cols[pick]] - image[rows[pick], cols[pick]]).max() < 0.15
    untouched = np.ones_like(mask)
    untouched[rows[pick], cols[pick]] = False
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            untouched[np.clip(rows[pick] + dy, 0, mask.shape[0] - 1), np.clip(cols[pick] + dx, 0, mask.shape[1] - 1)] = False
    assert np.mean(cleaned[untouched & mask] == speckled[untouched & mask]) > 0.99


def test_band_pass_has_unit_rms_inside_nothing_outside_and_no_edge_halo():
    image, mask = striped_finger()
    texture = ridge_texture(image, mask, 8.0)
    assert np.all(texture[~mask] == 0) and np.isfinite(texture).all()
    rms = float(np.sqrt(np.mean(texture[mask] ** 2)))
    assert 0.7 < rms < 1.3
    flat = np.where(mask, 0.5, 0.02).astype(np.float32)  # a textureless finger: no edge response to lock onto
    assert np.abs(ridge_texture(flat, mask, 8.0)[mask]).max() < 1e-2


@pytest.mark.parametrize("angle_deg", [0.0, 30.0, 115.0])
def test_structure_products_point_across_straight_ridges(angle_deg):
    """Straight ridges: the structure tensor's main axis runs across them and is one-directional (coherence ~1);
    over a mask, the flat grey outside does not dilute the tensor at the rim."""
    from fingersplat3d.structure_tensor import structure_products

    v, u = np.mgrid[0:120, 0:140].astype(np.float64)
    across = np.array([np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))])
    texture = np.cos(2 * np.pi * (u * across[0] + v * across[1]) / 9.0)
    uu, uv, vv = np.moveaxis(structure_products(texture, 6.0), -1, 0)
    found = 0.5 * np.arctan2(2 * uv, uu - vv)[60, 70]
    assert abs(np.sin(found - np.radians(angle_deg))) < 0.035  # central differences: ~1 degree off at 9 px a ridge
    coherence = np.hypot(uu - vv, 2 * uv) / (uu + vv)
    assert coherence[30:90, 30:110].min() > 0.98
    mask = np.zeros_like(texture)
    mask[:, :70] = 1.0
    masked = structure_products(texture * mask, 6.0, mask)
    plain = structure_products(texture * mask, 6.0)
    rim = (slice(40, 80), 66)
    assert (masked[rim][:, [0, 2]].sum(1) > 1.2 * plain[rim][:, [0, 2]].sum(1)).all()
    assert structure_products(texture.astype(np.float32), 6.0).dtype == np.float32
