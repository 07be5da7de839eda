"""``fs3d render``: novel views of a fitted model, on the arc or at given angles, as files."""
import math

import numpy as np
import torch

from fingersplat3d.cli import main
from fingersplat3d.io import read_cameras, read_depth, read_image
from fingersplat3d.io.cameras import write_cameras
from fingersplat3d.io.gaussians_ply import write_gaussians_ply
from fingersplat3d.splat import Gaussians, rgb_to_sh
from fingersplat3d.splat.fit import render_camera
from fingersplat3d.synth.rigs import ring_rig
from fingersplat3d.synth.shape import FingerParams


def _finger_gaussians(n=3000, seed=0) -> Gaussians:
    """A textured half cylinder along +x, pad toward -z (the synth finger frame), radius 8 mm."""
    generator = torch.Generator().manual_seed(seed)
    x = torch.rand(n, generator=generator) * 24.0 - 4.0
    angle = torch.rand(n, generator=generator) * math.pi
    means = torch.stack([x, 8.0 * torch.cos(angle), -8.0 * torch.sin(angle)], -1)
    colours = (0.5 + 0.3 * torch.sin(x * 6.0))[:, None]
    return Gaussians(means, torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1), torch.full((n, 3), math.log(0.5)),
                     torch.full((n,), 2.0), rgb_to_sh(colours))


def _reconstruction(tmp_path, angles=(-45.0, 0.0, 45.0)):
    folder = tmp_path / "rec"
    folder.mkdir()
    rig = ring_rig(FingerParams(), angles, size=(96, 80))
    write_cameras(folder / "cameras.json", {view.name: view.camera for view in rig})
    model = _finger_gaussians()
    write_gaussians_ply(folder / "gaussians.ply", model)
    return folder, rig, model


def test_render_arc_and_angles(tmp_path, capsys):
    folder, rig, model = _reconstruction(tmp_path)
    assert main(["render", str(folder), "--count", "5"]) == 0
    cameras = read_cameras(folder / "renders" / "cameras.json")
    assert cameras.names == [f"arc_{k:02d}" for k in range(5)]
    # The arc starts and ends at the outer input cameras and passes the middle one.
    assert np.allclose(cameras.cameras["arc_00"].world_to_cam, rig[0].camera.world_to_cam, atol=1e-6)
    assert np.allclose(cameras.cameras["arc_02"].world_to_cam, rig[1].camera.world_to_cam, atol=1e-6)
    assert np.allclose(cameras.cameras["arc_04"].world_to_cam, rig[2].camera.world_to_cam, atol=1e-6)
    image = read_image(folder / "renders" / "arc_02.png")
    with torch.no_grad():
        expected = render_camera(model, rig[1].camera, near=1.0).color[..., 0].clamp(0, 1).numpy()
    assert image.shape == (80, 96) and np.abs(image - expected).max() < 1.5 / 255
    depth = read_depth(folder / "renders" / "depth" / "arc_02.npy")
    assert np.isfinite(depth).sum() > 100 and np.nanmin(depth) > 100  # the cameras are ~120 mm away
    assert (folder / "renders" / "contact_sheet.png").is_file()
    # Given angles, relative to the middle camera: +22.5 is the ring camera at 22.5 degrees.
    out = tmp_path / "angles"
    assert main(["render", str(folder), "-o", str(out), "--angles=-22.5,22.5", "--scale", "0.5"]) == 0
    placed = read_cameras(out / "cameras.json")
    truth = ring_rig(FingerParams(), (22.5,), size=(96, 80))[0].camera.scaled(0.5)
    assert placed.cameras[placed.names[1]].width == 48
    assert np.allclose(placed.cameras[placed.names[1]].world_to_cam, truth.world_to_cam, atol=1e-6)


def test_render_refuses_bad_input(tmp_path, capsys):
    folder, _, _ = _reconstruction(tmp_path)
    assert main(["render", str(tmp_path / "nowhere")]) == 2
    assert "gaussians.ply" in capsys.readouterr().err
    assert main(["render", str(folder), "--count", "0"]) == 2
    (folder / "gaussians.ply").write_bytes(b"ply\nformat nonsense\n")
    assert main(["render", str(folder)]) == 2
    assert "gaussians.ply" in capsys.readouterr().err
    single, _, _ = _reconstruction(tmp_path / "single", angles=(0.0,)) if (tmp_path / "single").mkdir() is None else None
    assert main(["render", str(single)]) == 2
    assert "cannot place novel views" in capsys.readouterr().err
    assert not (single / "renders").exists()


def test_render_refuses_a_model_without_gaussians(tmp_path, capsys):
    """A gaussians.ply with no rows (a file that reads) would render blank views and say nothing: refused, nothing
    written."""
    folder, _, model = _reconstruction(tmp_path)
    empty = Gaussians(model.means[:0], model.quats[:0], model.log_scales[:0], model.opacity_logits[:0], model.sh_dc[:0])
    write_gaussians_ply(folder / "gaussians.ply", empty)
    assert main(["render", str(folder)]) == 2
    assert "holds no Gaussians" in capsys.readouterr().err
    assert not (folder / "renders").exists()
