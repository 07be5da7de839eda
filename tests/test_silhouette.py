"""Which end of a silhouette is the fingertip: the outline, the taper, and the views of one capture agreeing."""
import numpy as np
import pytest

from fingersplat3d.pointmaps.prior import finger_height
from fingersplat3d.segment.side_cut import sides_cut_share
from fingersplat3d.segment.silhouette import TIP_BASES, capture_axes, orient_frames, principal_axis, silhouette_frame


def crop(rows=300, cols=240, top=60, bottom=90, shift=0.0):
    """A finger crop cut at both ends by the image border: a vertical band whose half-width grows from
    ``top`` (first row) to ``bottom`` (last row), its centre moved ``shift`` pixels per row."""
    v, u = np.mgrid[:rows, :cols]
    half = top + (bottom - top) * v / (rows - 1)
    return np.abs(u - (cols / 2 + shift * v)) <= half


def capsule(rows=160, cols=400, radius=50, tip=80):
    """A horizontal capsule cut by the right border, tip to the left."""
    v, u = np.mgrid[:rows, :cols]
    return ((np.abs(v - rows // 2) <= radius) & (u >= tip)) | ((u - tip) ** 2 + (v - rows // 2) ** 2 <= radius ** 2)


def test_the_outline_names_the_tip_when_one_end_is_cut():
    frame = silhouette_frame(capsule())
    assert frame.tip_found and frame.tip_basis == "outline" and frame.tip_side == "left"


@pytest.mark.parametrize("mask, side", [(crop(), "top"), (crop()[::-1], "bottom"), (crop(shift=0.1).T, "left")])
def test_a_crop_cut_at_both_ends_takes_the_end_it_narrows_toward(mask, side):
    frame = silhouette_frame(mask)
    assert not frame.tip_found and frame.tip_basis == "taper" and frame.tip_side == side
    assert 0.25 < frame.taper < 0.5  # 60 -> 90 px half-width: a third of the median width


def test_askew_cut_ends_do_not_decide_the_tip():
    """A crop cut straight across an inclined finger leaves sliver chords at both ends; they are not its width."""
    frame = silhouette_frame(crop(shift=0.25))
    assert frame.tip_side == "top" and frame.taper > 0.2


def test_bevelled_corners_at_the_wide_end_do_not_decide_the_tip():
    """A crop whose wide end has its corners cut away (the cut of a rendered 3D finger, a rounded phone
    crop) is narrow over its last rows: the end rows alone would take it for the tip."""
    mask = crop()
    v, u = np.mgrid[:mask.shape[0], :mask.shape[1]]
    mask &= np.abs(u - mask.shape[1] / 2) <= 90 - 1.6 * np.maximum(v - (mask.shape[0] - 40), 0)
    frame = silhouette_frame(mask)
    width = frame.sections.half_width
    tenth = len(width) // 10  # stations run from the wide end to the tip
    assert width[:tenth].mean() < width[-tenth:].mean()  # the trap: the wide end's last rows are the narrower
    assert frame.tip_side == "top" and frame.taper > 0.1


def _longest(mask):
    v, u = np.nonzero(mask)
    return principal_axis(u, v)[0]


@pytest.mark.parametrize("shift", [0.0, 0.3])
@pytest.mark.parametrize("transpose", [False, True])
def test_a_crop_shorter_than_wide_keeps_its_axis_between_the_frame_cuts(transpose, shift):
    """Cut at both ends by the frame, 120 px along the finger and 160-200 px across it."""
    mask = crop(rows=120, cols=400, top=80, bottom=100, shift=shift)
    along = np.array([shift, 1.0]) / np.hypot(shift, 1.0)  # (du, dv) of the band
    if transpose:
        mask, along = mask.T, along[::-1]
    assert abs(_longest(mask) @ along) < 0.5  # the trap: its longest direction runs across the finger
    frame = silhouette_frame(mask)
    assert abs(frame.axis @ along) > np.cos(np.radians(3))
    assert frame.tip_basis == "taper" and frame.tip_side == ("left" if transpose else "top")
    assert abs(finger_height(mask).axis @ frame.axis) == pytest.approx(1.0)  # the prior's relief runs the same way


def _cut_inside(half_width: float, shift: float = 0.0) -> np.ndarray:
    """A crop cut straight across the finger at both ends inside the frame (black all round): 120 px along the
    finger (vertical) and ``2 * half_width`` across it, its sides leaning ``shift`` px per row."""
    return np.pad(crop(rows=120, cols=400, top=half_width, bottom=half_width + 8, shift=shift), 20)


@pytest.mark.parametrize("shift", [0.0, 0.3])
def test_views_of_crops_cut_inside_the_frame_agree_on_the_axis(shift):
    """Three views of one crop cut inside the frame, shorter along the finger than across it: no outline tells its
    ends from its sides, but the capture's do, its length along the finger the same in every view and its width not."""
    views = [_cut_inside(72, shift), _cut_inside(92, shift), _cut_inside(76, shift)]
    along = np.array([shift, 1.0]) / np.hypot(shift, 1.0)
    # The trap: each one's longest way runs across the finger, or along a leaning crop's diagonal.
    assert all(abs(_longest(mask) @ along) < np.cos(np.radians(30)) for mask in views)
    hints = capture_axes(views)
    assert all(hint is not None and abs(hint @ along) > np.cos(np.radians(3)) for hint in hints)
    for frame in orient_frames(views):  # the charts and the contours read these
        assert abs(frame.axis @ along) > np.cos(np.radians(3))
    assert abs(finger_height(views[1], hint=hints[1]).axis @ along) > np.cos(np.radians(3))  # the prior's relief


def test_the_capture_gives_no_axis_where_its_views_cannot_tell():
    alike = [_cut_inside(80)] * 3  # the same outline in every view: a round section, nothing to compare
    assert capture_axes(alike) == [None] * 3
    assert capture_axes([_cut_inside(80)]) == [None]  # one view
    framed = crop(rows=120, cols=400, top=72, bottom=80)  # cut by the frame: its own cuts give its axis
    hints = capture_axes([framed, _cut_inside(92), _cut_inside(76)])
    assert hints[0] is None and all(hint is not None for hint in hints[1:])
    turned = np.ascontiguousarray(_cut_inside(92).T)  # a view whose outline runs another way: no shared direction
    assert capture_axes([_cut_inside(72), turned, _cut_inside(76)]) == [None] * 3
    whole = [np.pad(crop(rows=400, cols=240, top=60, bottom=70 + 10 * k), 20) for k in range(3)]
    assert capture_axes(whole) == [None] * 3  # longer than wide: their own axes already run along the finger


def test_a_stub_entering_the_frame_runs_from_its_cut():
    """A fingertip that enters the frame less far than it is wide: cut by the right edge, tip to the left."""
    mask = capsule(rows=260, cols=190, radius=110, tip=120)
    assert abs(_longest(mask)[0]) < 0.1
    frame = silhouette_frame(mask)
    assert abs(frame.axis[0]) > 0.99 and frame.tip_basis == "outline" and frame.tip_side == "left"


@pytest.mark.parametrize("transpose", [False, True])
@pytest.mark.parametrize("centre", [80, 120, 40])
def test_a_finger_filling_the_frame_across_keeps_its_axis_along_it(centre, transpose):
    """A tight crop or a close-up: a finger 200 px wide in a frame 160 px high, cut along both flanks (``centre`` 80)
    or one (120: the top flank in view; 40: the bottom one) and at its base by the right edge, the tip in view at the
    left. Neither its long cut flanks (the long crop reads as cut at both ends) nor one long flank against the short
    base may turn its axis across the finger (real dev views cropped so lost every chart vote, stop 104)."""
    v, u = np.mgrid[:160, :600]
    mask = ((np.abs(v - centre) <= 100) & (u >= 120)) | ((u - 120) ** 2 + (v - centre) ** 2 <= 100 ** 2)
    along = np.array([1.0, 0.0])
    if transpose:
        mask, along = np.ascontiguousarray(mask.T), along[::-1]
    frame = silhouette_frame(mask)
    assert abs(frame.axis @ along) > 0.99
    assert frame.tip_basis == "outline" and frame.tip_side == ("top" if transpose else "left")
    assert abs(finger_height(mask).axis @ along) > 0.99  # the prior's relief runs the same way
    assert sides_cut_share(mask, frame) > 0.5  # report.json's share of stations cut at a side: a tight crop
    whole = capsule(rows=400, cols=600, radius=100, tip=120)  # the same finger, its flanks in view
    assert sides_cut_share(whole, silhouette_frame(whole)) == 0.0


def test_a_finger_whole_in_the_frame_or_cut_at_a_corner_keeps_its_longest_direction():
    whole = np.pad(crop(rows=120, cols=400, top=80, bottom=100), 5)
    corner = np.zeros((300, 300), bool)
    corner[:200, :120] = True  # cut by the top and the left edges
    for mask in (whole, corner):
        assert abs(silhouette_frame(mask).axis @ _longest(mask)) == pytest.approx(1.0)


def test_views_of_one_capture_agree_on_the_tip():
    clear_a, clear_b = crop(), crop(top=65, bottom=95)
    unclear = crop(top=80, bottom=78)  # tapers the other way, barely: its own choice would be "bottom"
    assert silhouette_frame(unclear).tip_side == "bottom"
    frames = orient_frames([clear_a, unclear, clear_b])
    assert [frame.tip_side for frame in frames] == ["top"] * 3
    assert [frame.tip_basis for frame in frames] == ["taper", "other views", "taper"]
    assert frames[1].taper < 0  # still said: it widens toward the end taken


def test_a_seen_tip_outweighs_every_taper():
    seen = capsule(rows=300, cols=240).T[::-1]  # vertical, cut by the top border: the tip is at the bottom
    assert silhouette_frame(seen).tip_side == "bottom"
    frames = orient_frames([crop(), seen])
    assert [frame.tip_side for frame in frames] == ["bottom", "bottom"]
    assert [frame.tip_basis for frame in frames] == ["other views", "outline"]
    assert set(TIP_BASES) >= {frame.tip_basis for frame in frames}


def test_frames_stay_finite_on_degenerate_masks():
    corner = np.zeros((20, 30), bool)
    corner[0, 0] = corner[19, 0] = True  # cut by the top and bottom edges at one column, by the left edge twice
    for mask in (np.ones((50, 50), bool), np.pad(np.ones((3, 3), bool), 20), crop(top=70, bottom=70),
                 np.ones((1, 40), bool), np.ones((40, 1), bool), corner):
        frame = silhouette_frame(mask)
        assert np.all(np.isfinite(frame.axis)) and np.isfinite(frame.taper) and frame.tip_side in {"top", "bottom", "left", "right"}
        assert 0.0 <= sides_cut_share(mask, frame) <= 1.0  # what report.json says of the view's cut sides
    assert len(orient_frames([crop(top=70, bottom=70)] * 2)) == 2


@pytest.mark.parametrize("window, count", [(3, 3), (5, 40), (21, 21), (31, 200)])
def test_local_quadratic_is_scipys_savgol_filter(window, count):
    from scipy.signal import savgol_filter

    from fingersplat3d.segment.silhouette import local_quadratic

    values = np.random.default_rng(window).normal(size=count).cumsum() + np.linspace(0, 5, count) ** 2
    assert np.allclose(local_quadratic(values, window), savgol_filter(values, window, 2, mode="interp"), atol=1e-9)


def test_the_widest_disc_is_the_fingers_width_whether_the_frame_cuts_it_or_not():
    """widest_disc: a band the frame cuts at both ends, shorter along the finger (its box's short side) than it is
    wide, reads its width; a capsule whole but for its cut end reads its diameter; nothing and everything read 0."""
    from fingersplat3d.segment.silhouette import widest_disc

    short = crop(rows=90, cols=300, top=60, bottom=60)  # 90 rows along the finger, 121 columns across it
    assert abs(widest_disc(short) - 121) <= 3
    assert abs(widest_disc(capsule(radius=50)) - 101) <= 3
    assert abs(widest_disc(short.T) - widest_disc(short)) <= 1e-9  # no preferred direction
    assert widest_disc(np.zeros((20, 20), bool)) == 0.0 and widest_disc(np.ones((20, 20), bool)) == 0.0


def _pad_profile(u, radius, tip=60, length=440):
    """Half-width along a horizontal finger whose tip is at column ``tip``: an elliptical cap one radius long, then a pad
    bulging by a third in the middle of the body and narrowing again toward the base."""
    body = np.clip((u - tip - radius) / (length - radius), 0.0, 1.0)
    cap = np.sqrt(np.clip(1.0 - ((tip + radius - u) / radius) ** 2, 0.0, 1.0))
    return np.where(u < tip + radius, radius * cap, radius * (1.0 + np.sin(np.pi * body) / 3.0))


def _pad_view(radius, centre_row, rows=300, cols=440):
    """A view of the bulging finger of :func:`_pad_profile` (cut by the right border), its axis on ``centre_row``."""
    v, u = np.mgrid[:rows, :cols]
    return (np.abs(v - centre_row) <= _pad_profile(u, radius)) & (u >= 60)


def test_a_view_the_frame_cuts_along_its_side_takes_its_widths_from_the_others():
    """A side view whose pad the bottom border cuts (its chords whole only at the tip's cap and near the base): its
    chords, completed from their whole neighbours, come out up to 8 px narrow; the other views' widths at the same
    distance from the tip, times the ratio where both are whole, give the pad's bulge back, and its relief with it."""
    from fingersplat3d.segment.side_cut import capture_frames, side_cut_widths

    front, whole_side, cut_side = _pad_view(60, 150), _pad_view(66, 150), _pad_view(66, 228)
    assert cut_side[-1].sum() > 150 and not cut_side[-1, :120].any()  # the border cuts the pad, not the cap
    masks = [front, whole_side, cut_side]
    widths = side_cut_widths(masks)
    assert widths[0] is None and widths[1] is None and widths[2] is not None
    plain, completed = orient_frames(masks), capture_frames(masks)
    for index in (0, 1):  # views the frame does not cut along their side are left as they were
        assert np.array_equal(plain[index].sections.half_width, completed[index].sections.half_width)
    assert [frame.widths_from_views for frame in completed] == [False, False, True]
    u = np.arange(200, 380)  # the stretch the border cuts
    truth = _pad_profile(u, 66)
    pixels = np.stack([u, np.full(u.size, 228.0)], 1)

    def error(frame):
        s, _ = frame.coordinates(pixels)
        return np.abs(frame.sections.at(s)[0] - truth).max()

    assert error(plain[2]) > 6.0 and error(completed[2]) < 2.5
    # The prior's relief, peaking at 0.95 of the half-width, follows.
    peak = lambda height: height[:, 250:330].max(0).mean()  # noqa: E731
    plain_peak, completed_peak = peak(finger_height(cut_side).height), peak(finger_height(cut_side, widths=widths[2]).height)
    true_peak = 0.95 * _pad_profile(np.arange(250, 330), 66).mean()
    assert abs(completed_peak - true_peak) < 0.03 * true_peak < abs(plain_peak - true_peak)


def test_a_view_cut_from_just_behind_its_cap_takes_the_ratio_on_the_cap():
    """A thick side view the bottom border cuts from just behind its tip's cap to the base: no whole chord off the cap
    is left to take the views' ratio from, so it is taken on the cap, and the pad's bulge comes back within a few
    pixels where the cap's own chords, completed, leave it 12 px narrow or more."""
    from fingersplat3d.segment.side_cut import capture_frames, side_cut_widths

    masks = [_pad_view(60, 150, cols=300), _pad_view(66, 150, cols=300), _pad_view(66, 240, cols=300)]
    assert masks[2][-1].sum() > 150 and not masks[2][-1, :90].any()  # cut behind the cap, not through it
    assert side_cut_widths(masks)[2] is not None
    plain, completed = orient_frames(masks)[2], capture_frames(masks)[2]
    u = np.arange(140, 290)
    pixels, truth = np.stack([u, np.full(u.size, 240.0)], 1), _pad_profile(u, 66)

    def error(frame):
        s, _ = frame.coordinates(pixels)
        return np.abs(frame.sections.at(s)[0] - truth).max()

    assert completed.widths_from_views and error(completed) < 4.0 and error(plain) > 10.0


def test_a_view_cut_along_its_whole_side_keeps_its_own_widths():
    """With too few whole chords to take the ratio from, even on the tip's cap, nothing stands in for a cut view's
    widths; a capture of one view has no other to take them from; the chords of views cut only across their end stay
    theirs."""
    from fingersplat3d.segment.side_cut import side_cut_widths

    cut_everywhere = _pad_view(66, 150)[:150 + 40]  # the bottom border cuts it from the cap to the base
    assert side_cut_widths([_pad_view(60, 150), cut_everywhere]) == [None, None]
    assert side_cut_widths([_pad_view(66, 228)]) == [None]
    assert side_cut_widths([capsule(), capsule(radius=55)]) == [None, None]


def _finger(shape=(300, 500), width=120, tip_x=80):
    """A finger entering from the right edge: a bar with a round tip."""
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    centre = shape[0] / 2
    bar = (np.abs(rows - centre) <= width / 2) & (cols >= tip_x + width / 2)
    cap = (rows - centre) ** 2 + (cols - tip_x - width / 2) ** 2 <= (width / 2) ** 2
    return bar | cap


def test_a_patch_joined_to_the_finger_swells_its_outline():
    from fingersplat3d.segment.silhouette import OUTLINE_SWELL, outline_swell

    finger = _finger()
    assert outline_swell(finger) == pytest.approx(1.0, abs=0.05)
    rows, cols = np.mgrid[0:300, 0:500]
    patch = finger | (((rows - 90) / 70.0) ** 2 + ((cols - 300) / 50.0) ** 2 <= 1)  # a blob touching its side
    assert outline_swell(patch) > OUTLINE_SWELL
    side_cut = finger[100:, :]  # the frame cuts the finger along its side: its whole chords are the tip's
    assert outline_swell(side_cut) is None
    assert outline_swell(np.zeros((50, 50), bool)) is None and outline_swell(np.ones((50, 50), bool)) is None


def test_the_fuse_names_a_view_whose_mask_swells():
    from fingersplat3d.pipeline import _swollen
    from fingersplat3d.scene import Capture, View

    rows, cols = np.mgrid[0:300, 0:500]
    patch = _finger() | (((rows - 90) / 70.0) ** 2 + ((cols - 300) / 50.0) ** 2 <= 1)
    views = [View("a", np.zeros((300, 500), np.float32), _finger()), View("b", np.zeros((300, 500), np.float32), patch)]
    said = _swollen(Capture(tuple(views)))
    assert len(said) == 1 and said[0].startswith("view 'b': its finger mask is")
