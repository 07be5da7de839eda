"""The generalisation sweep's settings and summary (fingersplat3d/experiments/stress.py; the fuses run in
tools/bench_stress.py, measured in docs/measurements.md)."""
from __future__ import annotations

import numpy as np

from fingersplat3d.experiments.stress import (DEPTH_TARGET_MM, KINDS, WARN_ABOVE_DEG, StressSetting, draw_settings,
                                              kind_of, sweep_summary)


def test_draws_repeat_for_a_seed_and_differ_between_seeds():
    assert draw_settings(3, 12) == draw_settings(3, 12)
    assert draw_settings(3, 12) != draw_settings(4, 12)


def test_draws_stay_within_the_tool_s_ranges_and_cover_every_kind():
    settings = draw_settings(0, 300)
    assert {kind_of(s) for s in settings} == set(KINDS)
    for s in settings:
        assert s.views in (2, 3, 5) and 25 <= s.spread_deg <= 60 and s.first_seed >= 20
        assert s.pitch_deg is None or abs(s.pitch_deg) <= 15
        assert s.crop_widths is None or 0.8 <= s.crop_widths <= 1.6
        assert -0.1 <= s.k1 <= 0.0 and abs(s.nearer_mm) <= 8 and 0.9 <= s.front_zoom <= 1.1
    # each stressor on some settings and off on others
    for field in ("pitch_deg", "crop_widths", "background"):
        values = [getattr(s, field) for s in settings]
        assert any(v is None for v in values) and any(v is not None for v in values)
    assert any(s.focal_given for s in settings) and not all(s.focal_given for s in settings)


def test_arguments_name_only_what_differs_from_the_tool_s_defaults():
    plain = StressSetting(42, 3, 45.0, 54.0).arguments(2)
    assert plain == ["--seeds", "2", "--first-seed", "42", "--views", "3", "--spread", "45", "--distance", "54"]
    full = StressSetting(7, 2, 30.0, 100.0, pitch_deg=-9.0, crop_widths=1.2, k1=-0.05, nearer_mm=3.0, relief_mm=0.08,
                         specular=0.2, front_zoom=1.05, background="bright desk", focal_given=True).arguments(1)
    for flag, value in (("--pitch", "-9"), ("--crop", "1.2"), ("--k1", "-0.05"), ("--nearer", "3"),
                        ("--relief", "0.08"), ("--specular", "0.2"), ("--front-zoom", "1.05"),
                        ("--background", "bright desk")):
        assert full[full.index(flag) + 1] == value
    assert full[-1] == "--focal-given"
    label = StressSetting(7, 2, 30.0, 100.0, pitch_deg=-9.0, focal_given=True).label()
    assert "pitch ±9°" in label and label.startswith("2 views ±30°") and label.endswith("focal given")


def _row(worst: float, depth: float, warned: bool, status: str = "done") -> dict:
    return {"status": status, "registered_all": True, "rotation_max_deg": worst, "depth_mae_mm": depth, "warned": warned}


def test_summary_counts_captures_off_without_a_warning_by_kind():
    three, two_fitted = StressSetting(20, 3, 45.0, 54.0), StressSetting(21, 2, 45.0, 54.0)
    records = [(three, _row(0.4, 0.05, False)), (three, _row(WARN_ABOVE_DEG + 0.5, 0.2, False)),
               (three, _row(5.0, 0.3, True)), (three, {"status": "failed", "reason": "mask"}),
               (two_fitted, _row(9.0, 0.5, True))]
    summary = {s["kind"]: s for s in sweep_summary(records)}
    assert set(summary) == {KINDS[0], KINDS[2]}
    three_views = summary[KINDS[0]]
    assert (three_views["fuses"], three_views["failed"], three_views["registered_all"]) == (4, 1, 3)
    assert three_views["off_unwarned"] == 1  # the warned 5 degree capture is told apart; the 2.5 degree one is not
    assert (three_views["within_1_deg"], three_views["within_2_deg"]) == (1, 1)
    assert three_views["depth_within_target"] == 1 and np.isclose(three_views["worst_pair_max_deg"], 5.0)
    assert three_views["depth_median_mm"] > DEPTH_TARGET_MM
    assert summary[KINDS[2]]["off_unwarned"] == 0


def test_summary_of_failures_alone_stays_finite_where_it_can():
    summary = sweep_summary([(StressSetting(20, 5, 30.0, 45.0), {"status": "failed", "reason": "x"})])
    assert summary[0]["fuses"] == 1 and summary[0]["failed"] == 1 and summary[0]["off_unwarned"] == 0
    assert np.isnan(summary[0]["worst_pair_median_deg"])


def test_the_sweep_s_picture_draws_every_kind(tmp_path):
    from fingersplat3d.experiments.plots import sweep_picture
    from fingersplat3d.experiments.stress import sweep_points

    three, two = StressSetting(20, 3, 45.0, 54.0), StressSetting(21, 2, 45.0, 54.0, focal_given=True)
    records = [(three, _row(0.3, 0.05, False)), (three, _row(3.0, 0.2, True)), (two, _row(0.0, 0.04, False)),
               (three, {"status": "failed", "reason": "mask"})]
    points = sweep_points(records)
    assert list(points) == [KINDS[0], KINDS[1]] and len(points[KINDS[0]]) == 2
    path = sweep_picture(tmp_path / "sweep.png", points, WARN_ABOVE_DEG, DEPTH_TARGET_MM, "sweep", "machine")
    assert path.stat().st_size > 10_000


def test_the_sweep_s_bad_settings_end_in_one_sentence():
    import subprocess
    import sys
    from pathlib import Path

    tool = Path(__file__).resolve().parents[1] / "tools" / "bench_stress.py"
    for args in (["--size", "12x5"], ["--count", "0"]):
        done = subprocess.run([sys.executable, str(tool), *args], capture_output=True, text=True, timeout=120)
        assert done.returncode == 2 and "Traceback" not in done.stderr
        assert len(done.stderr.strip().splitlines()) == 1 and ("--size" in done.stderr or "--count" in done.stderr)
