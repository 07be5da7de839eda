"""The fs3d command line: help, synth/info/preview end to end, one-line errors with exit code 2."""
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fingersplat3d.cli import main
from fingersplat3d.io import read_capture, read_image, read_minutiae


def test_console_entry_point_help_lists_subcommands():
    out = subprocess.run([sys.executable, "-m", "fingersplat3d.cli", "--help"], capture_output=True, text=True, check=True)
    for command in ("synth", "fuse", "info", "preview", "print", "batch", "rig", "eval", "register", "bench"):
        assert f"    {command} " in out.stdout
    # Listing the commands loads none of their libraries: torch alone took 2-3 s of a 5 s help on 2 cores.
    probe = ("import sys\nfrom fingersplat3d.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
             "print(sorted(m for m in ('torch', 'open3d', 'numba', 'cv2') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.splitlines()[-1]
    assert loaded == "[]"


def test_the_parser_builds_every_command_in_full_or_only_the_one_run():
    from fingersplat3d.cli.main import build_parser, command_of

    assert command_of(["--version"]) is None and command_of(["eval", "depth", "x"]) == "eval"
    full = build_parser()
    assert full.parse_args(["fuse", "a.png", "b.png", "-o", "out"]).guided_rounds >= 0
    assert full.parse_args(["eval", "depth", "x", "-o", "out"]).action == "depth"
    only_fuse = build_parser("fuse")
    assert only_fuse.parse_args(["fuse", "a.png", "-o", "out", "--no-splat"]).no_splat
    with pytest.raises(SystemExit):  # listed, not built: its arguments are unknown here
        only_fuse.parse_args(["synth", "out", "--seed", "3"])


def test_every_command_explains_itself_and_a_wrong_path_is_said_without_loading_torch(tmp_path):
    # The parsers' defaults live in torch-free settings modules (align/registration_config.py, align/solve/settings.py,
    # splat/config.py), and the commands check their paths before loading torch (fuse, batch, rig calibrate, render,
    # print, eval depth, eval quality): 'fs3d fuse --help' and a wrong path's one sentence took 1.8-2.7 s on 2 cores,
    # most of it torch (now 0.2-0.6 s).
    probe = ("import sys\nfrom fingersplat3d.cli.main import build_parser, main\nbuild_parser()\n"
             "missing, out = sys.argv[1], sys.argv[2]\n"
             "codes = [main(['fuse', missing, '-o', out]), main(['batch', missing, '-o', out]),\n"
             "         main(['rig', 'calibrate', missing, '-o', out + '.json']), main(['render', missing]),\n"
             "         main(['print', missing, '-o', out]), main(['eval', 'depth', missing, '-o', out]),\n"
             "         main(['eval', 'quality', missing, '-o', out, '--no-nfiq2'])]\n"
             "print(*codes, 'torch' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", probe, str(tmp_path / "no_such_photo.png"), str(tmp_path / "out")],
                          capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["2"] * 7 + ["False"]
    assert done.stderr.count("no_such_photo.png") == 7 and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["synth", "info", "preview"])
def test_each_subcommand_explains_itself(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--help"])
    assert exit_info.value.code == 0
    assert len(capsys.readouterr().out) > 200


def test_synth_info_preview_end_to_end(tmp_path, capsys):
    out = tmp_path / "finger"
    assert main(["synth", str(out), "--size", "160x128", "--seed", "3", "--bits", "16"]) == 0
    capture = read_capture(out)
    assert capture.names == ["left", "center", "right"] and capture.has_cameras
    assert all(v.depth is not None and v.mask is not None for v in capture.views)
    assert read_minutiae(out / "minutiae.json")["minutiae_3d"]
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["metadata"]["seed"] == 3 and manifest["metadata"]["units"] == "mm"
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report[0]["minutiae"] > 0
    assert main(["preview", str(out), "-o", str(tmp_path / "sheet.png")]) == 0
    sheet = read_image(tmp_path / "sheet.png")
    assert sheet.ndim == 3 and sheet.shape[0] > 100


def test_synth_count_writes_one_folder_per_finger(tmp_path):
    assert main(["synth", str(tmp_path / "many"), "--count", "2", "--rig", "ring", "--angles=-30,30",
                 "--size", "96x80", "--seed", "7"]) == 0
    folders = sorted(p.name for p in (tmp_path / "many").iterdir())
    assert folders == ["ring_00007", "ring_00008"]
    assert read_capture(tmp_path / "many" / "ring_00008").names == ["v0", "v1"]


def test_existing_output_is_not_overwritten(tmp_path, capsys):
    out = tmp_path / "finger"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["synth", str(out), "--size", "96x80"]) == 2
    err = capsys.readouterr().err
    assert str(out) in err and "--overwrite" in err and err.count("\n") == 1
    assert (out / "keep.txt").read_text() == "mine"


