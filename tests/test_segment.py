"""finger_mask: agreement with the synthetic ground-truth masks, robustness, bad input; mask_iou."""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np
import pytest

from fingersplat3d.errors import InputError
from fingersplat3d.experiments.backgrounds import bright_desk, clutter, on_background
from fingersplat3d.segment.masks import finger_mask, mask_iou, outline_offset_px, outward_px
from fingersplat3d.synth import SynthConfig, synthesize

# At 640x512 finger_mask reaches IoU >= 0.9995 on every view of 5 uwa and 3 cfpose seeds
# (tools/bench_prior.py); 0.97 leaves room for the coarser test images and real-world slack.
MIN_IOU = 0.97


@lru_cache(maxsize=None)
def synthetic_views(rig: str, seed: int) -> tuple:
    """Small synthetic views (cached: test_prior.py reuses them); uwa's finger lies on the rig axis (frontal centre view)."""
    if rig == "uwa":
        config = SynthConfig(rig="uwa", size=(320, 256), finger_pose=False)
    else:
        config = SynthConfig(rig="cfpose", size=(256, 320), poses=3)
    return synthesize(seed, config).capture.views


CASES = [("uwa", 0), ("uwa", 1), ("cfpose", 0), ("cfpose", 1)]


def raises_naming(expected: str, function, *args, **kwargs) -> str:
    """``function`` must raise an InputError whose one-line message names ``expected``."""
    with pytest.raises(InputError) as info:
        function(*args, **kwargs)
    message = str(info.value)
    assert expected in message and "\n" not in message, message
    return message


@pytest.mark.parametrize("rig,seed", CASES)
def test_mask_matches_ground_truth(rig, seed):
    for view in synthetic_views(rig, seed):
        mask = finger_mask(view.image, name=view.name)
        assert mask.dtype == bool and mask.shape == view.mask.shape
        assert mask_iou(mask, view.mask) >= MIN_IOU, (rig, seed, view.name)


def test_gray_rgb_and_16_bit_dim_exposure():
    """RGB and its gray version, and 12-bit data stored in 16 bits (dim floats), segment alike."""
    view = synthetic_views("cfpose", 0)[1]
    assert view.image.ndim == 3
    gray = view.image @ np.array([0.299, 0.587, 0.114], np.float32)
    dim = np.round(view.image * 4095) / 65535.0  # uses 1/16 of the range, 16-bit quantised
    for image in (gray, dim, dim[..., :1]):
        assert mask_iou(finger_mask(image), view.mask) >= MIN_IOU


def test_hot_pixels_and_texture_do_not_leak():
    view = synthetic_views("uwa", 0)[1]
    image = view.image.copy()
    rng = np.random.default_rng(0)
    import cv2

    # Hot pixels in the background, not touching the outline (a pixel next to it is indistinguishable from skin).
    away = cv2.distanceTransform((~view.mask).astype(np.uint8), cv2.DIST_L2, 5) > 3
    background = np.argwhere(away)
    hot = background[rng.choice(len(background), 40, replace=False)]
    image[hot[:, 0], hot[:, 1]] = 1.0
    mask = finger_mask(image)
    assert mask_iou(mask, view.mask) >= MIN_IOU
    assert not mask[hot[:, 0], hot[:, 1]].any()


def test_dark_spots_inside_are_filled_and_one_component_kept():
    import cv2

    view = synthetic_views("uwa", 1)[1]
    image = view.image.copy()
    padded = np.pad(view.mask, 1).astype(np.uint8)  # the image border counts as outside here
    inside = cv2.distanceTransform(padded, cv2.DIST_L2, 5)[1:-1, 1:-1]
    centres = np.argwhere(inside > 20)[::3000][:4]
    assert len(centres) == 4
    for row, col in centres:  # background-dark spots (dirt, a scar) well inside the finger
        cv2.circle(image, (int(col), int(row)), 6, 0.03, -1)
    image[5:9, 5:9] = 0.8  # a separate bright speck in the background
    mask = finger_mask(image)
    assert mask[centres[:, 0], centres[:, 1]].all()
    assert not mask[5:9, 5:9].any()
    count, _ = cv2.connectedComponents(mask.astype(np.uint8))
    assert count == 2  # background + one finger
    assert mask_iou(mask, view.mask) >= MIN_IOU


