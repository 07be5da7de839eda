"""Capture folders, cameras.json, depth maps and minutiae.json: exact round trips."""
import json

import cv2
import numpy as np
import pytest

from fingersplat3d.io import (CameraSet, capture_files, depth_colormap, read_cameras, read_capture, read_depth,
                              read_image, read_minutiae, write_cameras, write_capture, write_depth,
                              write_depth_preview, write_minutiae)
from fingersplat3d.io.jsonio import to_jsonable
from fingersplat3d.scene import Camera, Capture, View, look_at

H, W = 24, 32


def quantised(rng, shape, bits):
    """Random image whose values are exactly representable at ``bits``."""
    top = 255 if bits == 8 else 65535
    return (rng.integers(0, top + 1, size=shape) / top).astype(np.float32)


def camera(index: int) -> Camera:
    angle = 0.4 * index
    pose = look_at([20 * np.sin(angle), 0.3 * index, -20 * np.cos(angle)], [0, 0, 0], [0, -1, 0])
    K = np.array([[55.0 + index, 0, 14.25 + index], [0, 54.5, 10.75], [0, 0, 1]])
    return Camera(K, pose, W, H)


def make_capture(bits=8, seed=0, cameras=True, metadata=None, colour=False) -> Capture:
    """Three views, all gray or all colour (the loaders read a capture's photos in one kind of channel)."""
    rng = np.random.default_rng(seed)
    depth = rng.uniform(15, 25, size=(H, W)).astype(np.float32)
    depth[:3] = np.nan
    mask = np.zeros((H, W), bool)
    mask[5:20, 4:30] = True
    shape = (H, W, 3) if colour else (H, W)
    views = (
        View("v0", quantised(rng, shape, bits), mask=mask, depth=depth, camera=camera(0) if cameras else None),
        View("v1", quantised(rng, shape, bits), camera=camera(1) if cameras else None),
        View("v2", quantised(rng, shape, bits), depth=np.full((H, W), np.nan, np.float32),
             camera=camera(2) if cameras else None),
    )
    return Capture(views, metadata if metadata is not None else {"seed": np.int64(seed), "rig": "ring"})


def assert_same_capture(a: Capture, b: Capture):
    assert a.names == b.names
    for x, y in zip(a.views, b.views):
        assert x.image.shape == y.image.shape
        np.testing.assert_array_equal(x.image, y.image)
        for field in ("mask", "depth"):
            if getattr(x, field) is None:
                assert getattr(y, field) is None
            else:
                np.testing.assert_array_equal(getattr(x, field), getattr(y, field))
        if x.camera is None:
            assert y.camera is None
        else:
            np.testing.assert_array_equal(x.camera.K, y.camera.K)
            np.testing.assert_array_equal(x.camera.world_to_cam, y.camera.world_to_cam)


