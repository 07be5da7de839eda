"""Contact-like prints, NIST's tools on them (nbis-py), and verification error rates."""
import numpy as np
import pytest

from fingersplat3d.align.correspond.texture import estimate_ridge_period
from fingersplat3d.errors import InputError
from fingersplat3d.eval.contact import MAX_SIZE, TARGET_PERIOD_PX, ContactImage, contact_like
from fingersplat3d.eval.verification import det_curve, equal_error_rate, error_rates, fnmr_at_fmr, fmr_resolution
from fingersplat3d.synth import SynthConfig, synthesize


@pytest.fixture(scope="module")
def shots():
    """Two synthetic fingers, two poses each (the CFPose-like rig: rolled and pitched shots)."""
    return {seed: synthesize(seed, SynthConfig(rig="cfpose", size=(384, 480), poses=2)).capture for seed in (0, 1)}


def test_print_is_upright_dark_ridged_white_backed_and_at_500_ppi(uwa640):
    view = uwa640.views[1]  # the finger points left in the photo
    contact = contact_like(view.image, view.mask)
    image = contact.image
    assert image.dtype == np.uint8 and image.ndim == 2
    assert image[0].min() == 255 and image[:, 0].min() == 255  # white margin
    inked = image < 255
    rows = np.nonzero(inked.any(1))[0]
    top, bottom = inked[rows[0] + 10].sum(), inked[rows[-1] - 10].sum()
    assert top < bottom  # the rounded tip is at the top
    period = estimate_ridge_period(image.astype(np.float32) / 255.0, inked)
    assert abs(period - TARGET_PERIOD_PX) < 1.0
    assert contact.fits_nfiq2 and image.shape[1] <= MAX_SIZE[0] + 17 and image.shape[0] <= MAX_SIZE[1] + 17


def test_print_polarity_follows_the_ridges_option(uwa640):
    view = uwa640.views[1]
    bright, dark = (contact_like(view.image, view.mask, ridges=r).image.astype(float) for r in ("bright", "dark"))
    inked = (bright < 255) & (dark < 255)
    assert np.corrcoef(bright[inked] - 128, dark[inked] - 128)[0, 1] < -0.9  # one is the other inverted
    with pytest.raises(InputError, match="ridges"):
        contact_like(view.image, view.mask, ridges="up")


def test_print_coordinates_map_back_to_the_photo(uwa640):
    view = uwa640.views[0]
    contact = contact_like(view.image, view.mask)
    xy = np.array([[100.0, 200.0], [320.5, 255.25], [500.0, 10.0]])
    assert np.allclose(contact.to_photo(contact.to_print(xy)), xy)
    scale = np.sqrt(abs(np.linalg.det(contact.affine[:, :2])))
    assert scale == pytest.approx(TARGET_PERIOD_PX / contact.period_px)


def test_an_empty_mask_is_a_clear_error(uwa640):
    view = uwa640.views[0]
    with pytest.raises(InputError, match="no finger"):
        contact_like(view.image, np.zeros_like(view.mask))
    with pytest.raises(InputError, match="does not match"):
        contact_like(view.image, view.mask[:10])


def test_nist_tools_find_minutiae_score_quality_and_tell_fingers_apart(shots):
    pytest.importorskip("nbis")
    from fingersplat3d.eval.fingerprint import analyse, match_score

    prints = {(seed, view.name): analyse(contact_like(view.image, view.mask))
              for seed, capture in shots.items() for view in capture.views}
    for fingerprint in prints.values():
        assert fingerprint.count > 20
        assert fingerprint.nfiq2 is not None and 0 <= fingerprint.nfiq2 <= 100
        assert np.isfinite(fingerprint.minutiae).all()
        assert ((fingerprint.minutiae[:, 2] >= 0) & (fingerprint.minutiae[:, 2] < 360)).all()
    a, b = prints[(0, "p1")], prints[(1, "p1")]
    assert match_score(a, a) > 100 > match_score(a, b)
    genuine = match_score(prints[(0, "p1")], prints[(0, "p2")])
    assert genuine > match_score(prints[(0, "p1")], prints[(1, "p2")])


def test_minutiae_lie_on_the_finger_in_photo_pixels(shots):
    pytest.importorskip("nbis")
    from fingersplat3d.eval.fingerprint import analyse

    view = shots[0].views[0]
    fingerprint = analyse(contact_like(view.image, view.mask))
    cols, rows = np.rint(fingerprint.minutiae[:, :2]).astype(int).T
    inside = view.mask[np.clip(rows, 0, view.mask.shape[0] - 1), np.clip(cols, 0, view.mask.shape[1] - 1)]
    assert inside.mean() > 0.95


def test_a_print_nfiq2_cannot_score_is_a_recorded_failure(uwa640):
    pytest.importorskip("nbis")
    from fingersplat3d.eval.fingerprint import analyse, match_score

    view = uwa640.views[1]
    tiny = contact_like(view.image, view.mask, period_px=60.0)  # shrunk far below NFIQ2's 197 px
    result = analyse(tiny)
    assert result.nfiq2 is None and "NFIQ2" in result.failure
    blank = analyse(ContactImage.of_print(np.full((400, 300), 128, np.uint8)))  # a print with no ridges, given as one
    assert blank.nfiq2 is None or blank.nfiq2 < 10
    assert match_score(blank, blank) >= 0