def test_tiny_image_and_border():
    image = np.zeros((8, 8), np.float32)
    image[2:6, 0:5] = 0.7  # touches the left border
    mask = finger_mask(image)
    assert mask[3, 0] and mask[3, 3] and not mask[0, 7]


@pytest.mark.parametrize("image,problem", [
    (np.zeros((64, 80), np.float32), "no finger"),
    (np.full((64, 80), 0.5, np.float32), "no finger"),
    (np.random.default_rng(0).normal(0.05, 0.01, (64, 80)).clip(0, 1).astype(np.float32), "no finger"),
    # ridges on a strip thinner than the border rings (GrabCut had no finger to start from and asserted)
    (np.tile((0.5 + 0.3 * np.sin(np.arange(1280) / 1.3)).astype(np.float32), (10, 1)), "too thin"),
])
def test_no_finger_is_an_input_error(image, problem):
    assert problem in raises_naming("left.png", finger_mask, image, name="left.png")


def test_no_background_is_an_input_error():
    image = np.full((64, 80), 0.6, np.float32)
    image[:2, :2] = 0.02
    image += np.random.default_rng(1).normal(0, 0.01, image.shape).astype(np.float32)
    assert "no background" in raises_naming("v1", finger_mask, image.clip(0, 1), name="v1")  # nor ridges


def test_bad_arrays_are_input_errors():
    image = np.zeros((16, 16), np.float32)
    image[4:12, 4:12] = 0.8
    image[5, 5] = np.nan
    assert "NaN" in raises_naming("img", finger_mask, image, name="img")
    raises_naming("img", finger_mask, np.zeros((4, 4, 2)), name="img")


def test_mask_iou():
    a = np.zeros((4, 5), bool)
    b = a.copy()
    assert mask_iou(a, b) == 1.0
    a[0, :2] = True
    b[0, 1:3] = True
    assert mask_iou(a, b) == pytest.approx(1 / 3)
    assert mask_iou(a, ~a) == 0.0
    with pytest.raises(ValueError):
        mask_iou(a, np.zeros((5, 4), bool))


def test_a_finger_on_a_bright_or_cluttered_background():
    """Phone photos: no dark background. Measured IoU 0.989-0.996 on a bright desk, 0.993-0.996 on out-of-focus clutter
    (0.986-0.994 before the skin's colour had its covariance)."""
    views = synthetic_views("uwa", 1)
    rng = np.random.default_rng(0)
    for view in views:
        bright = on_background(view.image, view.mask, bright_desk(view.image.shape, rng))
        mask = finger_mask(bright)
        assert mask_iou(mask, view.mask) > 0.95
        assert abs(outward_px(mask, view.mask)) <= 0.5  # on the edge: measured 0.29-0.39 px (GrabCut's own 0.75-0.77)
        assert np.array_equal(mask, finger_mask(bright))  # the same photo, the same mask
        dim = finger_mask(bright * 0.02)  # a dim exposure (16-bit, bottom of the range)
        assert mask_iou(dim, view.mask) > 0.95 and abs(outward_px(dim, view.mask)) <= 0.5
        cluttered = on_background(view.image, view.mask, clutter(view.image.shape, rng))
        assert mask_iou(finger_mask(cluttered), view.mask) > 0.95
    plain = (0.8 + 0.02 * rng.normal(size=(256, 320, 3))).clip(0, 1).astype(np.float32)
    assert "no finger" in raises_naming("desk.jpg", finger_mask, plain, name="desk.jpg")