@pytest.mark.parametrize("bits, colour", [(8, False), (16, False), (8, True), (16, True)])
def test_capture_round_trip_is_exact(tmp_path, bits, colour):
    capture = make_capture(bits, colour=colour)
    folder = write_capture(capture, tmp_path / "cap", image_bits=bits)
    back = read_capture(folder)
    assert_same_capture(capture, back)
    assert [view.channels for view in back.views] == [3 if colour else 1] * 3
    sources = back.metadata.pop("sources")  # where each photo was read from, for cameras.json
    assert back.metadata == {"seed": 0, "rig": "ring", "units": "mm"}
    assert sources == {name: str((folder / "images" / f"{name}.png").resolve()) for name in back.names}
    raw = cv2.imread(str(folder / "images" / "v0.png"), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == (np.uint8 if bits == 8 else np.uint16)
    # and once more through disk: read -> write -> read keeps every value
    again = read_capture(write_capture(back, tmp_path / "again", image_bits=bits))
    assert_same_capture(back, again)


def test_capture_folder_layout_and_manifest(tmp_path):
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh.create_box(1.0, 2.0, 3.0)
    minutiae = {"minutiae_3d": [{"id": 0, "kind": "ending", "xyz": [1, 2, 3], "direction": [0, 0, 1]}],
                "views": {"v0": [{"id": 0, "uv": [3.5, 4.0], "angle_deg": 30.0, "visible": True}]},
                "pattern_class": "loop"}
    metadata = {"seed": np.int32(4), "spacing": np.float32(0.5), "offsets": np.arange(3), "gap": float("nan"),
                "units": "mm"}
    folder = write_capture(make_capture(metadata=metadata), tmp_path / "cap", minutiae=minutiae, mesh=mesh,
                           extra_manifest={"generator": "test"})
    names = sorted(path.relative_to(folder).as_posix() for path in folder.rglob("*") if path.is_file())
    assert names == ["cameras.json", "depth/v0.npy", "depth/v2.npy", "images/v0.png", "images/v1.png",
                     "images/v2.png", "manifest.json", "masks/v0.png", "mesh.ply", "minutiae.json"]
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["format"] == "fingersplat3d-capture" and manifest["version"] == 1
    assert manifest["created_by"].startswith("fingersplat3d ")
    assert manifest["views"] == ["v0", "v1", "v2"]
    assert manifest["files"]["masks"] == {"v0": "masks/v0.png"}
    assert manifest["files"]["depth"] == {"v0": "depth/v0.npy", "v2": "depth/v2.npy"}
    assert manifest["files"]["mesh"] == "mesh.ply" and manifest["files"]["minutiae"] == "minutiae.json"
    assert manifest["metadata"] == {"seed": 4, "spacing": 0.5, "offsets": [0, 1, 2], "gap": None, "units": "mm"}
    assert manifest["generator"] == "test"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries left
    files = capture_files(folder)
    assert files.mesh == folder / "mesh.ply" and files.minutiae == folder / "minutiae.json"
    assert read_minutiae(files.minutiae)["pattern_class"] == "loop"
    back = o3d.io.read_triangle_mesh(str(files.mesh))
    assert len(back.vertices) == len(mesh.vertices) and len(back.triangles) == len(mesh.triangles)
    assert b"binary" in (folder / "mesh.ply").read_bytes()[:200]


def test_capture_without_cameras_has_no_cameras_json(tmp_path):
    folder = write_capture(make_capture(cameras=False), tmp_path / "cap")
    assert not (folder / "cameras.json").exists()
    back = read_capture(folder)
    assert not back.has_cameras and "units" not in back.metadata


def test_read_without_manifest_uses_natural_order(tmp_path):
    rng = np.random.default_rng(1)
    views = tuple(View(f"v{i}", quantised(rng, (H, W), 8)) for i in (10, 2, 1))
    folder = write_capture(Capture(views), tmp_path / "cap")
    (folder / "manifest.json").unlink()
    back = read_capture(folder)
    assert back.names == ["v1", "v2", "v10"]
    np.testing.assert_array_equal(back["v10"].image, views[0].image)


def test_read_capture_skip_depth_and_arbitrary_units(tmp_path):
    capture = make_capture(metadata={"units": "arbitrary", "scale_mm_per_unit": 0.25})
    folder = write_capture(capture, tmp_path / "cap")
    assert read_cameras(folder / "cameras.json").scale_mm_per_unit == 0.25
    back = read_capture(folder, load_depth=False)
    assert all(view.depth is None for view in back.views)
    assert back.metadata["units"] == "arbitrary" and back.metadata["scale_mm_per_unit"] == 0.25


def test_overwrite(tmp_path):
    folder = write_capture(make_capture(seed=1), tmp_path / "cap")
    with pytest.raises(FileExistsError, match=r"already exists \(a folder with files in it\); use --overwrite"):
        write_capture(make_capture(seed=2), folder)
    write_capture(make_capture(seed=2), folder, overwrite=True)
    assert_same_capture(read_capture(folder), make_capture(seed=2))
    assert [p.name for p in tmp_path.iterdir()] == ["cap"]


def test_cameras_round_trip_exact_and_list_form(tmp_path):
    cams = {f"v{i}": camera(i) for i in range(3)}
    path = write_cameras(tmp_path / "cameras.json", cams)
    read = read_cameras(path)
    assert isinstance(read, CameraSet) and read.names == ["v0", "v1", "v2"] and read.units == "mm"
    assert read.images == {f"v{i}": f"images/v{i}.png" for i in range(3)}
    for name, cam in cams.items():
        np.testing.assert_array_equal(read.cameras[name].K, cam.K)
        np.testing.assert_array_equal(read.cameras[name].world_to_cam, cam.world_to_cam)
    write_cameras(tmp_path / "b.json", [("left", "/data/in/left.jpg", cams["v0"])], units="arbitrary")
    other = read_cameras(tmp_path / "b.json")
    assert other.images == {"left": "/data/in/left.jpg"} and other.units == "arbitrary"
    assert other.scale_mm_per_unit is None
    write_cameras(tmp_path / "c.json", read.entries())
    assert read_cameras(tmp_path / "c.json").images == read.images


def test_depth_round_trip_and_pictures(tmp_path):
    depth = np.array([[1.0, 2.0, np.nan], [3.0, 0.0, 1.5]], np.float32)
    back = read_depth(write_depth(tmp_path / "d.npy", depth), shape=(2, 3))
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, depth)
    preview_path = write_depth_preview(tmp_path / "d.png", depth)
    preview = cv2.imread(str(preview_path), cv2.IMREAD_UNCHANGED)
    assert preview.dtype == np.uint16
    assert preview[1, 1] == 65535 and preview[1, 0] == 1 and preview[0, 2] == 0  # near bright, far 1, NaN 0
    assert 1 < preview[0, 0] < 65535
    colours = depth_colormap(depth)
    assert colours.shape == (2, 3, 3) and colours.dtype == np.uint8
    assert (colours[0, 2] == 0).all() and colours[1, 1].any()
    all_nan = depth_colormap(np.full((2, 2), np.nan))
    assert not all_nan.any()
    flat = cv2.imread(str(write_depth_preview(tmp_path / "flat.png", np.full((2, 2), 5.0))), cv2.IMREAD_UNCHANGED)
    assert (flat == 65535).all()


