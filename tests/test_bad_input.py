"""Bad input fails with one InputError naming the file; failed writes leave nothing behind."""
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

import fingersplat3d.io.capture as capture_module
from fingersplat3d.errors import InputError, InputNote
from fingersplat3d.io import (load_image_folder, load_uwa, read_cameras, read_capture, read_depth, read_minutiae,
                              write_capture, write_depth)
from fingersplat3d.scene import Camera, Capture, View

H, W = 24, 32


def good_capture(with_depth=True) -> Capture:
    rng = np.random.default_rng(0)
    mask = np.zeros((H, W), bool)
    mask[2:5, 3:9] = True
    views = tuple(View(f"v{i}", rng.integers(0, 256, (H, W)) / 255.0, mask=mask,
                       depth=np.full((H, W), 10.0, np.float32) if with_depth else None,
                       camera=Camera.from_focal(40.0, W, H)) for i in range(3))
    return Capture(views, {"units": "mm"})


@pytest.fixture
def folder(tmp_path):
    return write_capture(good_capture(), tmp_path / "cap")


def raises_naming(name: str, function, *args, **kwargs) -> str:
    """Call ``function``; it must raise an InputError whose single-line message names ``name``."""
    with pytest.raises(InputError) as info:
        function(*args, **kwargs)
    message = str(info.value)
    assert name in message, message
    assert "\n" not in message
    return message


# ---------------------------------------------------------------------------------------- cameras.json

def camera_entry(**changes):
    entry = {"name": "v0", "image": "images/v0.png", "width": W, "height": H,
             "K": [[40.0, 0, 15.5], [0, 40.0, 11.5], [0, 0, 1]], "world_to_cam": np.eye(4).tolist()}
    entry.update(changes)
    return entry


@pytest.mark.parametrize("content, problem", [
    ('{"units": "mm", "views": [', "not valid JSON"),
    ('[]', "JSON object"),
    (json.dumps({"views": [camera_entry()]}), "units"),
    (json.dumps({"units": "mm"}), "views"),
    (json.dumps({"units": "inch", "views": [camera_entry()]}), "units"),
    (json.dumps({"units": "mm", "scale_mm_per_unit": 2.0, "views": [camera_entry()]}), "scale_mm_per_unit"),
    (json.dumps({"units": "arbitrary", "scale_mm_per_unit": -1, "views": [camera_entry()]}), "scale_mm_per_unit"),
    (json.dumps({"units": "mm", "views": []}), "non-empty"),
    (json.dumps({"units": "mm", "views": [{k: v for k, v in camera_entry().items() if k != "K"}]}), "'K'"),
    (json.dumps({"units": "mm", "views": [camera_entry(K=[[1, 0], [0, 1]])]}), "3x3"),
    (json.dumps({"units": "mm", "views": [camera_entry(world_to_cam=np.eye(3).tolist())]}), "4x4"),
    ('{"units": "mm", "views": [' + json.dumps(camera_entry()).replace("40.0", "NaN", 1) + "]}", "non-finite"),
    (json.dumps({"units": "mm", "views": [camera_entry(world_to_cam=np.diag([2.0, 1, 1, 1]).tolist())]}), "rigid"),
    (json.dumps({"units": "mm", "views": [camera_entry(world_to_cam=np.diag([1.0, 1, -1, 1]).tolist())]}), "rigid"),
    (json.dumps({"units": "mm", "views": [camera_entry(K=[[-4.0, 0, 1], [0, 4, 1], [0, 0, 1]])]}), "positive focal"),
    (json.dumps({"units": "mm", "views": [camera_entry(width=31.5)]}), "width"),
    (json.dumps({"units": "mm", "views": [camera_entry(K=[[4.0, 0, 1], [0, True, 1], [0, 0, 1]])]}), "numbers"),
    (json.dumps({"units": "mm", "views": [camera_entry(), camera_entry()]}), "twice"),
])
def test_bad_cameras_json(tmp_path, content, problem):
    path = tmp_path / "cameras.json"
    path.write_text(content)
    message = raises_naming("cameras.json", read_cameras, path)
    assert problem in message


