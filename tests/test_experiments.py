"""The benchmarks' measurements (experiments.geometry, experiments.real, experiments.process): view choice,
scoring summaries and tables, on records made here (the fuses themselves are covered by the slow tests)."""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingersplat3d.experiments.geometry import CASES, GeometryCase, geometry_table, pick_views
from fingersplat3d.experiments.process import in_fresh_process, peak_rss_mb
from fingersplat3d.experiments.real import real_table, summarize_real
from fingersplat3d.scene import Capture, View


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


def test_ring_and_uwa_views():
    assert pick_views(None, CASES["ring5"]) == ("v0", "v1", "v2", "v3", "v4")
    assert pick_views(None, CASES["ring2"]) == ("v0", "v2")
    uwa = Capture(tuple(View(n, np.zeros((4, 4))) for n in ("left", "center", "right")), {})
    assert pick_views(uwa, CASES["uwa2"]) == ("left", "center") and pick_views(uwa, CASES["uwa3"]) == tuple(uwa.names)


def test_geometry_table_gives_medians_and_worst_and_keeps_failed_cases():
    rows = [{"case": "ring 3 views 640x512", "status": "done", "registered_all": True, "rotation_error_deg": e,
             "rotation_max_deg": 2 * e, "depth_mae_mm": 0.1 * e, "depth_worst_view_mm": 0.2 * e, "wall_s": 5.0,
             "peak_rss_mb": 900.0} for e in (1.0, 2.0, 4.0)]
    rows.append({"case": "cfpose 5 views 512x640", "status": "failed", "reason": "boom"})
    table = geometry_table(rows).splitlines()
    assert "| ring 3 views 640x512 | 3 | 3 | 2.00 (8.00) | 0.200 (0.800) |" in table[2]
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


def _square(x):
    return x * x


def test_a_measurement_runs_in_a_fresh_process():
    assert in_fresh_process(_square, 7) == 49 and peak_rss_mb() > 10