def test_a_real_finger_on_a_bright_desk_keeps_its_outline(real_dev):
    """Dark skin on a bright desk: the ridge evidence, smoothed over a period, reaches two periods past the edge; as
    sure finger it had made the outline 26 px too wide at 1280 px (IoU 0.87). Measured now: within 1 px, IoU 0.99,
    the shaded base where the finger leaves the frame kept."""
    from fingersplat3d.io.datasets import load_any

    view = load_any([real_dev / "1_1_2_1_1.jpg"])[0].views[0]
    truth = finger_mask(view.image)  # the dark-background segmentation
    found = finger_mask(on_background(view.image, truth, bright_desk(view.image.shape, np.random.default_rng(1))))
    offset, far = outline_offset_px(found, truth)
    assert abs(offset) <= 2.0 and far <= 4.0
    assert mask_iou(found, truth) > 0.97
    # GrabCut's outline, at 640 px and scaled up, kept the edge's blended pixels (0.99 px outside, which turned the
    # registered cameras by up to 0.97 degrees); moved onto the edge's crest: measured 0.11 px
    assert abs(outward_px(found, truth)) <= 0.3


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_a_real_finger_on_clutter_keeps_to_its_outline(real_dev, seed):
    """A grey finger on coloured clutter: in standard deviations per channel, the ridges' spread made saturated
    things as near the skin's colour as its own shades, and GrabCut's finger model was learned from everything inside
    the frame's border. Measured with that code on these photos: IoU 0.62-0.86, up to 91 px outside on average;
    now 0.979-0.999, 0.14-3.19 px."""
    from fingersplat3d.io.datasets import load_any

    view = load_any([real_dev / "1_1_2_1_1.jpg"])[0].views[0]
    truth = finger_mask(view.image)
    for blur in (6.0, 1.0):  # out of focus, in focus
        scene = clutter(view.image.shape, np.random.default_rng(seed), blur)
        found = finger_mask(on_background(view.image, truth, scene))
        assert mask_iou(found, truth) > 0.95
        assert abs(outward_px(found, truth)) <= 4.0


@pytest.mark.parametrize("capture, stream", [("1_1_2_1", 0), ("1_1_4_1", 2)])
def test_a_grey_thing_touching_the_finger_is_left_out(real_dev, capture, stream):
    """Side view 2 of two real captures on out-of-focus clutter, as ``tools/bench_backgrounds.py --fuse`` composites
    them: a slate-grey ellipse touches the finger's flank. Its colour is within the skin's spread, so it started as
    probable finger and GrabCut learned the finger's colours from it too; showing no ridges it now starts as probable
    background. Measured with the code before on these photos: IoU 0.625 and 0.557, and each capture lost that view;
    now 0.997."""
    from fingersplat3d.experiments.backgrounds import BACKGROUNDS, background
    from fingersplat3d.io.datasets import load_any

    views = load_any([real_dev / f"{capture}_{frame}.jpg" for frame in range(3)])[0].views
    kind = BACKGROUNDS.index("out-of-focus clutter")
    rng = np.random.default_rng([3, stream, kind])
    scenes = [background(BACKGROUNDS[kind], view.image.shape, rng) for view in views]  # drawn in turn, as the bench
    truth = finger_mask(views[2].image)
    found = finger_mask(on_background(views[2].image, truth, scenes[2]))
    assert mask_iou(found, truth) > 0.95
    assert abs(outward_px(found, truth)) <= 4.0


def test_colour_distance_follows_the_skins_own_spread():
    """Skin varies along its own colour (ridges, shading), little across it: a saturated colour as bright as the skin
    is far from it, a shade of it near; strict, a lighter grey (a bright desk) is bounded per channel too."""
    from fingersplat3d.segment.any_background import _colour_distance

    rng = np.random.default_rng(0)
    grey = np.clip(0.45 + 0.1 * rng.normal(size=(40, 40)), 0, 1)
    image = np.repeat(grey[..., None], 3, axis=2).astype(np.float32)  # a grey finger's ridges: every channel alike
    image[0, 0] = (0.6, 0.3, 0.45)  # purple, as bright as the skin
    image[0, 1] = (0.2, 0.2, 0.2)  # a shade of the skin
    image[0, 2] = (0.8, 0.8, 0.8)  # a bright desk
    seed = np.ones((40, 40), bool)
    seed[0, :3] = False
    lenient, strict = _colour_distance(image, seed), _colour_distance(image, seed, strict=True)
    assert lenient[0, 0] > 5.0 > 3.0 > lenient[0, 1]  # purple beyond the piece's 5, the shade within the sure 3
    assert strict[0, 2] > lenient[0, 2] and strict[0, 2] > 3.0  # not sure finger
    assert np.all(strict >= lenient - 1e-5) and np.all(np.isfinite(strict))
    one = np.zeros((40, 40), bool)
    one[5, 5] = True  # a single seed pixel: no covariance, the floor alone
    assert np.all(np.isfinite(_colour_distance(image, one))) and _colour_distance(image, one)[5, 5] == 0.0