def test_minutiae_round_trip_keeps_free_keys(tmp_path):
    data = {"minutiae_3d": [{"id": 1, "kind": "bifurcation", "xyz": np.array([0.5, 1.0, 2.0]),
                             "direction": (1, 0, 0)},
                            {"id": "m2", "kind": "ending", "xyz": [0, 0, 0], "direction": [0, 1, 0]}],
            "views": {"v0": [{"id": "m2", "uv": np.array([1.5, 2.5]), "angle_deg": np.float32(90), "visible": False}]},
            "cores": [[1.0, 2.0, 3.0]], "deltas": [], "angle_convention": "degrees counter-clockwise from +u"}
    back = read_minutiae(write_minutiae(tmp_path / "minutiae.json", data))
    assert back["minutiae_3d"][0]["xyz"] == [0.5, 1.0, 2.0]
    assert back["minutiae_3d"][1]["id"] == "m2"
    assert back["views"]["v0"][0] == {"id": "m2", "uv": [1.5, 2.5], "angle_deg": 90.0, "visible": False}
    assert back["cores"] == [[1.0, 2.0, 3.0]] and back["angle_convention"].startswith("degrees")
    only_3d = read_minutiae(write_minutiae(tmp_path / "m2.json", {"minutiae_3d": []}))
    assert only_3d == {"minutiae_3d": [], "views": {}}


def test_to_jsonable():
    assert to_jsonable({1: (np.float64(1.5), np.array([[1, 2]])), "p": float("inf")}) == {"1": [1.5, [[1, 2]]],
                                                                                            "p": None}
    assert to_jsonable({"names": {"b", "a"}, "cut": frozenset({2, 1})}) == {"names": ["a", "b"], "cut": [1, 2]}
    with pytest.raises(TypeError, match=r"metadata\.x\.y: cannot store a object"):
        to_jsonable({"x": {"y": object()}})


