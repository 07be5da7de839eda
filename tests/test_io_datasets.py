"""Dataset loaders: UWA 3D/2D raw frames, CFPose, plain image folders, and the dispatcher."""
import cv2
import numpy as np
import pytest

from fingersplat3d.errors import InputError
from fingersplat3d.io import (find_uwa_groups, load_any, load_cfpose, load_image_folder, load_uwa, write_capture)
from fingersplat3d.io.datasets import natural_key
from fingersplat3d.scene import Capture, View

H, W = 24, 32


def gray(seed: int, shape=(H, W)) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, shape, dtype=np.uint8)


def make_uwa(folder, groups=(("1", "2", "1"), ("1", "2", "2"), ("10", "3", "1")), frames=range(6)):
    folder.mkdir(parents=True, exist_ok=True)
    for index, (subject, finger, capture) in enumerate(groups):
        for frame in frames:
            cv2.imwrite(str(folder / f"{subject}_{finger}_{capture}_{frame}.jpg"), gray(10 * index + frame))
    return folder


def make_cfpose(folder, fingers=("1", "A3"), poses=range(1, 11)):
    folder.mkdir(parents=True, exist_ok=True)
    suffixes = (".bmp", ".png")
    for index, finger in enumerate(fingers):
        for pose in poses:
            cv2.imwrite(str(folder / f"{finger}_{pose}{suffixes[pose % 2]}"), gray(100 * index + pose))
    return folder


def test_natural_key():
    assert sorted(["img10", "img2", "Img1", "img"], key=natural_key) == ["img", "Img1", "img2", "img10"]


def test_uwa_groups_views_and_metadata(tmp_path):
    folder = make_uwa(tmp_path / "uwa")
    (folder / "readme.txt").write_text("not a frame")
    cv2.imwrite(str(folder / "thumbnail.png"), gray(0))
    captures = load_uwa(folder)
    assert [(c.metadata["subject"], c.metadata["capture"]) for c in captures] == [("1", "1"), ("1", "2"), ("10", "1")]
    first = captures[0]
    assert first.names == ["f0", "f1", "f2"] and not first.has_cameras
    assert first["f0"].image.shape == (H, W)  # 8-bit grayscale stays one channel
    expected = cv2.imread(str(folder / "1_2_1_1.jpg"), cv2.IMREAD_UNCHANGED) / 255.0
    np.testing.assert_array_equal(first["f1"].image, expected.astype(np.float32))
    assert first.metadata["dataset"] == "uwa" and first.metadata["finger"] == "2"
    assert first.metadata["sources"]["f2"].endswith("1_2_1_2.jpg")
    assert set(first.metadata["lighting"].values()) == {"plain"}


def test_uwa_filters_and_structured_light(tmp_path):
    folder = make_uwa(tmp_path / "uwa")
    only = load_uwa(folder, subject=10)
    assert len(only) == 1 and only[0].metadata["subject"] == "10"
    assert len(load_uwa(folder, subject="01", finger=2, capture=2)) == 1
    lit = load_uwa(folder, subject=1, capture=1, structured_light=True)[0]
    assert lit.names == ["f0", "f1", "f2", "f3", "f4", "f5"]
    assert lit.metadata["lighting"]["f4"] == "structured"
    with pytest.raises(InputError, match="subject=7"):
        load_uwa(folder, subject=7)


def test_uwa_only_plain_frames_needed_without_structured_light(tmp_path):
    folder = make_uwa(tmp_path / "uwa", groups=(("5", "1", "1"),), frames=range(3))
    assert len(load_uwa(folder)) == 1
    with pytest.raises(InputError, match=r"5_1_1_3\.jpg"):
        load_uwa(folder, structured_light=True)


def test_uwa_list_of_files_and_subfolders(tmp_path):
    folder = make_uwa(tmp_path / "uwa" / "subject1", groups=(("1", "2", "1"),))
    make_uwa(tmp_path / "uwa" / "subject2", groups=(("2", "2", "1"),))
    assert len(load_uwa(tmp_path / "uwa")) == 2  # dataset folders are searched recursively
    files = [folder / f"1_2_1_{frame}.jpg" for frame in range(3)]
    captures = load_uwa(files)
    assert len(captures) == 1 and captures[0].names == ["f0", "f1", "f2"]
    groups = find_uwa_groups(tmp_path / "uwa")
    assert [group.subject for group in groups] == ["1", "2"] and sorted(groups[0].frames) == list(range(6))