def test_outline_offset_is_signed_and_in_pixels():
    truth = np.zeros((64, 64), bool)
    truth[16:48, 16:48] = True
    wider = np.zeros_like(truth)
    wider[13:51, 13:51] = True
    assert outline_offset_px(truth, truth) == (0.0, 0.0)
    assert outline_offset_px(wider, truth)[0] == pytest.approx(3.0, abs=0.05)
    assert outline_offset_px(truth, wider)[0] == pytest.approx(-3.0, abs=0.05)
    assert np.isnan(outline_offset_px(np.zeros_like(truth), truth)[0])
    disc = np.zeros((300, 300), np.uint8)
    small, large = (cv2.circle(disc.copy(), (150, 150), radius, 1, -1).astype(bool) for radius in (100, 103))
    assert 2.6 < outward_px(large, small) < 3.2 and -3.2 < outward_px(small, large) < -2.6  # measured 2.87, -2.79
    assert outward_px(small, small) == 0.0 and np.isnan(outward_px(small, np.zeros_like(small)))


def _shaded(view, low: float) -> np.ndarray:
    """The view lit from one side: its skin dimmed across the finger from 1 (one flank) to ``low`` (the other), the
    background as it was."""
    rows = np.nonzero(view.mask.any(1))[0]
    ramp = np.clip((np.arange(view.height) - rows.min()) / max(np.ptp(rows), 1), 0, 1)
    gain = np.where(view.mask, (low + (1 - low) * ramp)[:, None], 1.0)
    return (view.image * (gain if view.image.ndim == 2 else gain[..., None])).astype(np.float32)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_flank_in_shadow_stays_in_the_mask(seed):
    """Skin dimmed to 0.3 toward one flank: the edge level is read again inside the mask each read gives, until the
    edge stops moving out. Measured on the left views: IoU 0.79-0.87 when read once, 0.965-0.971 now (640x512:
    0.99)."""
    view = synthetic_views("uwa", seed)[0]
    assert mask_iou(finger_mask(_shaded(view, 0.3)), view.mask) >= 0.95


@pytest.mark.parametrize("sigma", [0.0, 6.0])
def test_an_out_of_focus_outline_stays_on_the_silhouette(sigma):
    """A photo blurred by a Gaussian of sigma 6 px (a close-up whose sides are out of focus): the level is the
    brightness at the crest of the edge's gradient, which a symmetric blur leaves on the true edge. The skin level read
    a few pixels inside the outline, alone, put these outlines 4.1-5.0 px outside; sharp, both within 0.4 px."""
    for view in synthetic_views("uwa", 0):
        image = view.image if sigma == 0 else cv2.GaussianBlur(view.image.astype(np.float32), (0, 0), sigma)
        assert abs(outward_px(finger_mask(image), view.mask)) <= (0.6 if sigma == 0 else 1.5)


def test_light_spilt_on_the_background_in_stripes_is_not_taken(real_dev):
    """A real frame under projected fringes (UWA frame 3): reading the edge level again would follow the stripes of
    light on the background (the mask's area +25 %, solidity down to ~0.8); a read that leaves the mask less solid is
    not kept."""
    import cv2

    from fingersplat3d.segment.masks import _solidity

    image = (cv2.imread(str(real_dev / "2_2_10_1_3.jpg"), cv2.IMREAD_GRAYSCALE) / 255.0).astype(np.float32)
    assert _solidity(finger_mask(image).astype(np.uint8)) > 0.97



def test_a_hazy_dark_background_is_found_by_brightness():
    """A dark-background photo whose contrast is lowered about its mean (haze, glare, a faint capture) and blurred
    past its ridges: the border ring reads above the dark share of the bright end, the ridges find no finger, and the
    brightness still does. (Measured on a real frame so degraded, 2_2_7_1 f2: border 0.352 of the bright end, IoU
    0.992 against the clean frame's mask; before, "no finger found".)"""
    from fingersplat3d.segment.masks import DARK_BORDER_SHARE, HAZY_BORDER_SHARE, _brightness, _dark_border

    view = synthetic_views("uwa", 0)[1]
    image = cv2.GaussianBlur(view.image.astype(np.float32), (0, 0), 3.0)
    skin = float(np.median(image[view.mask]))
    hazy = (0.45 * skin + 0.55 * image).astype(np.float32)  # the background lifted to ~45 % of the skin
    brightness = _brightness(hazy, "v")
    assert not _dark_border(brightness, DARK_BORDER_SHARE) and _dark_border(brightness, HAZY_BORDER_SHARE)
    assert mask_iou(finger_mask(hazy, name="v"), view.mask) >= 0.95
    # Haze over no finger at all is still no finger.
    blank = np.full_like(hazy, 0.45 * skin) + np.random.default_rng(0).normal(0, 0.003, hazy.shape).astype(np.float32)
    raises_naming("v", finger_mask, blank, name="v")