@pytest.mark.parametrize("argv, words", [
    (["info", "does/not/exist"], "does/not/exist"),
    (["preview", "does/not/exist"], "does/not/exist"),
    (["synth", "x", "--rig", "ring"], "angles"),
    (["synth", "x", "--count", "0"], "--count"),
])
def test_bad_input_is_one_clear_sentence(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_bad_size_is_one_sentence_without_usage(capsys):
    assert main(["synth", "x", "--size", "640by512"]) == 2
    err = capsys.readouterr().err
    assert "640x512" in err and err.count("\n") == 1 and "usage" not in err


def test_pure_modules_do_not_import_open3d():
    code = ("import sys, fingersplat3d.scene, fingersplat3d.synth.ridges, fingersplat3d.synth.shape, "
            "fingersplat3d.io.images; assert 'open3d' not in sys.modules and 'torch' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_info_names_every_unreadable_image(tmp_path, capsys):
    """Reading stops at the first broken file; info then names each of them in its one sentence."""
    from fingersplat3d.io.images import write_image

    write_image(tmp_path / "good.png", np.full((40, 60), 0.5, np.float32))
    for name in ("broken_a.png", "broken_b.jpg"):
        (tmp_path / name).write_bytes(b"not an image")
    assert main(["info", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "2 of 3 images" in err and "broken_a.png" in err and "broken_b.jpg" in err and "\n" not in err
    assert main(["info", str(tmp_path / "good.png"), str(tmp_path / "broken_a.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert "broken_a.png" in err and "of 2 images" not in err and "\n" not in err


def test_info_describes_a_reconstruction_folder(tmp_path, capsys):
    """A folder 'fs3d fuse' wrote: each view's registration and backing, each registered pair's turn from the
    cameras with how sure the run was, and the run's warnings."""
    from scipy.spatial.transform import Rotation

    from fingersplat3d.io.cameras import write_cameras
    from fingersplat3d.scene import Camera

    rec = tmp_path / "rec"
    rec.mkdir()
    poses = []
    for degrees, roll in ((0.0, 0.0), (30.0, 90.0), (75.0, 0.0)):  # b's photo stored portrait: its camera rolled 90°
        pose = np.eye(4)
        turned = Rotation.from_euler("z", roll, degrees=True) * Rotation.from_euler("y", degrees, degrees=True)
        pose[:3, :3] = turned.as_matrix()
        poses.append(pose)
    write_cameras(rec / "cameras.json", [(name, f"{name}.png", Camera.from_focal(1500.0, 640, 512, pose))
                                         for name, pose in zip(("a", "b", "c"), poses)])
    report = {"version": "x", "points": 10, "warnings": ["something to know"], "splat": {"shading": {"facing_exponent": 0.37}},
              "alignment": {"mode": "multi-view", "aligned": {"a": True, "b": True, "c": False}, "residual_px": 0.4,
                            "backed_by_two_views": {"a": 0.9, "b": 0.8, "c": None},
                            "turn_uncertainty_deg": {"a-b": 0.05}, "turn_sensitivity_deg": {"a-b": 0.7}}}
    (rec / "report.json").write_text(json.dumps(report))
    assert main(["info", str(rec), "--json"]) == 0
    described = json.loads(capsys.readouterr().out)[0]
    assert described["kind"] == "reconstruction folder" and described["registered"] == "2 of 3"
    assert [p["pair"] for p in described["pairs"]] == ["a-b"]  # c is not registered
    assert described["pairs"][0]["turn_deg"] == pytest.approx(30.0, abs=1e-6)  # the optical axes', not 95.7°
    assert described["pairs"][0]["roll_deg"] == pytest.approx(90.0, abs=1e-6)
    assert described["warnings"] == ["something to know"] and described["files"] == ["report.json"]
    assert described["shading_exponent"] == 0.37  # how much darker the skin at a slant (gaussians.ply's exponent)
    assert main(["info", str(rec)]) == 0
    out = capsys.readouterr().out
    assert "c: 640x512, focal 1500 px, not registered" in out
    assert "turn a-b: 30.00° (and rolled 90° about the optical axis, as a photo turned in its plane), ±0.05°" in out
    assert "warning: something to know" in out and "shading_exponent: 0.37" in out
    batch = tmp_path / "batch"  # 'fs3d batch -o' writes one reconstruction folder per capture
    batch.mkdir()
    for name in ("c10", "c2"):
        shutil.copytree(rec, batch / name)
    assert main(["info", str(batch)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].endswith("2 reconstruction folders") and lines[1].startswith("  c2: registered 2 of 3")
    assert "1 warning(s)" in lines[2]
    assert not any(line.startswith("focal fitted") for line in lines)  # no focal probe, a view unregistered
    (rec / "report.json").write_text("{not json")
    assert main(["info", str(rec), "--json"]) == 0  # the cameras still described, the report's state said
    described = json.loads(capsys.readouterr().out)[0]
    assert len(described["pairs"]) == 3 and "report.json could not be read" in described["warnings"][0]


def test_info_offers_a_batch_the_median_of_its_fitted_focals(tmp_path, capsys):
    """A batch's three-view reconstructions whose photos held a fitted focal: their median, offered as --focal-px (a
    camera stored portrait counts with its landscape twins); one focal given (no probe), one with a view unregistered
    and one of another photo size do not count."""
    from fingersplat3d.cli.info import shared_focal
    from fingersplat3d.io.cameras import write_cameras
    from fingersplat3d.scene import Camera

    batch = tmp_path / "batch"
    cases = {"c1": (1500.0, True, True, (640, 512)), "c2": (1600.0, True, True, (640, 512)),
             "c3": (1900.0, True, True, (640, 512)), "portrait": (1700.0, True, True, (512, 640)),
             "given": (1000.0, None, True, (640, 512)), "lost": (1200.0, True, False, (640, 512)),
             "other": (3000.0, True, True, (1280, 1024))}
    for name, (focal, held, third, (width, height)) in cases.items():
        rec = batch / name
        rec.mkdir(parents=True)
        write_cameras(rec / "cameras.json", [(v, f"{v}.png", Camera.from_focal(focal, width, height, np.eye(4)))
                                             for v in ("a", "b", "c")])
        alignment = {"mode": "multi-view", "aligned": {"a": True, "b": True, "c": third}, "residual_px": 0.4}
        if held is not None:
            alignment["focal_probe"] = {"held": held, "longer_loss_rise": 0.05}
        (rec / "report.json").write_text(json.dumps({"alignment": alignment}))
    assert main(["info", str(batch)]) == 0
    last = capsys.readouterr().out.splitlines()[-1]
    assert last.startswith("focal fitted by 4 of them (640x512")
    assert "median 1650 px, 1500-1900 px (spread 24 %)" in last
    assert last.endswith("--focal-px 1650")
    assert shared_focal([]) is None
    one = {"focal_held_by_photos": True, "views": [{"size": "640x512", "focal_px": 1500.0, "registered": True}] * 3}
    assert shared_focal([one]) is None  # one capture: nothing to share
    weak = {**one, "focal_held_by_photos": False}
    assert shared_focal([one, weak]) is None  # a focal its photos did not hold does not count