def test_read_image_round_trip_8_and_16_bit_files(tmp_path):
    # files written by other tools: the exact integers survive read -> write -> read
    rng = np.random.default_rng(5)
    raw8 = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    raw16 = rng.integers(0, 65536, (H, W), dtype=np.uint16)
    cv2.imwrite(str(tmp_path / "a.png"), raw8)
    cv2.imwrite(str(tmp_path / "b.png"), raw16)
    capture = Capture((View("a", read_image(tmp_path / "a.png")),))
    folder = write_capture(capture, tmp_path / "c8")
    np.testing.assert_array_equal(cv2.imread(str(folder / "images" / "a.png"), cv2.IMREAD_UNCHANGED), raw8)
    capture = Capture((View("b", read_image(tmp_path / "b.png")),))
    folder = write_capture(capture, tmp_path / "c16", image_bits=16)
    np.testing.assert_array_equal(cv2.imread(str(folder / "images" / "b.png"), cv2.IMREAD_UNCHANGED), raw16)


def test_a_phone_photo_is_read_upright(tmp_path):
    """A JPEG stored sideways with an EXIF orientation tag (as phones write them) is read as a viewer shows it;
    its alpha-free pixels and the other formats are read as stored."""
    from PIL import Image

    stored = np.zeros((40, 60, 3), np.uint8)
    stored[:, :, 0] = np.arange(60, dtype=np.uint8)[None, :] * 4  # red grows to the right, as stored
    picture = Image.fromarray(stored)
    tags = picture.getexif()
    tags[274] = 6  # "rotate 90 clockwise to display"
    picture.save(tmp_path / "phone.jpg", exif=tags, quality=100)
    picture.save(tmp_path / "plain.jpg", quality=100)
    upright, plain = read_image(tmp_path / "phone.jpg"), read_image(tmp_path / "plain.jpg")
    assert plain.shape[:2] == (40, 60) and upright.shape[:2] == (60, 40)
    assert upright[:, :, 0].mean(axis=1)[-1] > upright[:, :, 0].mean(axis=1)[0] + 0.5  # red now grows downward


def test_other_formats_and_colour_modes_read_as_the_same_picture(tmp_path):
    """CMYK JPEG, palette, RGBA and 16-bit PNG, TIFF, WebP and BMP (what other tools and cameras write) come back as
    the picture they hold: a capture in each fused whole (docs/measurements.md, stop 106)."""
    from PIL import Image

    rng = np.random.default_rng(3)
    gray = cv2.GaussianBlur(rng.integers(0, 256, (H, W), dtype=np.uint8), (0, 0), 2.0)  # smooth: JPEG keeps it
    picture = Image.fromarray(np.repeat(gray[..., None], 3, axis=2))
    writes = {"cmyk.jpg": lambda p: picture.convert("CMYK").save(p, quality=100),
              "palette.png": lambda p: picture.quantize(256).save(p),
              "rgba.png": lambda p: picture.convert("RGBA").save(p),
              "gray16.png": lambda p: cv2.imwrite(str(p), gray.astype(np.uint16) * 257),
              "plain.tif": lambda p: picture.save(p), "plain.webp": lambda p: picture.save(p, lossless=True),
              "plain.bmp": lambda p: picture.save(p)}
    for name, write in writes.items():
        write(tmp_path / name)
        image = read_image(tmp_path / name, gray=True)
        assert image.shape == (H, W) and image.dtype == np.float32, name
        assert np.abs(image * 255 - gray).max() < (6 if name.endswith("jpg") else 1.01), name


def test_an_output_path_that_is_a_file_is_named_so(tmp_path):
    (tmp_path / "out").write_text("mine")
    with pytest.raises(FileExistsError, match=r"already exists \(a file\); use --overwrite"):
        write_capture(make_capture(seed=1), tmp_path / "out")
    assert (tmp_path / "out").read_text() == "mine"