@pytest.mark.parametrize("blur", [0.0, 6.0])
def test_a_photo_without_ridges_makes_no_print(uwa640, blur):
    """A flat finger, or one blurred beyond its ridges (σ 6 px on a ~9 px period), is refused with one sentence;
    the same photo sharp makes a print."""
    import cv2

    view = uwa640.views[1]
    sharp = contact_like(view.image, view.mask)
    assert (sharp.image < 255).sum() > 10_000
    flat = np.full_like(view.image, 0.5) if blur == 0 else cv2.GaussianBlur(view.image, (0, 0), blur)
    with pytest.raises(InputError, match="no ridges"):
        contact_like(flat, view.mask)


def test_error_rates_on_hand_counted_scores():
    genuine = [10, 20, 30, 40]
    impostor = [0, 5, 15, 25]
    thresholds, fmr, fnmr = det_curve(genuine, impostor)
    assert np.all(np.diff(fmr) <= 0) and np.all(np.diff(fnmr) >= 0)
    assert fmr[0] == 1.0 and fnmr[0] == 0.0 and fmr[-1] == 0.0 and fnmr[-1] == 1.0
    # t = 20: impostors 25 accepted (1/4), genuines 10 rejected (1/4): the EER
    assert equal_error_rate(genuine, impostor) == pytest.approx(0.25)
    assert fnmr_at_fmr(genuine, impostor, 0.0) == pytest.approx(0.5)  # t = 26 or 30: 10 and 20 rejected
    assert fnmr_at_fmr(genuine, impostor, 0.25) == pytest.approx(0.25)
    assert fmr_resolution(4) == 0.25
    rates = error_rates([1, 2], [0])
    assert rates["eer"] == 0.0 and rates["fmr_zero"] == 0.0 and rates["genuine"] == 2


def test_error_rates_at_the_extremes():
    assert equal_error_rate([5, 5, 5], [5, 5]) == pytest.approx(0.5)  # all tied: chance
    assert equal_error_rate([0], [10]) == pytest.approx(1.0)  # every comparison wrong
    assert fnmr_at_fmr([1e300], [-1e300], 0.0) == 0.0
    with pytest.raises(ValueError, match="genuine and impostor"):
        error_rates([], [1])
    with pytest.raises(ValueError, match="NaN"):
        error_rates([np.nan], [1])
    with pytest.raises(ValueError, match="target"):
        fnmr_at_fmr([1], [0], 1.5)


@pytest.mark.parametrize("period", [7.0, 9.0, 12.0])
def test_a_print_is_brought_to_the_photos_ridge_period(period):
    """A print whose ridges lie ``period`` px apart (a finger's own spacing at 500 ppi, or another scanner's
    resolution), dark ridges on white: scaled so they lie TARGET_PERIOD_PX apart, as a photo's print is."""
    from fingersplat3d.eval.contact import print_at_period

    yy, xx = np.mgrid[0:400, 0:360]
    ridges = np.cos(2 * np.pi * (0.8 * xx + 0.6 * yy) / period)  # ridges across the print at an angle
    inked = (yy - 200) ** 2 / 170 ** 2 + (xx - 180) ** 2 / 140 ** 2 < 1
    image = np.where(inked, np.rint(128 + 48 * ridges), 255).astype(np.uint8)
    scaled = print_at_period(image)
    assert scaled.period_px == pytest.approx(period, rel=0.03)
    if period == TARGET_PERIOD_PX:  # already there: the print itself, the identity map
        assert scaled.image is image and scaled.ppi_scale == 1.0
        return
    assert scaled.ppi_scale == pytest.approx(TARGET_PERIOD_PX / period, rel=0.03)
    assert print_at_period(scaled.image).period_px == pytest.approx(TARGET_PERIOD_PX, rel=0.03)
    assert scaled.image.dtype == np.uint8 and scaled.image[0, 0] == 255  # still white outside the ink
    corner = scaled.to_print(np.array([[360.0, 400.0]]))[0]
    assert corner == pytest.approx([scaled.image.shape[1], scaled.image.shape[0]], abs=1.0)


def test_a_print_without_ridges_or_not_8_bit_gray():
    from fingersplat3d.eval.contact import print_at_period

    blank = np.full((300, 300), 255, np.uint8)
    assert print_at_period(blank).image is blank  # no period to read: as it is
    with pytest.raises(ValueError, match="8-bit gray"):
        print_at_period(blank.astype(np.float32))


def test_a_gallery_print_is_analysed_at_scales_about_the_photos_ridge_period():
    from fingersplat3d.eval.contact import SCALE_STEPS, print_at_period, prints_about_period

    yy, xx = np.mgrid[0:400, 0:360]
    image = np.where((yy - 200) ** 2 / 170 ** 2 + (xx - 180) ** 2 / 140 ** 2 < 1,
                     np.rint(128 + 48 * np.cos(2 * np.pi * (0.6 * xx + 0.8 * yy) / 11.0)), 255).astype(np.uint8)
    scaled = prints_about_period(image)
    assert len(scaled) == len(SCALE_STEPS) and 1.0 in SCALE_STEPS
    middle = scaled[SCALE_STEPS.index(1.0)]
    assert middle.ppi_scale == pytest.approx(print_at_period(image).ppi_scale)
    for step, contact in zip(SCALE_STEPS, scaled):  # each at its step of the period: 9 px times the step
        assert contact.ppi_scale == pytest.approx(step * middle.ppi_scale)
        assert print_at_period(contact.image).period_px == pytest.approx(TARGET_PERIOD_PX * step, rel=0.04)
    blank = np.full((200, 200), 255, np.uint8)
    assert [c.image is blank for c in prints_about_period(blank)] == [True]  # no period read: as it is, once
