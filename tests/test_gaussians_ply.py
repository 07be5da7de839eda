"""The standard 3DGS PLY: exact round trip, readable by MeshLab, foreign fields, corrupt files."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from fingersplat3d.errors import InputError
from fingersplat3d.io.gaussians_ply import (
    GAUSSIAN_PLY_FIELDS,
    read_gaussians_ply,
    write_gaussians_ply,
)
from fingersplat3d.splat.gaussians import Gaussians


def random_gaussians(count: int, channels: int, seed: int = 0) -> Gaussians:
    generator = torch.Generator().manual_seed(seed)
    return Gaussians(torch.randn(count, 3, generator=generator) * 10,
                     torch.randn(count, 4, generator=generator),
                     torch.randn(count, 3, generator=generator) - 3,
                     torch.randn(count, generator=generator),
                     torch.randn(count, channels, generator=generator))


def assert_same(a: Gaussians, b: Gaussians) -> None:
    for x, y in zip(a.tensors(), b.tensors()):
        assert x.dtype == y.dtype == torch.float32
        assert torch.equal(x, y)


@pytest.mark.parametrize("channels", [1, 3])
def test_round_trip_is_exact(tmp_path, channels):
    gaussians = random_gaussians(257, channels)
    path = write_gaussians_ply(tmp_path / "g.ply", gaussians)
    back = read_gaussians_ply(path, channels=channels)
    assert_same(gaussians, back)
    if channels == 1:  # a grayscale model writes its channel three times; reading it plain gives RGB
        rgb = read_gaussians_ply(path)
        assert rgb.channels == 3 and torch.equal(rgb.sh_dc, gaussians.sh_dc.repeat(1, 3))
    assert not [p for p in tmp_path.iterdir() if p.name != "g.ply"]  # no temporary left behind


def test_header_is_standard_3dgs(tmp_path):
    path = write_gaussians_ply(tmp_path / "g.ply", random_gaussians(5, 3))
    data = path.read_bytes()
    header = data[:data.index(b"end_header")].decode().splitlines()
    assert header[1] == "format binary_little_endian 1.0"
    assert [line.split()[2] for line in header if line.startswith("property")] == list(GAUSSIAN_PLY_FIELDS)
    assert all(line.split()[1] == "float" for line in header if line.startswith("property"))
    assert len(data) - data.index(b"end_header\n") - len(b"end_header\n") == 5 * 17 * 4


def test_gray_with_colour_file_averages(tmp_path):
    gaussians = random_gaussians(10, 3)
    path = write_gaussians_ply(tmp_path / "g.ply", gaussians)
    gray = read_gaussians_ply(path, channels=1)
    assert gray.channels == 1
    assert torch.allclose(gray.sh_dc[:, 0], gaussians.sh_dc.mean(1), atol=1e-6)


def test_opens_in_pymeshlab(tmp_path):
    pymeshlab = pytest.importorskip("pymeshlab")
    path = write_gaussians_ply(tmp_path / "g.ply", random_gaussians(123, 1))
    meshes = pymeshlab.MeshSet()
    meshes.load_new_mesh(str(path))
    assert meshes.current_mesh().vertex_number() == 123
    vertices = meshes.current_mesh().vertex_matrix()
    assert np.allclose(vertices, read_gaussians_ply(path).means.numpy(), atol=1e-5)


def test_opens_in_open3d(tmp_path):
    o3d = pytest.importorskip("open3d")
    gaussians = random_gaussians(40, 3)
    path = write_gaussians_ply(tmp_path / "g.ply", gaussians)
    cloud = o3d.io.read_point_cloud(str(path))
    assert np.allclose(np.asarray(cloud.points), gaussians.means.numpy(), atol=1e-5)


def write_foreign(path, count: int, byte_order: str = "<", rest: int = 45, kind: str = "f4"):
    """A file as other 3DGS tools write it: f_rest_*, a different property order, maybe doubles."""
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
             *(f"f_rest_{i}" for i in range(rest)), "opacity", "scale_0", "scale_1", "scale_2",
             "rot_0", "rot_1", "rot_2", "rot_3", "extra"]
    rng = np.random.default_rng(1)
    block = np.zeros(count, dtype=[(name, byte_order + kind) for name in names])
    for name in names:
        block[name] = rng.normal(size=count)
    type_name = {"f4": "float", "f8": "double"}[kind]
    order = {"<": "binary_little_endian", ">": "binary_big_endian"}[byte_order]
    header = ["ply", f"format {order} 1.0", f"element vertex {count}",
              *(f"property {type_name} {name}" for name in names), "end_header"]
    path.write_bytes(("\n".join(header) + "\n").encode() + block.tobytes())
    return block


@pytest.mark.parametrize("byte_order,kind", [("<", "f4"), (">", "f4"), ("<", "f8")])
def test_reads_files_with_f_rest_and_other_layouts(tmp_path, byte_order, kind):
    path = tmp_path / "foreign.ply"
    block = write_foreign(path, 17, byte_order, kind=kind)
    gaussians = read_gaussians_ply(path)
    assert len(gaussians) == 17 and gaussians.channels == 3
    assert np.allclose(gaussians.quats[:, 3].numpy(), block["rot_3"].astype(np.float32))
    assert np.allclose(gaussians.opacity_logits.numpy(), block["opacity"].astype(np.float32))


def raises_naming(path, *args, **kwargs) -> str:
    with pytest.raises(InputError) as info:
        read_gaussians_ply(path, *args, **kwargs)
    message = str(info.value)
    assert str(path) in message and "\n" not in message, message
    return message


def test_corrupt_files_raise_input_error_naming_the_file(tmp_path):
    raises_naming(tmp_path / "missing.ply")
    not_ply = tmp_path / "text.ply"
    not_ply.write_text("hello")
    assert "not a PLY" in raises_naming(not_ply)
    good = write_gaussians_ply(tmp_path / "good.ply", random_gaussians(20, 3))
    data = good.read_bytes()
    truncated = tmp_path / "truncated.ply"
    truncated.write_bytes(data[:-10])
    assert "truncated" in raises_naming(truncated)
    no_end = tmp_path / "no_end.ply"
    no_end.write_bytes(data[:data.index(b"end_header")])
    raises_naming(no_end)
    missing_field = tmp_path / "points.ply"
    missing_field.write_bytes(data.replace(b"property float opacity", b"property float density"))
    assert "opacity" in raises_naming(missing_field)
    gaussians = random_gaussians(4, 3)
    nan = gaussians.with_(log_scales=gaussians.log_scales.clone())
    block_path = write_gaussians_ply(tmp_path / "nan.ply", nan)
    raw = bytearray(block_path.read_bytes())
    start = raw.index(b"end_header\n") + len(b"end_header\n")
    raw[start + 4 * 10:start + 4 * 11] = np.float32(np.nan).tobytes()  # vertex 0, scale_0
    block_path.write_bytes(bytes(raw))
    assert "NaN" in raises_naming(block_path)
    ascii_ply = tmp_path / "ascii.ply"
    ascii_ply.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n")
    raises_naming(ascii_ply)


def test_write_refuses_nan(tmp_path):
    gaussians = random_gaussians(3, 3)
    means = gaussians.means.clone()
    means[1, 2] = float("nan")
    with pytest.raises(ValueError):
        write_gaussians_ply(tmp_path / "bad.ply", gaussians.with_(means=means))
    assert not list(tmp_path.iterdir())


def test_empty_model_round_trips(tmp_path):
    empty = random_gaussians(0, 3)
    assert len(read_gaussians_ply(write_gaussians_ply(tmp_path / "e.ply", empty))) == 0