def test_cfpose_orders_views_by_pose(tmp_path):
    folder = make_cfpose(tmp_path / "cfpose")
    captures = load_cfpose(folder)
    assert [c.metadata["finger"] for c in captures] == ["1", "A3"]
    assert captures[0].names == [f"p{pose}" for pose in range(1, 11)]
    assert captures[1].metadata["poses"] == list(range(1, 11))
    expected = cv2.imread(str(folder / "A3_10.bmp"), cv2.IMREAD_UNCHANGED) / 255.0
    np.testing.assert_array_equal(captures[1]["p10"].image, expected.astype(np.float32))
    only = load_cfpose(folder, finger="A3")
    assert len(only) == 1 and only[0].metadata["dataset"] == "cfpose"
    with pytest.raises(InputError, match="finger 9"):
        load_cfpose(folder, finger=9)


def test_image_folder_natural_order_and_masks(tmp_path):
    folder = tmp_path / "photos"
    (folder / "masks").mkdir(parents=True)
    for index, name in enumerate(["img10", "img2", "img1"]):
        cv2.imwrite(str(folder / f"{name}.png"), gray(index))
    mask = np.zeros((H, W), np.uint8)
    mask[4:10, 5:20] = 255
    cv2.imwrite(str(folder / "masks" / "img2.png"), mask)
    cv2.imwrite(str(folder / "img10_mask.png"), mask)
    capture = load_image_folder(folder)
    assert capture.names == ["img1", "img2", "img10"]
    assert capture["img1"].mask is None
    np.testing.assert_array_equal(capture["img2"].mask, mask > 0)
    np.testing.assert_array_equal(capture["img10"].mask, mask > 0)
    assert capture.metadata["dataset"] == "images"


def test_image_folder_explicit_list_keeps_order_and_rgb(tmp_path):
    paths = []
    for index, name in enumerate(["b", "a"]):
        rgb = np.random.default_rng(index).integers(0, 256, (H, W, 3), dtype=np.uint8)
        cv2.imwrite(str(tmp_path / f"{name}.png"), rgb)
        paths.append(tmp_path / f"{name}.png")
    capture = load_image_folder(paths, min_views=2)
    assert capture.names == ["b", "a"] and capture["a"].channels == 3
    assert load_image_folder(paths, gray=True)["a"].channels == 1
    with pytest.raises(InputError, match="at least 3"):
        load_image_folder(paths, min_views=3)


def test_load_any_dispatch(tmp_path):
    uwa = make_uwa(tmp_path / "uwa", groups=(("1", "1", "1"),))
    cfpose = make_cfpose(tmp_path / "cfpose", fingers=("7",), poses=range(1, 4))
    plain = tmp_path / "plain"
    plain.mkdir()
    for name in ("left", "right"):
        cv2.imwrite(str(plain / f"{name}.jpg"), gray(3))
    capture_folder = write_capture(Capture((View("v0", np.zeros((H, W))),), {"units": "mm"}), tmp_path / "cap")

    assert [c.metadata["dataset"] for c in load_any(uwa)] == ["uwa"]
    assert load_any(cfpose)[0].names == ["p1", "p2", "p3"]
    assert load_any(plain)[0].names == ["left", "right"]
    assert load_any(capture_folder)[0].names == ["v0"]
    assert load_any([plain / "right.jpg", plain / "left.jpg"])[0].names == ["right", "left"]
    assert len(load_any([uwa, cfpose, plain])) == 3
    with pytest.raises(InputError):
        load_any([plain, plain / "left.jpg"])
    with pytest.raises(InputError, match="nowhere"):
        load_any(tmp_path / "nowhere")