def test_bad_camera_names_the_view(tmp_path):
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"units": "mm", "views": [camera_entry(), camera_entry(name="right", width=-3)]}))
    assert "'right'" in raises_naming("cameras.json", read_cameras, path)


def test_missing_cameras_json(tmp_path):
    raises_naming("cameras.json", read_cameras, tmp_path / "cameras.json")


# ------------------------------------------------------------------------------------------ depth maps

@pytest.mark.parametrize("array, problem", [
    (np.array([[1.0, np.inf]], np.float32), "Inf"),
    (np.array([[1.0, -2.0]], np.float32), "negative"),
    (np.ones((2, 2, 2), np.float32), "2-D"),
    (np.array([["a", "b"]]), "real numbers"),
])
def test_bad_depth(tmp_path, array, problem):
    path = tmp_path / "bad_depth.npy"
    np.save(path, array)
    assert problem in raises_naming("bad_depth.npy", read_depth, path)


def test_depth_wrong_shape_and_not_npy(tmp_path):
    path = write_depth(tmp_path / "d.npy", np.ones((4, 5)))
    assert "5x4" in raises_naming("d.npy", read_depth, path, shape=(4, 6))
    (tmp_path / "junk.npy").write_bytes(b"not numpy at all")
    message = raises_naming("junk.npy", read_depth, tmp_path / "junk.npy")
    assert "NumPy's header" in message and "pickle" not in message  # never a hint to load a file unsafely
    raises_naming("absent.npy", read_depth, tmp_path / "absent.npy")


def test_write_depth_refuses_inf(tmp_path):
    with pytest.raises(ValueError, match="Inf"):
        write_depth(tmp_path / "d.npy", np.array([[np.inf]]))
    assert not list(tmp_path.iterdir())


# ------------------------------------------------------------------------------------------- minutiae

@pytest.mark.parametrize("data, problem", [
    ({"views": {}}, "minutiae_3d"),
    ({"minutiae_3d": [{"id": 0, "kind": "loop", "xyz": [0, 0, 0], "direction": [1, 0, 0]}]}, "kind"),
    ({"minutiae_3d": [{"id": 0, "kind": "ending", "xyz": [0, 0], "direction": [1, 0, 0]}]}, "xyz"),
    ({"minutiae_3d": [{"id": 0, "kind": "ending", "xyz": [0, 0, 0], "direction": [0, 0, 0]}]}, "zero"),
    ({"minutiae_3d": [{"id": 0, "kind": "ending", "xyz": [0, 0, 0]}]}, "direction"),
    ({"minutiae_3d": [{"id": 0, "kind": "ending", "xyz": [0, 0, 0], "direction": [1, 0, 0]}] * 2}, "repeats"),
    ({"minutiae_3d": [], "views": {"v0": [{"id": 3, "uv": [1, 2], "angle_deg": 0, "visible": True}]}}, "id 3"),
    ({"minutiae_3d": [{"id": 0, "kind": "ending", "xyz": [0, 0, 0], "direction": [1, 0, 0]}],
      "views": {"v0": [{"id": 0, "uv": [1, 2], "angle_deg": 0, "visible": "yes"}]}}, "visible"),
])
def test_bad_minutiae(tmp_path, data, problem):
    path = tmp_path / "minutiae.json"
    path.write_text(json.dumps(data))
    assert problem in raises_naming("minutiae.json", read_minutiae, path)


def test_minutiae_invalid_json(tmp_path):
    (tmp_path / "minutiae.json").write_text("{oops")
    raises_naming("minutiae.json", read_minutiae, tmp_path / "minutiae.json")


# ------------------------------------------------------------------------------------- capture folders

def test_capture_folder_missing(tmp_path):
    raises_naming("nothing_here", read_capture, tmp_path / "nothing_here")


def test_capture_without_images_folder(tmp_path):
    (tmp_path / "empty").mkdir()
    raises_naming("empty", read_capture, tmp_path / "empty")


def test_capture_images_folder_without_images(tmp_path):
    (tmp_path / "cap" / "images").mkdir(parents=True)
    raises_naming("images", read_capture, tmp_path / "cap")


