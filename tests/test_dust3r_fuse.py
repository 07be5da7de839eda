"""The dust3r backend end to end: a tiny random checkpoint in the official layout through `fs3d fuse`."""
import json
from pathlib import Path

import numpy as np
import pytest

from dust3r_tiny import tiny_checkpoint, tiny_model
from fingersplat3d.cli import main
from fingersplat3d.errors import InputError
from fingersplat3d.io import read_capture, read_depth
from fingersplat3d.pipeline import FuseConfig, fuse
from fingersplat3d.pointmaps import get_backend
from fingersplat3d.pointmaps.dust3r import Dust3rBackend
from fingersplat3d.scene import Capture, View

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "uwa_seed0"


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return tiny_checkpoint(tmp_path_factory.mktemp("weights"))


@pytest.fixture(scope="module")
def small_capture():
    """The sample at a quarter of its size (160x128) for fast backend checks."""
    capture = read_capture(SAMPLE)
    return Capture(tuple(View(v.name, v.image[::4, ::4], v.mask[::4, ::4]) for v in capture.views), capture.metadata)


def test_backend_pointmaps_are_on_each_views_own_grid(checkpoint):
    rng = np.random.default_rng(0)
    views = [View("landscape", rng.random((90, 150)).astype(np.float32)),
             View("portrait_rgb", rng.random((100, 70, 3)).astype(np.float32))]
    backend = get_backend("dust3r", checkpoint=str(checkpoint), device="cpu", batch_size=1, image_size=224)
    assert isinstance(backend, Dust3rBackend) and backend.model.architecture.img_size == (64, 64)
    pointmaps = backend.predict_views(views)
    for view, pointmap in zip(views, pointmaps):
        assert pointmap.points.shape == (view.height, view.width, 3) and pointmap.points.dtype == np.float32
        assert pointmap.confidence.shape == (view.height, view.width) and pointmap.focal > 0
        assert np.isnan(pointmap.points[~pointmap.valid]).all() and (pointmap.confidence[pointmap.valid] >= 1).all()
        assert (pointmap.depth[pointmap.valid] > 0).all()
    # 224 mode crops a square: the landscape image's sides have no points, its middle has.
    landscape = pointmaps[0].valid
    assert not landscape[:, :25].any() and not landscape[:, -25:].any() and landscape[:, 50:100].mean() > 0.9
    pairs = backend.predict_pairs(views)
    assert [(p.i, p.j) for p in pairs] == [(0, 1), (1, 0)]  # symmetrised
    assert pairs[0].points_i.shape == (90, 150, 3) and pairs[0].points_j.shape == (100, 70, 3)
    assert pairs[1].confidence_i.shape == (100, 70) and pairs[1].confidence_j.shape == (90, 150)
    views_record, pairs_record = backend.stats
    assert (views_record.task, views_record.forward_passes, views_record.images_encoded) == ("views", 2, 2)
    assert (pairs_record.task, pairs_record.forward_passes, pairs_record.images_encoded) == ("pairs", 2, 0)  # cached
    assert pairs_record.seconds_per_pair > 0 and pairs_record.peak_memory_mb >= 0 and views_record.device == "cpu"


def test_monocular_mode_is_the_image_paired_with_itself(small_capture):
    model = tiny_model(seed=5)
    backend = Dust3rBackend(model=model, device="cpu")
    view = small_capture.views[1]
    pointmap = backend.predict_views([view])[0]
    pair = backend.predict_pairs([view, view], [(0, 1)])[0]
    valid = pointmap.valid
    assert valid.mean() > 0.5
    assert np.allclose(pointmap.points[valid], pair.points_i[valid], rtol=1e-4, atol=1e-5)


def test_batches_of_pairs_give_the_same_pointmaps(small_capture):
    model = tiny_model(seed=6)
    one = Dust3rBackend(model=model, device="cpu", batch_size=1).predict_pairs(small_capture.views[:2])
    two = Dust3rBackend(model=model, device="cpu", batch_size=2).predict_pairs(small_capture.views[:2])
    assert len(one) == len(two) == 2
    for a, b in zip(one, two):
        assert (a.i, a.j) == (b.i, b.j)
        assert np.allclose(a.points_j, b.points_j, rtol=1e-4, atol=1e-5, equal_nan=True)


