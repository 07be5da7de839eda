"""The benchmarks' measurements (experiments.geometry, experiments.real, experiments.process): view choice,
scoring summaries and tables, on records made here (the fuses themselves are covered by the slow tests)."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingersplat3d.experiments.geometry import CASES, GeometryCase, geometry_table, pick_views
from fingersplat3d.experiments.process import in_fresh_process, peak_rss_mb
from fingersplat3d.experiments.real import (real_table, summarize_real, two_view_table, two_view_turn_errors,
                                           two_view_turn_excess)
from fingersplat3d.scene import Camera, Capture, View


def _cfpose(rolls):
    views = tuple(View(f"p{i + 1}", np.zeros((4, 4))) for i in range(len(rolls)))
    return Capture(views, {"poses": {f"p{i + 1}": {"roll_deg": r} for i, r in enumerate(rolls)}})


@pytest.mark.parametrize("count", [2, 3, 5])
def test_cfpose_views_spread_over_the_roll_with_the_extremes(count):
    rolls = [0.0, -40.0, -30.0, -20.0, -10.0, 5.0, 15.0, 25.0, 35.0, 44.0]
    capture = _cfpose(rolls)
    names = pick_views(capture, GeometryCase("cfpose", count))
    picked = [rolls[int(n[1:]) - 1] for n in names]
    assert len(names) == count and picked == sorted(picked)
    assert picked[0] == min(rolls) and picked[-1] == max(rolls)


def test_a_case_of_more_views_than_cfposes_default_shots_synthesizes_as_many(tmp_path):
    """cfpose20 asks 20 shots of ``fs3d synth`` (its default is 10, which would leave half the views repeated), its
    captures apart from the ten-shot cases'; the other rigs take no shots."""
    import pickle

    from fingersplat3d.experiments.geometry import synth_captures

    assert (CASES["cfpose20"].shots, CASES["cfpose3"].shots, CASES["ring5"].shots) == (20, 10, 0)
    assert CASES["cfpose20"].synth_key != CASES["cfpose10"].synth_key
    (path,) = synth_captures([0], tmp_path, (96, 120), "cfpose", shots=12)
    capture = pickle.loads(path.read_bytes())
    assert len(capture.views) == 12 and len(pick_views(capture, GeometryCase("cfpose", 12, (96, 120)))) == 12


def test_ring_and_uwa_views():
    assert pick_views(None, CASES["ring5"]) == ("v0", "v1", "v2", "v3", "v4")
    assert pick_views(None, CASES["ring2"]) == ("v0", "v2")
    uwa = Capture(tuple(View(n, np.zeros((4, 4))) for n in ("left", "center", "right")), {})
    assert pick_views(uwa, CASES["uwa2"]) == ("left", "center") and pick_views(uwa, CASES["uwa3"]) == tuple(uwa.names)


def test_a_zoomed_case_frames_the_finger_larger(tmp_path):
    """``GeometryCase.zoom``: the focal times the rig's default, named in the label and kept apart in the captures."""
    import pickle

    from fingersplat3d.experiments.geometry import synth_captures

    zoomed = CASES["uwa3-zoom"]
    assert zoomed.zoom == 1.6 and "zoomed 1.6x" in zoomed.label and zoomed.synth_key != CASES["uwa3"].synth_key
    plain, = synth_captures([0], tmp_path, (160, 128), "uwa")
    near, = synth_captures([0], tmp_path, (160, 128), "uwa", zoom=1.6)
    focal = [pickle.loads(path.read_bytes()).views[0].camera.K[0, 0] for path in (plain, near)]
    assert plain != near and focal[1] == pytest.approx(1.6 * focal[0])