def test_listed_image_missing(folder):
    (folder / "images" / "v1.png").unlink()
    assert "'v1'" in raises_naming("v1.png", read_capture, folder)


def test_unreadable_image(folder):
    (folder / "images" / "v2.png").write_bytes(b"\x89PNG garbage")
    raises_naming("v2.png", read_capture, folder)


def test_mask_size_mismatch(folder):
    cv2.imwrite(str(folder / "masks" / "v0.png"), np.full((H, W + 1), 255, np.uint8))
    raises_naming("v0.png", read_capture, folder)


def test_empty_mask(folder):
    cv2.imwrite(str(folder / "masks" / "v1.png"), np.zeros((H, W), np.uint8))
    assert "empty" in raises_naming("v1.png", read_capture, folder)


def test_depth_inf_is_an_error_nan_only_is_fine(folder):
    np.save(folder / "depth" / "v0.npy", np.full((H, W), np.nan, np.float32))
    assert np.isnan(read_capture(folder)["v0"].depth).all()
    depth = np.full((H, W), 5.0, np.float32)
    depth[1, 1] = np.inf
    np.save(folder / "depth" / "v1.npy", depth)
    assert "Inf" in raises_naming("v1.npy", read_capture, folder)


def test_depth_wrong_shape_in_capture(folder):
    np.save(folder / "depth" / "v2.npy", np.ones((H - 1, W), np.float32))
    raises_naming("v2.npy", read_capture, folder)


def edit_json(path, change):
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def test_cameras_name_a_view_without_image(folder):
    edit_json(folder / "cameras.json", lambda data: data["views"].append({**data["views"][0], "name": "ghost"}))
    assert "'ghost'" in raises_naming("cameras.json", read_capture, folder)


def test_cameras_miss_a_view(folder):
    edit_json(folder / "cameras.json", lambda data: data["views"].pop())
    assert "'v2'" in raises_naming("cameras.json", read_capture, folder)


def test_cameras_size_differs_from_image(folder):
    edit_json(folder / "cameras.json", lambda data: data["views"][1].update(width=64))
    assert "64x24" in raises_naming("cameras.json", read_capture, folder)


@pytest.mark.parametrize("change, problem", [
    (lambda data: data.update(format="fingersplat3d-reconstruction"), "format"),
    (lambda data: data.update(version=99), "newer"),
    (lambda data: data.update(version="1"), "version"),
    (lambda data: data.update(views="v0"), "views"),
    (lambda data: data.update(views=["v0", "v0"]), "twice"),
    (lambda data: data.update(files=[]), "files"),
    (lambda data: data.update(metadata=3), "metadata"),
    (lambda data: data["files"]["images"].update(v0="../../etc/passwd"), "outside"),
    (lambda data: data["files"]["images"].update(v9="images/v9.png"), "'v9'"),
])
def test_malformed_manifest(folder, change, problem):
    edit_json(folder / "manifest.json", change)
    assert problem in raises_naming("manifest.json", read_capture, folder)


@pytest.mark.parametrize("foreign", [{"format": "acme-dataset", "subject": 3}, {"subject": 3}, ["v0", "v1"]])
def test_foreign_manifest_is_ignored_with_a_note(folder, foreign):
    """A manifest.json another tool wrote (a dataset's own) is set aside with a note; images/ is read."""
    (folder / "manifest.json").write_text(json.dumps(foreign))
    with pytest.warns(InputNote, match="not a fingersplat3d capture manifest"):
        capture = read_capture(folder)
    assert capture.names == ["v0", "v1", "v2"] and capture_module.is_capture_folder(folder)
    (folder / "images").rename(folder / "photos")  # then it is no capture folder at all
    assert not capture_module.is_capture_folder(folder)