def test_explicit_files_are_used_as_given(tmp_path):
    """Files the user names are one capture of exactly those files: a dataset's naming names the views, never
    groups or completes them (a UWA group without frame 1 is still three views)."""
    uwa = make_uwa(tmp_path / "uwa", groups=(("1", "1", "2"), ("1", "1", "3")))
    (capture,) = load_any([uwa / "1_1_2_2.jpg", uwa / "1_1_2_0.jpg", uwa / "1_1_2_3.jpg"])
    assert capture.names == ["f2", "f0", "f3"]  # the order given, named by frame
    assert capture.metadata["dataset"] == "uwa" and capture.metadata["name"] == "1_1_2"
    assert capture.metadata["sources"]["f0"].endswith("1_1_2_0.jpg")
    assert capture.metadata["lighting"] == {"f2": "plain", "f0": "plain", "f3": "structured"}
    mixed = load_any([uwa / "1_1_2_0.jpg", uwa / "1_1_3_1.jpg"])[0]  # two captures' frames: plain names
    assert mixed.names == ["1_1_2_0", "1_1_3_1"] and mixed.metadata["dataset"] == "images"
    cfpose = make_cfpose(tmp_path / "cfpose", fingers=("7",), poses=range(1, 5))
    (poses,) = load_any([cfpose / "7_4.bmp", cfpose / "7_1.png"])
    assert poses.names == ["p4", "p1"] and poses.metadata["poses"] == [4, 1]
    (tmp_path / "uwa" / "1_1_3_1.jpg").unlink()
    with pytest.raises(InputError, match="missing frame 1") as refused:  # a folder is a dataset: its groups whole
        load_any(uwa)
    assert "give them as files" in str(refused.value)  # and the sentence says how to fuse the frames there alone
    (partial,) = load_any([uwa / "1_1_3_0.jpg", uwa / "1_1_3_2.jpg"])  # which works
    assert partial.names == ["f0", "f2"]
    with pytest.raises(InputError, match="missing frame 1") as alone:  # one file alone: no folder to speak of
        load_any(uwa / "1_1_3_0.jpg")
    assert "give them as files" not in str(alone.value)


def test_webp_and_heic_photos_are_read_upright_and_a_gif_is_named_with_what_to_do(tmp_path):
    """A phone may save WebP or HEIC (an iPhone's default): both read, turned as the phone showed them (a WebP's EXIF
    tag, a HEIC's own turn), a HEIC in a folder as any photo; a file named HEIC that is none says so; a GIF (a palette
    of 256 colours) is named as not read, with what to do, not just "holds no images"."""
    from PIL import Image
    from pillow_heif import register_heif_opener

    register_heif_opener()
    rng = np.random.default_rng(0)
    stored = (rng.random((40, 64, 3)) * 255).astype(np.uint8)  # stored sideways, the tag turns it upright
    stored = cv2.GaussianBlur(stored, (0, 0), 2.0)  # smooth enough for HEVC to keep it close
    exif = Image.Exif()
    exif[0x0112] = 6
    for name in ("a", "b"):
        Image.fromarray(stored).save(tmp_path / f"{name}.webp", exif=exif, lossless=True)
    Image.fromarray(stored).save(tmp_path / "c.heic", exif=exif.tobytes(), quality=95)  # written as the HEIF's own turn
    capture = load_image_folder([tmp_path / "a.webp", tmp_path / "b.webp", tmp_path / "c.heic"])
    assert capture.names == ["a", "b", "c"] and all(view.image.shape == (64, 40, 3) for view in capture.views)
    webp, heic = capture.views[0].image, capture.views[2].image
    assert np.abs(heic - webp).mean() < 0.03 and np.corrcoef(heic.ravel(), webp.ravel())[0, 1] > 0.9  # the same picture
    assert load_image_folder(tmp_path).names == ["a", "b", "c"]  # a folder's HEIC is one of its photos
    (tmp_path / "d.heic").write_bytes(b"\x00\x00\x00\x18ftypheic")
    with pytest.raises(InputError, match="d.heic: not a readable HEIC/HEIF image"):
        load_image_folder([tmp_path / "a.webp", tmp_path / "d.heic"])
    only_gif = tmp_path / "web"
    only_gif.mkdir()
    Image.fromarray(stored).save(only_gif / "finger.gif")
    with pytest.raises(InputError, match="holds no images .*its GIF photos are not read: save them as JPEG"):
        load_any(only_gif)


