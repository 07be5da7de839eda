"""The focal a photo's EXIF records (io/exif.py), and fs3d fuse keeping it as a known focal."""
import math

import numpy as np
import pytest
from PIL import Image

from fingersplat3d.io.datasets import load_any
from fingersplat3d.io.exif import FULL_FRAME_DIAGONAL_MM, exif_focal

EXIF_IFD = 0x8769


def _jpeg(path, pixels, orientation=None, **tags):
    """``pixels`` (floats in [0, 1]) written as a JPEG with the given EXIF tags (by hex number) in its Exif IFD."""
    exif = Image.Exif()
    if orientation is not None:
        exif[0x0112] = orientation
    ifd = exif.get_ifd(EXIF_IFD)
    for key, value in tags.items():
        ifd[int(key, 16)] = value
    Image.fromarray((np.clip(pixels, 0, 1) * 255).astype(np.uint8)).save(path, exif=exif, quality=95)
    return path


def _photo(path, size=(400, 300), orientation=None, **tags):
    """A noise JPEG of ``size`` (as stored) with the given EXIF tags."""
    return _jpeg(path, np.random.default_rng(0).random((size[1], size[0], 3)), orientation, **tags)


def test_the_35mm_equivalent_is_carried_to_the_photos_pixels(tmp_path):
    path = _photo(tmp_path / "a.jpg", **{"0xA405": 26})
    found = exif_focal(path, (400, 300))
    assert found.focal_px == pytest.approx(26 / FULL_FRAME_DIAGONAL_MM * 500.0) and "35mm" in found.how


def test_a_scaled_down_photo_keeps_its_focal_in_its_own_pixels(tmp_path):
    # the full image was 4000 x 3000; this copy is a tenth of it
    path = _photo(tmp_path / "a.jpg", **{"0xA405": 26, "0xA002": 4000, "0xA003": 3000})
    assert exif_focal(path, (400, 300)).focal_px == pytest.approx(26 / FULL_FRAME_DIAGONAL_MM * 500.0)


def test_the_focal_plane_resolution_gives_the_focal_without_a_35mm_figure(tmp_path):
    # 4.2 mm lens, 1000 px per cm on the sensor (unit 3 = cm): 420 px at the full image (the stored size here)
    path = _photo(tmp_path / "a.jpg", **{"0x920A": 4.2, "0xA20E": 1000.0, "0xA210": 3})
    found = exif_focal(path, (400, 300))
    assert found.focal_px == pytest.approx(420.0) and "FocalLength" in found.how


def test_a_photo_turned_by_its_orientation_tag(tmp_path):
    # stored 400 x 300 and turned a quarter by the tag: read upright as 300 x 400
    path = _photo(tmp_path / "a.jpg", orientation=6, **{"0xA405": 26, "0xA002": 400, "0xA003": 300})
    assert exif_focal(path, (300, 400)).focal_px == pytest.approx(26 / FULL_FRAME_DIAGONAL_MM * 500.0)


def test_a_phones_heic_stored_sideways_gives_its_focal_upright(tmp_path):
    """An iPhone's HEIC: stored 400 x 300 with its turn in the file (read upright as 300 x 400, the orientation tag
    reset by pillow-heif), its EXIF the same as a JPEG's."""
    from pillow_heif import register_heif_opener

    from fingersplat3d.io.images import read_image

    register_heif_opener()  # Pillow writes HEIC through it
    exif = Image.Exif()
    exif[0x0112] = 6
    ifd = exif.get_ifd(EXIF_IFD)
    ifd[0xA405], ifd[0xA002], ifd[0xA003] = 26, 400, 300
    pixels = (np.random.default_rng(0).random((300, 400, 3)) * 255).astype(np.uint8)
    path = tmp_path / "IMG_0001.HEIC"
    Image.fromarray(pixels).save(path, format="HEIF", exif=exif.tobytes(), quality=90)
    assert read_image(path).shape == (400, 300, 3)
    found = exif_focal(path, (300, 400))
    assert found.focal_px == pytest.approx(26 / FULL_FRAME_DIAGONAL_MM * 500.0) and "35mm" in found.how


@pytest.mark.parametrize("tags, why", [({}, "no EXIF"), ({"0xA405": 0}, "no EXIF focal"), ({"0xA405": -3}, "no EXIF focal"),
                                       ({"0xA405": 26, "0xA002": 4000, "0xA003": 2000}, "cropped"),
                                       ({"0x920A": 4.2}, "no EXIF focal")])
def test_no_focal_where_the_exif_gives_none_or_the_photo_was_cropped(tmp_path, tags, why):
    found = exif_focal(_photo(tmp_path / "a.jpg", **tags), (400, 300))
    assert found.focal_px is None and why in found.how


def test_a_focal_no_camera_has_is_set_aside(tmp_path):
    found = exif_focal(_photo(tmp_path / "a.jpg", **{"0xA405": 65000}), (400, 300))  # ~1900 times the long side
    assert found.focal_px is None and "not a camera's focal" in found.how


def test_a_file_pillow_cannot_read_has_no_focal(tmp_path):
    path = tmp_path / "a.jpg"
    path.write_bytes(b"not an image")
    found = exif_focal(path, (400, 300))
    assert found.focal_px is None and "no EXIF" in found.how