def test_foreign_manifest_note_on_the_command_line(folder, capsys):
    from fingersplat3d.cli import main

    (folder / "manifest.json").write_text(json.dumps({"format": "acme-dataset"}))
    assert main(["info", str(folder)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fs3d info: note: ") and "acme-dataset" in err[0]


def test_manifest_invalid_json(folder):
    (folder / "manifest.json").write_text('{"format": ')
    raises_naming("manifest.json", read_capture, folder)


def test_manifest_lists_a_missing_view(folder):
    edit_json(folder / "manifest.json", lambda data: data["views"].append("v7"))
    assert "'v7'" in raises_naming("v7.png", read_capture, folder)


# ------------------------------------------------------------------------------------------- datasets

def test_uwa_incomplete_group_names_group_and_file(tmp_path):
    for frame in (0, 2):
        cv2.imwrite(str(tmp_path / f"3_1_2_{frame}.jpg"), np.zeros((H, W), np.uint8))
    message = raises_naming("3_1_2_1.jpg", load_uwa, tmp_path)
    assert "subject 3, finger 1, capture 2" in message and "frame 1" in message


def test_uwa_nothing_matches(tmp_path):
    cv2.imwrite(str(tmp_path / "photo.jpg"), np.zeros((H, W), np.uint8))
    raises_naming(tmp_path.name, load_uwa, tmp_path)


def test_uwa_frames_of_different_sizes_and_orientations_load(tmp_path):
    # Real datasets store a camera portrait now and then (UWA 1_1_4_1_0.jpg): the views keep their own sizes.
    for frame in range(3):
        shape = (W, H) if frame == 0 else (H, W)
        cv2.imwrite(str(tmp_path / f"1_1_1_{frame}.jpg"), np.zeros(shape, np.uint8))
    (capture,) = load_uwa(tmp_path)
    assert [v.image.shape for v in capture.views] == [(W, H), (H, W), (H, W)]


def test_mixed_gray_and_colour_views_and_too_few(tmp_path):
    # A capture whose views mix grayscale and colour is fused in the one channel they all have, not refused.
    for name, channels in (("a", 1), ("b", 1), ("c", 3)):
        cv2.imwrite(str(tmp_path / f"{name}.png"), np.zeros((H, W, channels), np.uint8) + 40 * np.arange(channels, dtype=np.uint8))
    capture = load_image_folder(tmp_path)
    assert [view.image.ndim for view in capture.views] == [2, 2, 2]
    assert np.allclose(capture.views[2].image, (0.299 * 80 + 0.587 * 40) / 255, atol=1e-6)  # stored B, G, R = 0, 40, 80
    (tmp_path / "c.png").unlink()
    raises_naming(tmp_path.name, load_image_folder, tmp_path, min_views=3)
    raises_naming("missing.png", load_image_folder, [tmp_path / "a.png", tmp_path / "missing.png"])
    (tmp_path / "notes.txt").write_text("hi")
    raises_naming("notes.txt", load_image_folder, [tmp_path / "a.png", tmp_path / "notes.txt"])


def test_image_folder_empty_mask(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((H, W), np.uint8))
    cv2.imwrite(str(tmp_path / "a_mask.png"), np.zeros((H, W), np.uint8))
    raises_naming("a_mask.png", load_image_folder, tmp_path)


# ------------------------------------------------------------------------------ nothing half-written

def leftovers(parent):
    return sorted(path.name for path in parent.iterdir())


@pytest.mark.parametrize("writer", ["write_mask", "write_depth", "write_cameras", "write_image"])
def test_failed_write_leaves_nothing(tmp_path, monkeypatch, writer):
    original = getattr(capture_module, writer)
    calls = []

    def fail_after_first(*args, **kwargs):
        calls.append(args[0])
        if len(calls) > 1 or writer in ("write_cameras",):
            raise OSError("disk full (simulated)")
        return original(*args, **kwargs)

    monkeypatch.setattr(capture_module, writer, fail_after_first)
    with pytest.raises(OSError, match="simulated"):
        write_capture(good_capture(), tmp_path / "out")
    assert calls  # the writer was reached, so something had been written before the failure
    assert leftovers(tmp_path) == []


def test_failed_overwrite_keeps_the_old_folder(tmp_path, monkeypatch):
    folder = write_capture(good_capture(), tmp_path / "out")
    before = read_capture(folder)

    def broken(*args, **kwargs):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(capture_module, "write_depth", broken)
    with pytest.raises(OSError):
        write_capture(good_capture(with_depth=True), folder, overwrite=True)
    assert leftovers(tmp_path) == ["out"]
    after = read_capture(folder)
    for x, y in zip(before.views, after.views):
        np.testing.assert_array_equal(x.image, y.image)


def test_unwritable_inputs_are_refused_before_writing(tmp_path):
    capture = good_capture()
    empty = Capture((capture.views[0], capture.views[1].with_(mask=np.zeros((H, W), bool))))
    assert "empty mask" in raises_naming("out", write_capture, empty, tmp_path / "out")
    bad_name = Capture((capture.views[0].with_(name="a/b"),))
    raises_naming("out", write_capture, bad_name, tmp_path / "out")
    inf_depth = Capture((capture.views[0].with_(depth=np.full((H, W), np.inf, np.float32)),))
    raises_naming("out", write_capture, inf_depth, tmp_path / "out")
    assert leftovers(tmp_path) == []


# ------------------------------------------------------------------------------ fs3d fuse: failures said once

def _stderr_lines(text: str) -> list[str]:
    """What a terminal shows last: progress-bar redraws (carriage returns) split like new lines."""
    return [line for line in text.replace("\r", "\n").splitlines() if line.strip()]


def _write_views(folder, views):
    folder.mkdir()
    for view in views:
        cv2.imwrite(str(folder / f"{view.name}.png"), np.clip(view.image * 255, 0, 255).astype(np.uint8))
    return folder


@pytest.fixture(scope="module")
def two_fingers(tmp_path_factory):
    from fingersplat3d.synth import SynthConfig, synthesize

    a = synthesize(1, SynthConfig(size=(320, 256))).capture["center"]
    b = synthesize(4, SynthConfig(size=(320, 256))).capture["left"].with_(name="other")
    return _write_views(tmp_path_factory.mktemp("fingers") / "two", [a, b])


def test_views_that_cannot_be_registered_exit_3_with_outputs_written(two_fingers, tmp_path, capsys):
    from fingersplat3d.cli import main
    from fingersplat3d.errors import EXIT_NOT_REGISTERED

    out = tmp_path / "rec"
    assert main(["fuse", str(two_fingers), "-o", str(out), "--no-splat"]) == EXIT_NOT_REGISTERED
    last = _stderr_lines(capsys.readouterr().err)[-1]
    assert last.startswith("fs3d fuse: view(s) other could not be registered") and "Traceback" not in last
    report = json.loads((out / "report.json").read_text())
    assert report["alignment"]["ok"] is False and report["alignment"]["not_registered"] == ["other"]
    assert (out / "fused.ply").is_file() and (out / "cameras.json").is_file()


def test_photos_too_small_for_their_ridges_say_so_and_print_no_residual(tmp_path, capsys):
    """Three photos of a finger shrunk to 64x51 px: no ridges to register by. The summary line had read "alignment
    residual nan px"."""
    from fingersplat3d.cli import main
    from fingersplat3d.errors import EXIT_NOT_REGISTERED

    images = Path(__file__).resolve().parents[1] / "data_samples" / "uwa_seed0" / "images"
    small = tmp_path / "small"
    small.mkdir()
    for path in sorted(images.glob("*.png")):
        photo = cv2.imread(str(path))
        cv2.imwrite(str(small / path.name), cv2.resize(photo, (64, 51), interpolation=cv2.INTER_AREA))
    assert main(["fuse", str(small), "-o", str(tmp_path / "rec"), "--no-splat"]) == EXIT_NOT_REGISTERED
    captured = capsys.readouterr()
    assert "nan" not in captured.out and "no two views aligned" in captured.out
    assert "no ridges found" in captured.err and "Traceback" not in captured.err


def test_one_view_says_there_is_nothing_to_align(two_fingers, tmp_path, capsys):
    from fingersplat3d.cli import main

    assert main(["fuse", str(two_fingers / "center.png"), "-o", str(tmp_path / "one"), "--no-splat"]) == 0
    out = capsys.readouterr().out
    assert "one view: nothing to align" in out and "nan" not in out


@pytest.mark.parametrize("option, value", [("--polish-iterations", "-5"), ("--guided-rounds", "1.5"),
                                           ("--splat-iterations", "-1"), ("--px-per-mm", "nan"),
                                           ("--finger-width-mm", "-3"), ("--pair-batch", "0"), ("--px-per-mm", "1e-9"),
                                           ("--finger-width-mm", "500")])
def test_numeric_options_are_range_checked_in_one_sentence(two_fingers, tmp_path, capsys, option, value):
    from fingersplat3d.cli import main

    assert main(["fuse", str(two_fingers), "-o", str(tmp_path / "x"), option, value]) == 2
    lines = _stderr_lines(capsys.readouterr().err)
    assert len(lines) == 1 and option in lines[0] and not (tmp_path / "x").exists()


@pytest.mark.parametrize("command", [["synth", "{out}", "--seed", "-1"], ["fuse", "{out}", "-o", "{out}/x", "--seed", "-2"],
                                     ["bench", "-o", "{out}/x", "--seeds", "0"]])
def test_seeds_are_range_checked_in_one_sentence(tmp_path, capsys, command):
    """A negative seed had reached numpy's generator and ended in its traceback."""
    from fingersplat3d.cli import main

    assert main([part.format(out=tmp_path / "s") for part in command]) == 2
    lines = _stderr_lines(capsys.readouterr().err)
    assert len(lines) == 1 and "--seed" in lines[0] and not (tmp_path / "s").exists()


def test_an_error_inside_fuse_is_the_last_line_not_mixed_into_the_progress_bar(two_fingers, tmp_path, capsys):
    from fingersplat3d.cli import main

    cv2.imwrite(str(two_fingers.parent / "black.png"), np.zeros((256, 320), np.uint8))
    inputs = [str(two_fingers / "center.png"), str(two_fingers.parent / "black.png")]
    assert main(["fuse", *inputs, "-o", str(tmp_path / "x"), "--no-splat"]) == 2
    lines = _stderr_lines(capsys.readouterr().err)
    assert lines[-1].startswith("fs3d fuse: error:") and "no finger found" in lines[-1]
    assert "fs3d fuse: error" not in " ".join(lines[:-1]) and not (tmp_path / "x").exists()


def test_a_backend_without_points_on_the_finger_is_one_sentence(two_fingers):
    from fingersplat3d.pipeline import FuseConfig, fuse
    from fingersplat3d.pointmaps import register_backend
    from fingersplat3d.pointmaps.base import Pointmap
    from fingersplat3d.io.datasets import load_image_folder

    class Empty:
        name = "empty"

        def predict_views(self, views):
            return [Pointmap(i, np.full(v.image.shape[:2] + (3,), np.nan, np.float32), np.zeros(v.image.shape[:2], np.float32), 100.0)
                    for i, v in enumerate(views)]

    register_backend("empty", Empty)
    raises_naming("gave no finite 3D point on the finger", fuse, load_image_folder(two_fingers), FuseConfig(backend="empty", splat=None))


def test_truncated_jpeg_is_named(tmp_path, capfd):
    """An interrupted copy: OpenCV decodes what is there and fills the rest grey; the reader refuses it instead, before
    decoding (libjpeg's own complaint on stderr would stand above the sentence), while a whole JPEG with data appended
    after its end (as cameras append a second picture) still reads."""
    from fingersplat3d.io.images import read_image

    rng = np.random.default_rng(1)
    image = (rng.random((64, 80)) * 255).astype(np.uint8)
    ok, encoded = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 90])
    data = encoded.tobytes()
    (tmp_path / "cut.jpg").write_bytes(data[: len(data) * 2 // 3])
    capfd.readouterr()
    assert "truncated" in raises_naming("cut.jpg", read_image, tmp_path / "cut.jpg")
    assert capfd.readouterr().err == ""
    (tmp_path / "whole.jpg").write_bytes(data + data + b"\xff\xda trailing bytes")
    assert read_image(tmp_path / "whole.jpg").shape == (64, 80)
    (tmp_path / "progressive.jpg").write_bytes(
        cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])[1].tobytes()[:-2])
    assert "truncated" in raises_naming("progressive.jpg", read_image, tmp_path / "progressive.jpg")