def test_heic_without_pillow_heif_says_what_to_install(tmp_path, monkeypatch):
    import sys

    from fingersplat3d.io.images import read_image

    (tmp_path / "IMG_0001.HEIC").write_bytes(b"\x00\x00\x00\x18ftypheic")
    monkeypatch.setitem(sys.modules, "pillow_heif", None)  # as in an environment without it
    with pytest.raises(InputError, match="IMG_0001.HEIC: HEIC photos need the pillow-heif package"):
        read_image(tmp_path / "IMG_0001.HEIC")


def test_gray_stored_in_colour_is_read_gray_and_a_gif_is_refused_by_every_reader(tmp_path):
    """A gray photo saved as RGB and re-encoded lossily (channels a level apart here and there) is one channel; a
    photo whose channels differ by more is colour. A GIF is named as not read wherever a photo is read (``fs3d print``
    reads photos one by one: it had read a GIF ``fs3d fuse`` refused)."""
    from PIL import Image

    from fingersplat3d.io.images import read_image

    rng = np.random.default_rng(1)
    gray_values = (rng.random((40, 64)) * 250).astype(np.uint8)
    near = np.repeat(gray_values[..., None], 3, axis=2)
    near[::7, ::5, 1] += 1  # a lossy codec's chroma: one level on some pixels
    cv2.imwrite(str(tmp_path / "near.png"), near)
    image = read_image(tmp_path / "near.png")
    assert image.ndim == 2 and np.abs(image - gray_values / 255.0).max() <= 1.0 / 255.0
    exact = np.repeat(gray_values[..., None], 3, axis=2)
    cv2.imwrite(str(tmp_path / "exact.png"), exact)
    assert np.array_equal(read_image(tmp_path / "exact.png"), gray_values / np.float32(255.0))  # to the bit
    colour = exact.copy()
    colour[20:, :, 2] += 3  # three levels of red on the lower rows: colour
    cv2.imwrite(str(tmp_path / "colour.png"), colour)
    assert read_image(tmp_path / "colour.png").shape == (40, 64, 3)
    Image.fromarray(gray_values).save(tmp_path / "finger.gif")
    with pytest.raises(InputError, match="GIF photos are not read: save them as JPEG"):
        read_image(tmp_path / "finger.gif")


def test_every_loader_gives_a_capture_one_kind_of_channel(tmp_path):
    """A CFPose folder or a capture folder whose photos mix grayscale and colour is read in gray, as an image folder
    is (a capture folder of that kind had reached the splat fit with one channel in the model and three in a photo, and
    ended in a traceback); a capture built by hand that mixes them is refused by the fuse with one sentence."""
    from fingersplat3d.io import read_capture
    from fingersplat3d.pipeline import fuse

    colour = np.stack([gray(1), gray(2), gray(3)], -1)  # three different channels: colour
    cfpose = make_cfpose(tmp_path / "cfpose", fingers=("1",), poses=range(1, 4))
    cv2.imwrite(str(cfpose / "1_2.png"), colour)
    (cfpose / "1_2.bmp").unlink(missing_ok=True)
    (capture,) = load_cfpose(cfpose)
    assert [view.channels for view in capture.views] == [1, 1, 1]
    folder = write_capture(Capture((View("a", gray(4) / 255.0), View("b", gray(5) / 255.0))), tmp_path / "capture")
    cv2.imwrite(str(folder / "images" / "b.png"), colour)
    read = read_capture(folder)
    assert [view.channels for view in read.views] == [1, 1]
    assert np.allclose(read["b"].image, colour[..., ::-1] @ np.array([0.299, 0.587, 0.114]) / 255.0, atol=1e-5)
    mixed = Capture((View("a", gray(4) / 255.0), View("b", colour / 255.0)))
    with pytest.raises(InputError, match="mix grayscale and colour"):
        fuse(mixed)