def test_ridges_repeat_where_a_line_or_an_edge_does_not():
    """Asked to repeat a period across their own direction, ridges score and the edges of other things do not: a
    grating of the searched period scores high, a sharp line or the step of a plain object's edge (as periodic as
    ridges by the bands' measure, and scored so by the plain score) scores nothing."""
    from fingersplat3d.segment.any_background import REPEAT_GATE, RIDGE_LEVEL, repetition, ridge_score

    period = 6.5
    rows, cols = np.mgrid[0:200, 0:300].astype(np.float32)
    image = np.full((200, 300), 0.5, np.float32)
    grating = (cols < 120) & (rows > 40) & (rows < 160)
    image[grating] += 0.2 * np.cos(2 * np.pi * (0.8 * cols + 0.6 * rows)[grating] / period)
    image[(np.abs(cols - 0.3 * rows - 170) < 1.0) & (rows > 30) & (rows < 170)] = 0.9  # a thin line, in focus
    image[(cols > 230) & (rows > 60) & (rows < 140)] = 0.15  # a plain dark object's edges
    image = cv2.GaussianBlur(image, (0, 0), 0.7)
    inner = cv2.erode(grating.astype(np.uint8), np.ones((21, 21), np.uint8)).astype(bool)
    line, edge = (cols >= 135) & (cols < 225), cols >= 225
    plain, repeated = ridge_score(image, period), ridge_score(image, period, repeated=True)
    assert plain[line].max() > RIDGE_LEVEL and plain[edge].max() > RIDGE_LEVEL  # measured 0.34 and 0.27
    assert np.median(repeated[inner]) > 2 * RIDGE_LEVEL
    assert repeated[line | edge].max() < RIDGE_LEVEL
    band = cv2.GaussianBlur(image, (0, 0), 0.15 * period) - cv2.GaussianBlur(image, (0, 0), 0.45 * period)
    energy = cv2.GaussianBlur(band * band, (0, 0), period)
    repeats = repetition(band, energy, period)
    assert np.median(repeats[inner]) > 0.5
    strong = (line | edge) & (energy > 0.1 * energy[inner].mean())
    assert strong.any() and np.percentile(repeats[strong], 95) < REPEAT_GATE[0]
    for blank in (np.zeros((50, 60), np.float32), np.ones((50, 60), np.float32)):
        assert np.isfinite(ridge_score(blank, period, repeated=True)).all()


def test_the_mask_of_repeating_ridges_is_taken_where_the_plain_one_found_something_else():
    """Of the two cuts, the plain one stays unless the other holds half as many repeating ridges again (the plain one
    found a thing whose edges read as ridges), the plain one swells past the finger where the other does not, or the
    plain one's outline lies on no edge of the photo where the other's lies on strong ones; the other is cut only where
    it could be taken."""
    from fingersplat3d.segment.any_background import EDGE_GAIN, REPEATED_MORE, _chosen, _working_copy

    rows, cols = np.mgrid[0:240, 0:320]
    finger = (np.abs(rows - 120) < 40) & (cols > 60)
    ridged = np.zeros((240, 320), np.float32)
    ridged[finger & (cols < 200)] = 0.5  # repeating ridges on the pad
    other = (np.hypot(rows - 60, cols - 40) < 35)  # a blob with no repeating ridges
    photo = np.full((240, 320, 3), 0.5, np.float32)
    photo[finger] = 0.3  # the finger's edge is the photo's
    photo[other] = 0.8
    work = _working_copy(cv2.GaussianBlur(photo, (0, 0), 1.0))
    cuts = []

    def cut(mask):
        def again():
            cuts.append(mask)
            return mask
        return again

    assert _chosen(other, cut(finger), ridged, work) is finger  # the plain cut took the blob
    assert _chosen(finger, cut(finger.copy()), ridged, work) is finger  # the same finger: the plain cut stays
    swollen = finger | ((np.abs(cols - 250) < 30) & (rows > 20))  # something of the skin's colour joined to it
    assert _chosen(swollen, cut(finger), ridged, work) is finger
    assert _chosen(finger, cut(swollen), ridged, work) is finger
    assert _chosen(None, cut(finger), ridged, work) is finger and _chosen(finger, cut(None), ridged, work) is finger
    assert _chosen(None, cut(None), ridged, work) is None
    part = finger & (cols < 130)  # a cut holding a share of the ridges only
    assert _chosen(part, cut(finger), ridged, work) is finger and REPEATED_MORE > 1.0
    # a band of background kept all round the finger (a desk of the skin's grey): its outline lies on no edge, the
    # other's on the finger's
    band = cv2.dilate(finger.astype(np.uint8), np.ones((13, 13), np.uint8)) > 0
    assert _chosen(band, cut(finger), ridged, work) is finger and EDGE_GAIN > 1.0
    plain_photo = _working_copy(np.full((240, 320, 3), 0.5, np.float32))  # no edge anywhere: nothing to prefer
    assert _chosen(band, cut(finger), ridged, plain_photo) is band
    # the second cut is made only where it could be taken
    cuts.clear()
    assert _chosen(finger, cut(other), ridged, work) is finger and not cuts
    for plain in (None, other, part, swollen, band):
        cuts.clear()
        _chosen(plain, cut(finger), ridged, work)
        assert len(cuts) == 1