def test_geometry_table_gives_medians_and_worst_and_keeps_failed_cases():
    rows = [{"case": "ring 3 views 640x512", "status": "done", "registered_all": True, "rotation_error_deg": e,
             "rotation_max_deg": 2 * e, "depth_mae_mm": 0.1 * e, "depth_worst_view_mm": 0.2 * e, "wall_s": 5.0,
             "depth_two_views_mm": 0.05 * e, "depth_one_view_mm": 0.3 * e if e < 4 else float("nan"),
             "peak_rss_mb": 900.0} for e in (1.0, 2.0, 4.0)]
    rows.append({"case": "cfpose 5 views 512x640", "status": "failed", "reason": "boom"})
    table = geometry_table(rows).splitlines()
    assert "| ring 3 views 640x512 | 3 | 3 | 2.00 (8.00) | 0.200 (0.800) | 0.100 / 0.450 |" in table[2]  # NaN: no such skin
    assert table[3].startswith("| cfpose 5 views 512x640 | 1 | 0 (failed)")


def _records(turns_deg, fingers):
    """Captures of a 3-camera rig whose middle-to-side turns are ``turns_deg`` (deg about y)."""
    records = []
    for index, ((left, right), finger) in enumerate(zip(turns_deg, fingers)):
        rotations = [Rotation.from_euler("y", angle, degrees=True).as_matrix() for angle in (0.0, left, -right)]
        poses = [np.eye(4) for _ in rotations]
        for pose, rotation in zip(poses, rotations):
            pose[:3, :3] = rotation
        records.append({"capture": f"{finger}_{index}", "finger": finger, "registered": 3, "sizes": [[64, 48]] * 3,
                        "world_to_cam": [p.tolist() for p in poses], "focal": 1000.0 + 100 * index,
                        "residual_px": 0.5, "seconds": 3.0, "peak_rss_mb": 800.0,
                        "angles_deg": {"01": left, "02": right, "12": left + right}})
    return records


def test_rig_summary_per_finger_and_focal_spread():
    records = _records([(45, 45), (45, 45), (45, 45), (50, 45), (45, 45), (45, 45)], ["1_1"] * 3 + ["2_2"] * 3)
    summary = summarize_real(records)
    assert summary["registered_all"] == 6 and summary["captures"] == 6
    assert summary["rig"]["01"]["deviation_deg"]["2_2_3"] == pytest.approx(5.0, abs=0.2)  # the odd capture
    assert summary["rig"]["01"]["median_deg"] < 0.5
    assert set(summary["by_finger"]) == {"1_1", "2_2"}
    assert summary["focal_spread"] == pytest.approx(500 / 1250)
    table = real_table(records, summary)
    assert "| **median** | 6/6 captures |" in table and "| median, finger 2_2 |" in table


def test_rig_summary_of_too_few_captures_is_empty_not_an_error():
    summary = summarize_real(_records([(45, 45)], ["1_1"]))
    assert summary["rig"] == {} and math.isnan(summary["rig_deviation_median_deg"])


def _fused(turns_deg, registered=True):
    """A stand-in fuse result: one camera per turn (deg about y)."""
    cameras = []
    for angle in turns_deg:
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("y", angle, degrees=True).as_matrix()
        cameras.append(Camera.from_focal(1000.0, 64, 48, pose))
    return SimpleNamespace(cameras=cameras, registered=registered)


