"""fs3d batch on a real local Ray instance (2 CPUs): every capture done or recorded, resumable, results and report."""
from __future__ import annotations

import csv
import json
from html.parser import HTMLParser

import pytest

from fingersplat3d.cli import main
from fingersplat3d.io.capture import write_capture

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def ray_local():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


class _Images(HTMLParser):
    def __init__(self):
        super().__init__()
        self.sources, self.rows = [], 0

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.sources.append(dict(attrs)["src"])
        elif tag == "tr":
            self.rows += 1


@pytest.fixture(scope="module")
def small_capture():
    """A three-view capture at 320x256: the batch's bookkeeping needs a capture that registers, not a large one."""
    from fingersplat3d.synth import SynthConfig, synthesize

    return synthesize(1, SynthConfig(size=(320, 256))).capture


def test_batch_runs_records_failures_and_resumes(tmp_path, small_capture, ray_local, capsys):
    dataset = tmp_path / "dataset"
    write_capture(small_capture, dataset / "good")
    broken = dataset / "broken"
    write_capture(small_capture, broken)
    (broken / "images" / "left.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    stale = out / ".good.tmp-killed"  # what a run killed mid-write leaves
    stale.mkdir(parents=True)
    (stale / "fused.ply").write_text("half")

    status = main(["batch", str(dataset), "-o", str(out), "--no-splat", "--workers", "2"])
    assert status == 4  # one capture failed: the run finished, said so, and the good one is complete
    assert "1 of 2 captures failed" in capsys.readouterr().err
    assert not stale.exists() and not [p for p in out.iterdir() if ".tmp-" in p.name]
    good = out / "good"
    for name in ("fused.ply", "cameras.json", "report.json", "batch.json", "depth", "thumbs", "overview.png"):
        assert (good / name).exists(), name
    assert not (out / "broken").exists() and (out / ".failed" / "broken.json").is_file()
    rows = {row["capture"]: row for row in csv.DictReader(open(out / "results.csv"))}
    assert rows["good"]["status"] == "done" and float(rows["good"]["seconds"]) > 0 and float(rows["good"]["peak_rss_mb"]) > 0
    assert rows["broken"]["status"] == "failed" and "left.png" in rows["broken"]["reason"]
    assert json.loads(rows["good"]["rig_angles_deg"])["0-1"] > 10
    page = _Images()
    page.feed((out / "report.html").read_text())
    assert page.rows == 3 and page.sources and all((out / src).is_file() for src in page.sources)
    assert "good/overview.png" in page.sources  # each capture's row opens with what its fuse found
    from fingersplat3d.batch.results import browser_check, find_browser

    browser = find_browser()
    if browser:  # a real headless browser loads the page and every picture (tools/check_report.py)
        loaded, failed_to_load = browser_check(out / "report.html", browser)
        assert loaded == len(page.sources) and failed_to_load == 0

    # a re-run skips the complete capture (not redone) and leaves the recorded failure alone
    before = (good / "batch.json").stat().st_mtime_ns
    assert main(["batch", str(dataset), "-o", str(out), "--no-splat", "--workers", "2"]) == 4
    assert "0 run now, 1 complete before, 1 failed before" in capsys.readouterr().out
    assert (good / "batch.json").stat().st_mtime_ns == before
    # fixed, and retried on request
    write_capture(small_capture, broken, overwrite=True)
    assert main(["batch", str(dataset), "-o", str(out), "--no-splat", "--retry-failed", "--select", "name=broken"]) == 0
    assert (out / "broken" / "batch.json").is_file() and not (out / ".failed" / "broken.json").exists()
    rows = {row["capture"]: row["status"] for row in csv.DictReader(open(out / "results.csv"))}
    assert rows == {"good": "done", "broken": "done"}  # the table covers every capture on disk, not just this run's


def test_rig_calibrate_command(tmp_path, small_capture, ray_local, capsys):
    from fingersplat3d.io.rig import read_rig
    from fingersplat3d.synth import SynthConfig, synthesize

    dataset = tmp_path / "dataset"
    write_capture(small_capture, dataset / "a")
    write_capture(synthesize(3, SynthConfig(size=(320, 256))).capture, dataset / "b")
    rig_path = tmp_path / "rig.json"
    assert main(["rig", "calibrate", str(dataset), "-o", str(rig_path), "--rounds", "1"]) == 0
    assert "2 captures used" in capsys.readouterr().out
    rig = read_rig(rig_path)
    assert rig.names == tuple(small_capture.names) and rig.focal > 0 and sorted(rig.info["captures"]) == ["a", "b"]
    assert rig.info["rounds"] == 1
    assert main(["rig", "calibrate", str(dataset), "-o", str(rig_path)]) == 2  # exists: nothing overwritten
    # one capture selected: bad input, said before any registration
    assert main(["rig", "calibrate", str(dataset), "-o", str(tmp_path / "one.json"), "--select", "count=1"]) == 2
    assert "1 capture in" in (err := capsys.readouterr().err) and "a rig needs at least 2" in err
    assert not (tmp_path / "one.json").exists()


def test_a_dying_worker_is_a_recorded_failure_not_a_crash(ray_local):
    from fingersplat3d.batch.engine import ray_map

    def _die_on_two(item):  # nested: shipped to the workers by value
        import os

        if item == 2:
            os._exit(1)  # the worker process dies mid-task
        return item * 10

    seen = {}
    figures = ray_map(_die_on_two, [1, 2, 3], (), lambda item, result, error: seen.update({item: (result, error)}),
                      progress=False)
    assert seen[1] == (10, None) and seen[3] == (30, None)
    assert seen[2][0] is None and seen[2][1]  # one sentence saying why
    assert figures["tasks"] == 3 and figures["cpus"] == 2


def test_a_capture_with_no_view_registered_keeps_its_reason_and_files(tmp_path, small_capture, monkeypatch):
    """No view registered leaves the residual NaN: the row holds none (JSON has no NaN), not a JSON error as its reason,
    and the capture's files are written (run in this process, no Ray)."""
    import math

    import fingersplat3d.pipeline as pipeline
    from fingersplat3d.batch.task import BatchOptions, process_capture
    from fingersplat3d.io.jobs import list_jobs
    from fingersplat3d.pipeline import FuseConfig

    real_fuse = pipeline.fuse

    def unregistered(capture, config, rig=None):
        result = real_fuse(capture, config, rig=rig)
        result.report["alignment"].update(residual_px=math.nan, reason="f1, f2: the views agree at 5 % (test)")
        return result

    monkeypatch.setattr(pipeline, "fuse", unregistered)
    write_capture(small_capture, tmp_path / "dataset" / "lone")
    job = list_jobs([tmp_path / "dataset"])[0]
    row = process_capture(job, str(tmp_path / "out"), BatchOptions(FuseConfig(splat=None), render=0))
    assert row["reason"] == "f1, f2: the views agree at 5 % (test)" and row["residual_px"] is None
    assert row["focal_px"] is not None and math.isfinite(row["focal_px"])
    written = json.loads((tmp_path / "out" / "lone" / "batch.json").read_text())
    assert written["residual_px"] is None and (tmp_path / "out" / "lone" / "report.json").is_file()


def test_the_batch_arc_of_a_capture_with_a_camera_stored_portrait(tmp_path):
    """UWA stores a camera turned by a quarter turn now and then (1_1_4_1_0.jpg): the batch's arc renders it at its
    landscape twins' scale and all the arc's views share one size (each camera scaled to one width made the portrait
    one taller, and the whole capture was lost to the arc's size check)."""
    from types import SimpleNamespace

    from fingersplat3d.batch.task import THUMB_WIDTH, _render_arc
    from fingersplat3d.io import read_cameras
    from fingersplat3d.splat.camera_path import _quarter_turn
    from fingersplat3d.synth.rigs import ring_rig
    from fingersplat3d.synth.shape import FingerParams
    from test_render_cli import _finger_gaussians

    cameras = [view.camera for view in ring_rig(FingerParams(), (-45.0, 0.0, 45.0), size=(640, 512))]
    cameras[0] = _quarter_turn(cameras[0], 1)
    assert cameras[0].size == (512, 640)
    result = SimpleNamespace(cameras=cameras, gaussians=_finger_gaussians(), units="mm", scale_mm_per_unit=1.0)
    _render_arc(tmp_path, result, 5)
    placed = read_cameras(tmp_path / "renders" / "cameras.json")
    assert len(placed.names) == 5
    assert {camera.size for camera in placed.cameras.values()} == {(2 * THUMB_WIDTH, 2 * THUMB_WIDTH * 512 // 640)}


def test_a_capture_that_fails_after_its_fuse_is_recorded_as_failed(tmp_path, small_capture, monkeypatch):
    """An error after the fuse (writing, rendering) leaves the row 'failed', not the 'done' the fuse had set."""
    import fingersplat3d.pipeline as pipeline
    from fingersplat3d.batch.task import BatchOptions, process_capture
    from fingersplat3d.io.jobs import list_jobs
    from fingersplat3d.pipeline import FuseConfig

    def full_disk(result, folder):
        raise OSError("No space left on device (test)")

    monkeypatch.setattr(pipeline, "write_reconstruction_files", full_disk)
    write_capture(small_capture, tmp_path / "dataset" / "lone")
    row = process_capture(list_jobs([tmp_path / "dataset"])[0], str(tmp_path / "out"),
                          BatchOptions(FuseConfig(splat=None), render=0))
    assert row["status"] == "failed" and "No space left" in row["reason"]
    written = json.loads((tmp_path / "out" / ".failed" / "lone.json").read_text())
    assert written["status"] == "failed" and not (tmp_path / "out" / "lone").exists()