def _exif_capture(folder, views, focals):
    """``views`` written as JPEGs whose EXIF records ``focals`` (photo pixels, as a 35mm equivalent)."""
    paths = []
    for view, focal in zip(views, focals):
        height, width = view.image.shape[:2]
        tags = {} if focal is None else {"0xA405": round(focal / math.hypot(width, height) * FULL_FRAME_DIAGONAL_MM)}
        paths.append(_jpeg(folder / f"{view.name}.jpg", view.image, **tags))
    return load_any(paths)[0]


@pytest.mark.slow
def test_two_phone_like_photos_with_their_exif_focal_get_the_turn_right(tmp_path):
    """A close-up (focal 1.4x the long side) in two views: the turn follows the focal, which two views cannot fix; the
    focal the EXIF records fixes it (measured: 0.25 degrees off with it, 7.0 fitted)."""
    from fingersplat3d.eval import relative_rotation_errors
    from fingersplat3d.pipeline import FuseConfig, _with_exif_focal, fuse
    from fingersplat3d.synth import SynthConfig, synthesize

    truth = synthesize(0, SynthConfig(size=(640, 512), distance_mm=50.0)).capture
    focal = truth.views[0].camera.K[0, 0]
    capture = _exif_capture(tmp_path, truth.views[:2], [focal, focal])
    result = fuse(capture, FuseConfig(splat=None))
    record = result.report["exif_focal"]
    assert record["used"] and record["focal_px"] == pytest.approx(focal, rel=0.02)  # the 35mm figure is whole mm
    assert result.report["alignment"]["focals_px"][0] == pytest.approx(record["focal_px"])
    errors = relative_rotation_errors([c.world_to_cam for c in result.cameras], [v.camera.world_to_cam for v in truth.views[:2]])
    assert errors[0] < 2.0
    # Off by the user's choice, or when the views disagree (another zoom) or one has none: fitted, and said why.
    assert fuse(capture, FuseConfig(splat=None, exif_focal=False)).report["exif_focal"]["why_not"] == "--no-exif-focal"
    mixed = _exif_capture(tmp_path, truth.views[:2], [focal, None])
    report = {}
    assert _with_exif_focal(mixed, FuseConfig(splat=None), None, report).focal_px is None
    assert not report["exif_focal"]["used"] and "not every view" in report["exif_focal"]["why_not"]
    report = {}
    assert _with_exif_focal(capture, FuseConfig(splat=None, focal_px=500.0), None, report).focal_px == 500.0
    assert report["exif_focal"]["why_not"] == "--focal-px gives the focal"


def test_two_photos_at_other_zooms_keep_each_its_exif_focal(tmp_path):
    """One photo zoomed 1.25x (its EXIF focal 1.25x the other's): each view keeps its own focal (measured, seeds 0-2:
    0.28-0.37 degrees off; one focal fitted for both, as before when the EXIF focals differed: 11-22 degrees)."""
    import cv2

    from fingersplat3d.eval import relative_rotation_errors
    from fingersplat3d.pipeline import FuseConfig, _with_exif_focal, fuse
    from fingersplat3d.synth import SynthConfig, synthesize

    truth = synthesize(0, SynthConfig(size=(640, 512), distance_mm=50.0)).capture
    focal = truth.views[0].camera.K[0, 0]
    zoomed = truth.views[1].with_(image=cv2.resize(truth.views[1].image, None, fx=1.25, fy=1.25, interpolation=cv2.INTER_CUBIC),
                                  mask=None, depth=None, camera=None)
    capture = _exif_capture(tmp_path, [truth.views[0], zoomed], [focal, 1.25 * focal])
    report = {}
    config = _with_exif_focal(capture, FuseConfig(splat=None), None, report)
    assert config.focal_px is None and config.view_focals_px[1] == pytest.approx(1.25 * config.view_focals_px[0], rel=0.03)
    assert report["exif_focal"]["used"] and "differ" in report["exif_focal"]["per_view"]
    result = fuse(capture, FuseConfig(splat=None))
    focals = result.report["alignment"]["focals_px"]
    assert focals == pytest.approx(list(config.view_focals_px))  # each held, on its photo's grid
    errors = relative_rotation_errors([c.world_to_cam for c in result.cameras], [v.camera.world_to_cam for v in truth.views[:2]])
    assert errors[0] < 2.0


def test_fs3d_info_shows_each_photos_exif_focal(tmp_path, capsys):
    from fingersplat3d.cli import main

    with_focal = _photo(tmp_path / "a.jpg", **{"0xA405": 26})
    without = _photo(tmp_path / "b.jpg")
    assert main(["info", str(with_focal), str(without)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "EXIF focal 300 px" in lines[1] and "EXIF" not in lines[2]


def test_fs3d_fuse_says_it_kept_the_exif_focal(tmp_path, capsys):
    from fingersplat3d.cli import main
    from fingersplat3d.synth import SynthConfig, synthesize

    truth = synthesize(1, SynthConfig(size=(320, 256))).capture
    focal = truth.views[0].camera.K[0, 0]
    capture = _exif_capture(tmp_path, truth.views, [focal] * len(truth.views))
    files = [str(tmp_path / f"{name}.jpg") for name in capture.names]
    assert main(["fuse", *files, "-o", str(tmp_path / "out"), "--no-splat"]) == 0
    assert "from the photos' EXIF, kept" in capsys.readouterr().out