def test_fs3d_fuse_with_a_checkpoint_end_to_end(checkpoint, tmp_path, capsys):
    out = tmp_path / "rec"
    code = main(["fuse", str(SAMPLE), "-o", str(out), "--backend", "dust3r", "--checkpoint", str(checkpoint),
                 "--device", "cpu", "--pair-batch", "2", "--polish-iterations", "20", "--no-splat"])
    # Random weights describe no rigid scene: the pairs are refused, the outputs are written and the
    # exit status says that the views were not registered.
    assert code == 3, capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["backend"] == "dust3r" and report["settings"]["checkpoint"] == str(checkpoint)
    inference = {record["task"]: record for record in report["pointmap_inference"]}
    assert inference["views"]["forward_passes"] == 3 and inference["pairs"]["forward_passes"] == 6
    assert inference["views"]["images_encoded"] == 3 and inference["views"]["network_size"] == [64, 48]
    assert [record["method"] for record in report["pairs"]] == ["pointmaps"] * 3
    assert not any(record["ok"] for record in report["pairs"]) and "disagree" in report["pairs"][0]["reason"]
    for name in ("left", "center", "right"):
        depth = read_depth(out / "depth" / f"{name}.npy")
        assert depth.shape == (512, 640) and np.isfinite(depth).any()
    assert (out / "fused.ply").stat().st_size > 1000 and (out / "cameras.json").is_file()


def test_one_image_and_identical_images_run_in_monocular_mode(small_capture):
    backend_model = tiny_model(seed=7)
    from fingersplat3d.pointmaps import register_backend

    register_backend("dust3r-test-model", lambda: Dust3rBackend(model=backend_model, device="cpu"))
    view = small_capture.views[1]
    config = FuseConfig(backend="dust3r-test-model", splat=None)
    single = fuse(Capture((view,), {}), config)
    twice = fuse(Capture((view, view.with_(name="again")), {}), config)
    for result in (single, twice):
        assert result.report["alignment"]["mode"] == "monocular" and np.isfinite(result.depths[0][view.mask]).any()
    assert twice.report["pairs"][0]["reason"].startswith("identical images")
    assert [r["task"] for r in twice.report["pointmap_inference"]] == ["views"]  # no pair inference for twins
    assert np.allclose(single.depths[0], twice.depths[0], equal_nan=True)


def test_cli_errors_are_one_line_with_exit_code_2(checkpoint, tmp_path, capsys):
    corrupt = tmp_path / "corrupt.pth"
    corrupt.write_bytes(checkpoint.read_bytes()[:3000])
    cases = [
        ([], "--backend dust3r needs --checkpoint PATH"),
        (["--checkpoint", str(tmp_path / "missing.pth")], "missing.pth: checkpoint file not found"),
        (["--checkpoint", str(corrupt)], "corrupt.pth: is corrupt or not a PyTorch checkpoint"),
        (["--checkpoint", str(checkpoint), "--device", "tpu"], "device 'tpu'; use auto, cpu, cuda or cuda:N"),
        (["--checkpoint", str(checkpoint), "--pair-batch", "0"], "--pair-batch: must be at least 1, got 0"),
    ]
    for extra, message in cases:
        code = main(["fuse", str(SAMPLE), "-o", str(tmp_path / "out"), "--backend", "dust3r", "--no-splat", *extra])
        errors = [line for line in capsys.readouterr().err.replace("\r", "\n").splitlines() if "error:" in line]
        assert code == 2 and len(errors) == 1 and message in errors[0], errors
    code = main(["fuse", str(SAMPLE), "-o", str(tmp_path / "out"), "--checkpoint", str(checkpoint), "--no-splat"])
    assert code == 2 and "only used by --backend dust3r" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_backend_without_checkpoint_is_an_input_error():
    with pytest.raises(InputError, match="needs a checkpoint"):
        get_backend("dust3r")
