"""`fs3d bench`: the sweep, its files, and bad arguments (the full run is slow: marked)."""
import csv
import math

import pytest

from fingersplat3d.cli import main
from fingersplat3d.errors import EXIT_INPUT
from fingersplat3d.experiments.bench import Setting, _write, sweep
from fingersplat3d.splat.config import preset


def test_sweep_turns_one_knob_at_a_time():
    settings = sweep("fast", ("fast", "balanced"))
    assert settings[0] == Setting("baseline", "fast", "fast")
    knobs = [s.knob for s in settings]
    assert knobs.count("preset") == 1 and knobs.count("resolution") == 2 and knobs.count("views") == 2
    base = preset("fast")
    for s in settings[1:]:
        changed = {k for k, v in (("preset", s.preset != "fast"), ("resolution", s.scale != 1.0),
                                  ("iterations", s.iterations is not None), ("gaussians", s.gaussians_per_cell is not None),
                                  ("views", s.views != 3)) if v}
        assert changed == {s.knob}
    iterations = sorted(s.iterations for s in settings if s.knob == "iterations")
    assert iterations == [base.iterations // 2, base.iterations * 2]
    assert [s.knob for s in sweep("fast", knobs=("views",))] == ["baseline", "views", "views"]


def test_tables_and_pictures_from_runs(tmp_path):
    settings = sweep("fast", ("fast",), knobs=("views", "iterations"))
    rows = []
    for k, s in enumerate(settings):
        for seed in (0, 1):
            row = {**s.__dict__, "seed": seed, "status": "done", "wall_s": 10.0 + 5 * k + seed, "peak_rss_mb": 800.0,
                   "depth_mae_mm": 0.3 + 0.01 * k, "rotation_error_deg": 1.0, "registered": s.views,
                   "held_out_psnr_db": math.nan if s.views == 5 else 25.0 + k, "gaussians": 1000}
            row.update({f"{stage}_s": 1.0 for stage in ("pointmaps", "registration", "icp", "fusion", "splat")})
            rows.append(row)
    rows.append({**settings[1].__dict__, "seed": 2, "status": "failed", "reason": "ValueError: boom"})
    real = {(1.0,): {"captures": 9, "registered_all": 9, "rig_deviation_median_deg": 0.4, "rig_deviation_max_deg": 2.0,
                     "fuse_s_median": 12.0, "peak_rss_mb": 900.0}}
    _write(tmp_path, rows, real, settings, {"cpu": "Test CPU", "cores": 2, "torch": "x", "device": "cpu"}, [0, 1], (64, 48))
    table = (tmp_path / "summary.md").read_text()
    assert "Machine: Test CPU, 2 cores" in table
    assert "| baseline | fast | 10.5 |" in table  # the median over seeds
    assert "| 1x | 9 | 9 | 0.40 | 2.00 |" in table and "boom" in table
    with open(tmp_path / "bench.csv") as handle:
        assert len(list(csv.DictReader(handle))) == len(rows)
    assert (tmp_path / "trade_depth.png").stat().st_size > 1000 and (tmp_path / "trade_psnr.png").is_file()


def test_bad_arguments_are_one_sentence(tmp_path, capsys):
    assert main(["bench", "-o", str(tmp_path / "a"), "--knobs", "speed"]) == EXIT_INPUT
    assert "unknown knob 'speed'" in capsys.readouterr().err
    assert main(["bench", "-o", str(tmp_path / "b"), "--presets", "fast,turbo"]) == EXIT_INPUT
    assert "unknown preset 'turbo'" in capsys.readouterr().err
    assert main(["bench", "-o", str(tmp_path / "c"), "--seeds", "0"]) == EXIT_INPUT
    assert main(["bench", "-o", str(tmp_path / "d"), "--real", str(tmp_path / "nowhere")]) == EXIT_INPUT
    assert not any((tmp_path / n).exists() for n in "abcd")


@pytest.mark.slow
def test_a_small_sweep_end_to_end(tmp_path):
    out = tmp_path / "bench"
    assert main(["bench", "-o", str(out), "--seeds", "1", "--size", "320x256", "--knobs", "views"]) == 0
    with open(out / "bench.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["label"] for r in rows] == ["fast", "2 views", "5 views"]
    for row in rows:
        assert row["status"] == "done" and float(row["wall_s"]) > 0 and float(row["peak_rss_mb"]) > 100
        assert float(row["depth_mae_mm"]) < 2.0
    assert rows[2]["held_out_psnr_db"] == "nan"  # every view fused: none held out


def test_working_resolution_resizes_photos_with_or_without_masks(uwa640):
    from fingersplat3d.experiments.bench import _resized

    view = uwa640.views[0]
    half = _resized(view, 0.5)
    assert half.image.shape[:2] == (256, 320) and half.mask.shape == (256, 320) and half.depth.shape == (256, 320)
    assert half.camera.width == 320
    bare = _resized(view.with_(mask=None, depth=None, camera=None), 0.75)  # a real photo: nothing but the image
    assert bare.image.shape[:2] == (384, 480) and bare.mask is None