def _crossing_finger(h: int = 512, w: int = 256, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A brown finger the frame cuts at both ends (it crosses the image from side to side), faint ridges, on a bright
    desk: ``(image, true mask)``."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:h, :w].astype(np.float32)
    top, bottom = 150 + 10 * np.sin(xx / 60), 360 - 8 * np.cos(xx / 70)
    mask = (yy > top) & (yy < bottom)
    shade = np.sqrt(np.clip(1 - ((yy - (top + bottom) / 2) / ((bottom - top) / 2)) ** 2, 0, 1))
    ridges = np.sin(2 * np.pi * (xx * 0.8 + yy * 0.6 + 8 * np.sin(yy / 50)) / 7.0)
    skin = (0.18 + 0.12 * shade + 0.02 * ridges)[..., None] * np.array([1.15, 0.9, 0.78], np.float32)
    return on_background(np.clip(skin, 0, 1).astype(np.float32), mask, bright_desk((h, w, 3), rng)), mask


def test_the_crossing_cut_finds_a_finger_the_frame_cuts_at_both_ends_and_nothing_on_a_plain_desk(monkeypatch):
    """The last resort of any_background (stop 93): the ring's pixels off its own colour taken as probable finger."""
    from fingersplat3d.segment import any_background as ab

    image, truth = _crossing_finger()
    here = ab._working_copy(image)
    evidence, _ = ab._ridge_evidence(here.gray)
    found = ab._crossing_cut(here, evidence)
    assert found is not None and mask_iou(found, truth) > 0.97
    assert ab._off_ring(image, here.ring).sum() > ab.MIN_CROSSING_SHARE * here.ring.sum()
    desk = (0.8 + 0.02 * np.random.default_rng(1).normal(size=(256, 320, 3))).clip(0, 1).astype(np.float32)
    plain = ab._working_copy(desk)
    assert ab._crossing_cut(plain, ab._ridge_evidence(plain.gray)[0]) is None
    # where the other cuts found a mask: tried only where it holds under half of the crossing, taken where it holds more
    patch = np.zeros_like(truth)
    patch[:100, 60:200] = True  # a patch of the desk above the finger
    calls = []
    framed_cut = ab._framed_cut

    def counted(*args):
        calls.append(1)
        return framed_cut(*args)

    monkeypatch.setattr(ab, "_framed_cut", counted)
    crossed = ab._crossing_cut(here, evidence, patch)
    assert crossed is not None and mask_iou(crossed, truth) > 0.97 and len(calls) == 1
    assert ab._crossing_cut(here, evidence, truth) is None and len(calls) == 1  # the finger: not tried


def test_an_earlier_piece_is_kept_where_its_outline_lies_on_the_photos_edges():
    """any_background._best_supported (stop 94): a later cut that dropped half of the skin leaves its outline across the
    skin, where the photo has no edge; a cut that dropped a thing joined to the finger along a clear edge stays."""
    from fingersplat3d.segment import any_background as ab

    image, truth = _crossing_finger()
    work = ab._working_copy(image)
    rows = np.arange(truth.shape[0])[:, None]
    half = truth & (rows > 255)  # the lower half: its upper outline runs across the skin
    assert ab._edge_support(truth, work) > ab.EDGE_GAIN * ab._edge_support(half, work)
    assert ab._best_supported((half, truth), work) is truth
    assert ab._best_supported((truth, half), work) is truth
    joined = truth | ((rows < 150) & (np.arange(truth.shape[1])[None, :] < 60))  # a block of the desk joined to it
    assert ab._best_supported((truth, joined), work) is truth
    nothing = np.zeros_like(truth)
    nothing[work.ring] = True  # an outline all along the ring: no support to compare, the later mask stays
    assert ab._edge_support(nothing, work) is None and ab._best_supported((truth, nothing), work) is truth
    # what an earlier piece adds must have the skin's hue: the finger's shaded half does, the desk does not
    assert ab._same_hue(truth & (rows <= 255), half, work.colour)
    assert not ab._same_hue(~truth & ~work.ring, truth, work.colour)


def _bench_textured():
    """``tools/bench_textured.py`` as a module (its fingers of another make, backgrounds and crops)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    try:
        import bench_textured
    finally:
        sys.path.pop(0)
    return bench_textured


def test_a_faint_finger_cut_at_both_ends_on_a_bright_desk(impose_dev):
    """Found by tools/bench_stress.py (stop 93): another make's finger cropped to 0.9 widths on a bright desk, its
    front view's ridges fainter than the desk's grain, had no finger found; measured IoU 0.999 since."""
    from fingersplat3d.experiments.textured_finger import random_finger, skin_texture, textured_capture

    bt = _bench_textured()

    seed = 7877
    capture = textured_capture(random_finger(np.random.default_rng(seed)), skin_texture(impose_dev / "sample2_texture.png"),
                               size=(640, 512), ring_deg=[-28, 0], distance_mm=45.0, seed=seed)
    capture = bt._distorted(capture, -0.06)
    capture = bt._on_background(capture, "bright desk", seed)
    front = bt._cropped(capture, 0.9).views[1]
    assert mask_iou(finger_mask(front.image, name="front"), front.mask) > 0.98


@pytest.mark.parametrize("seed, view", [(7878, 0), (7875, 2), (7860, 1)])
def test_dark_fingers_cut_at_both_ends_on_a_bright_desk_masked_whole(impose_dev, seed, view):
    """Found by a sweep of crops (stop 94): another make's finger cut to 0.9 widths on a bright desk, three views
    +-40 degrees at 54 mm; measured IoU before -> since: its shaded half dropped by the last cut 0.47 -> 1.00, its
    highlit band by the second 0.84 -> 1.00, a patch of the desk above it taken instead 0.00 -> 1.00."""
    from fingersplat3d.experiments.textured_finger import random_finger, skin_texture, textured_capture

    bt = _bench_textured()

    capture = textured_capture(random_finger(np.random.default_rng(seed)), skin_texture(impose_dev / "sample2_texture.png"),
                               size=(640, 512), ring_deg=[-40, 0, 40], distance_mm=54.0, seed=seed)
    capture = bt._on_background(capture, "bright desk", seed)
    cropped = bt._cropped(capture, 0.9).views[view]
    assert mask_iou(finger_mask(cropped.image, name="crop"), cropped.mask) > 0.95


@pytest.mark.parametrize("desk, photo", [("lamp-lit", "2_2_10_1_0"), ("grey", "1_1_1_1_0")])
def test_a_real_grey_finger_on_a_desk_of_its_own_greys_keeps_to_its_outline(real_dev, desk, photo):
    """A grey real view on a warm desk lit from above the frame (bright above, dark below: its greys span the
    finger's) or on a plain desk of the skin's grey: the plain cut kept a band of desk all round the finger, its outline
    on no edge of the photo; the cut of repeating ridges lies on the finger's edge. Measured with the code before on
    these photos: IoU 0.85 and 0.89 (docs/measurements.md, stop 107); now 0.99 and 0.999."""
    from fingersplat3d.io.datasets import load_any

    view = load_any([real_dev / f"{photo}.jpg"])[0].views[0]
    truth = finger_mask(view.image)
    height, width = view.image.shape[:2]
    level = np.linspace(0.95, 0.15, height)[:, None] if desk == "lamp-lit" else np.full((height, 1), 0.45)
    warm = np.array([1.0, 0.97, 0.9])
    scene = level[..., None] * warm + 0.02 * np.random.default_rng(5).normal(size=(height, width, 3))
    found = finger_mask(on_background(view.image, truth, scene.astype(np.float32)))
    assert mask_iou(found, truth) > 0.97
    assert abs(outward_px(found, truth)) <= 2.0