def test_two_view_turn_errors_compare_each_pair_alone_with_the_same_pair_in_all_views():
    three = _fused([0.0, 45.0, -44.0])
    twos = {"01": _fused([10.0, 62.0]), "02": _fused([0.0, -44.0]), "12": _fused([0.0, 0.0], registered=False)}
    errors = two_view_turn_errors(three, twos)
    assert errors["01"] == pytest.approx(7.0) and errors["02"] == pytest.approx(0.0, abs=1e-6)
    assert errors["12"] is None  # not registered: no turn to compare, never a 0
    excess = two_view_turn_excess(three, twos)
    assert excess["01"] == pytest.approx(7.0) and excess["02"] == pytest.approx(0.0, abs=1e-6) and excess["12"] is None
    narrower = two_view_turn_excess(three, {"01": _fused([0.0, 41.5]), "02": _fused([5.0, -40.0])})
    assert narrower["01"] == pytest.approx(-3.5) and narrower["02"] == pytest.approx(1.0)  # signed, whichever way round
    records = _records([(45, 45), (45, 45)], ["1_1", "2_2"])
    records[0]["two_view_turn_error_deg"], records[0]["two_view_turn_excess_deg"] = errors, excess
    records[1]["two_view_turn_error_deg"] = {"01": 3.0, "02": 1.0, "12": None}
    records[1]["two_view_turn_excess_deg"] = {"01": -3.0, "02": 1.0, "12": None}
    summary = summarize_real(records)["two_views"]
    assert summary["01"] == {"registered": 2, "captures": 2, "median_deg": pytest.approx(5.0), "max_deg": pytest.approx(7.0),
                             "wider": 1, "signed": 2, "excess_median_deg": pytest.approx(2.0),
                             "by_finger": {"1_1": pytest.approx(7.0), "2_2": pytest.approx(3.0)}}
    assert summary["12"]["registered"] == 0 and summary["12"]["median_deg"] is None
    assert summary["12"]["signed"] == 0 and summary["12"]["by_finger"] == {"1_1": None, "2_2": None}
    table = two_view_table({"two_views": summary})
    assert "| 0, 1 | 2 of 2 | 5.00 (7.00) | 1_1 7.00, 2_2 3.00 | 1 of 2, +2.00 |" in table
    assert "| 1, 2 | 0 of 2 | – | 1_1 –, 2_2 – | – |" in table


def test_two_views_alone_are_measured_against_the_rig_mean_of_every_three_view_fuse():
    """The pair's deviation from the rig mean (the three-view target's own measure): a three-view fuse off the rig does
    not move it, as it moves the comparison with that same fuse."""
    records = _records([(45, 45)] * 2 + [(47, 45)] + [(45, 45)] * 3, ["1_1"] * 3 + ["2_2"] * 3)  # one fuse 2° off
    turn = lambda angle: Rotation.from_euler("y", angle, degrees=True).as_matrix().tolist()  # noqa: E731
    for record, alone in zip(records, (46.0, 45.0, 45.0, 45.0, 48.0, 45.0)):  # pair 0-1 fused alone
        record["two_view_turn_error_deg"] = {"01": abs(alone - record["angles_deg"]["01"])}
        record["two_view_rotations"] = {"01": [turn(0.0), turn(alone)]}
    summary = summarize_real(records)["two_views"]["01"]
    assert summary["median_deg"] == pytest.approx(0.5)  # against each capture's own three-view fuse: 1, 0, 2, 0, 3, 0
    # the rig mean is robust: the capture 2 degrees off pulls it by a twentieth of a degree at most
    assert summary["rig_median_deg"] == pytest.approx(0.0, abs=0.06)
    assert summary["rig_max_deg"] == pytest.approx(3.0, abs=0.06)
    assert summary["rig_by_finger"] == {"1_1": pytest.approx(0.0, abs=0.06), "2_2": pytest.approx(0.0, abs=0.06)}
    row = two_view_table({"two_views": {"01": summary}}).splitlines()[-1]
    assert row.endswith(f"| {summary['rig_median_deg']:.2f} ({summary['rig_max_deg']:.2f}) | "
                        f"1_1 {summary['rig_by_finger']['1_1']:.2f}, 2_2 {summary['rig_by_finger']['2_2']:.2f} |")


def _square(x):
    return x * x


def test_a_measurement_runs_in_a_fresh_process():
    assert in_fresh_process(_square, 7) == 49 and peak_rss_mb() > 10


def _open3d_as_loaded():
    import sys

    import open3d  # noqa: F401

    return "dash" in sys.modules, sys.modules["open3d.visualization.draw_plotly"].__doc__ or ""


def test_a_measured_process_loads_open3d_as_fs3d_does():
    """Without the web viewer, as the fs3d command and its batch workers load it: a measured time is the command's."""
    dash_loaded, viewer = in_fresh_process(_open3d_as_loaded)
    assert not dash_loaded and "not loaded" in viewer
