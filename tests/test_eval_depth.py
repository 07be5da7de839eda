"""`fs3d eval depth`: PolyU 3D+ height maps, pairing by name, the run and its files."""
import csv

import numpy as np
import pytest
from scipy.io import savemat

from fingersplat3d.cli import main
from fingersplat3d.errors import EXIT_INCOMPLETE, EXIT_INPUT, InputError
from fingersplat3d.experiments.depth import pair_by_name
from fingersplat3d.io.polyu import read_height_map


def test_height_map_is_fc_flipped_upside_down_with_nan_background(tmp_path):
    fc = np.arange(12 * 10, dtype=float).reshape(12, 10)
    fc[0, 0] = np.nan
    fc[1, 1] = np.inf
    savemat(tmp_path / "a.mat", {"fc": fc, "other": np.ones((20, 20))})
    height = read_height_map(tmp_path / "a.mat")
    assert height.shape == (12, 10)
    assert np.array_equal(height[:-2], np.flipud(fc)[:-2])
    assert np.isnan(height[-1, 0]) and np.isnan(height[-2, 1])  # non-finite: background


def test_the_one_two_d_array_is_taken_when_there_is_no_fc(tmp_path):
    savemat(tmp_path / "b.mat", {"Z": np.ones((16, 9)), "note": np.array(["x"]), "k": np.ones(3)})
    assert read_height_map(tmp_path / "b.mat").shape == (16, 9)


def test_unusable_files_say_what_they_hold(tmp_path):
    savemat(tmp_path / "two.mat", {"A": np.ones((16, 16)), "B": np.zeros((16, 16))})
    with pytest.raises(InputError, match=r"several 2-D arrays \(A, B\).*it holds: A \(16, 16\), B \(16, 16\)"):
        read_height_map(tmp_path / "two.mat")
    savemat(tmp_path / "none.mat", {"v": np.ones(5)})
    with pytest.raises(InputError, match="no 2-D numeric array"):
        read_height_map(tmp_path / "none.mat")
    (tmp_path / "junk.mat").write_bytes(b"\x00not a mat file at all" * 20)
    with pytest.raises(InputError, match="junk.mat"):
        read_height_map(tmp_path / "junk.mat")
    savemat(tmp_path / "nan.mat", {"fc": np.full((10, 10), np.nan)})
    with pytest.raises(InputError, match="no finite value"):
        read_height_map(tmp_path / "nan.mat")


def test_matlab_v73_files_are_read_through_hdf5(tmp_path):
    h5py = pytest.importorskip("h5py")
    fc = np.random.default_rng(0).random((14, 11))
    with h5py.File(tmp_path / "c.mat", "w") as handle:
        handle["fc"] = fc.T  # MATLAB stores column-major
    assert np.allclose(read_height_map(tmp_path / "c.mat"), np.flipud(fc))


def test_pairing_by_name_reports_the_unpaired(tmp_path):
    images = [tmp_path / n for n in ("S1_F1.png", "s2_f1.jpg", "lonely.png")]
    truths = [tmp_path / n for n in ("s1_f1.mat", "S2_F1.mat", "orphan.mat")]
    pairs, lonely_images, lonely_truths = pair_by_name(images, truths)
    assert [(a.name, b.name) for a, b in pairs] == [("S1_F1.png", "s1_f1.mat"), ("s2_f1.jpg", "S2_F1.mat")]
    assert [p.name for p in lonely_images] == ["lonely.png"] and [p.name for p in lonely_truths] == ["orphan.mat"]
    with pytest.raises(InputError, match="two image files"):
        pair_by_name([tmp_path / "a.png", tmp_path / "sub" / "A.jpg"], truths)


@pytest.fixture(scope="module")
def small_capture(tmp_path_factory):
    folder = tmp_path_factory.mktemp("eval") / "finger"
    assert main(["synth", "--rig", "uwa", "--seed", "3", "--size", "320x256", str(folder)]) == 0
    return folder


def _rows(path):
    with open(path) as handle:
        return list(csv.DictReader(handle))


def test_capture_folders_are_scored_view_by_view(small_capture, tmp_path):
    out = tmp_path / "out"
    assert main(["eval", "depth", str(small_capture), "-o", str(out)]) == 0
    rows = _rows(out / "depth_errors.csv")
    assert [r["name"] for r in rows] == [f"finger/{v}" for v in ("left", "center", "right")]
    from fingersplat3d.io.depth import read_depth

    ratios = []
    for row in rows:
        assert row["status"] == "done" and int(row["pixels"]) > 1000
        # The reconstruction carries the finger's shape: its aligned error is under that of the
        # best flat guess (the ground truth's median) in every view, far under it in most.
        truth = read_depth(small_capture / "depth" / f"{row['name'].split('/')[1]}.npy")
        ratios.append(float(row["mae_scale_shift"]) / np.nanmean(np.abs(truth - np.nanmedian(truth))))
        assert np.isfinite([float(row[k]) for k in ("mae_scale", "mae_weighted", "rmse_scale_shift")]).all()
        assert (out / "error_maps" / f"finger__{row['name'].split('/')[1]}.png").is_file()
    assert 0 < max(ratios) < 0.85 and np.median(ratios) < 0.4
    # Split by a second view's backing: the skin two views see is most of each view, and measured from the photos
    # it is truer than the skin one view alone sees, whose depth is the pointmap's guess.
    shares = [float(r["share_two_views"]) for r in rows]
    assert all(0.5 < share <= 1.0 for share in shares)
    two, one = (np.nanmean([float(r[k]) for r in rows]) for k in ("mae_two_views", "mae_one_view"))
    assert 0 < two < one
    summary = (out / "summary.md").read_text()
    assert "Cui et al." in summary and "the skin two views see" in summary


def test_polyu_mode_scores_images_against_height_maps(small_capture, tmp_path):
    from fingersplat3d.io.depth import read_depth

    images, truths = tmp_path / "images", tmp_path / "truth"
    images.mkdir()
    truths.mkdir()
    depth = read_depth(small_capture / "depth" / "center.npy")
    (images / "sample1.png").write_bytes((small_capture / "images" / "center.png").read_bytes())
    (images / "nomap.png").write_bytes((small_capture / "images" / "left.png").read_bytes())
    savemat(truths / "sample1.mat", {"fc": np.flipud(-depth.astype(float))})  # height = -depth, stored flipped
    (truths / "broken.mat").write_bytes(b"garbage")
    (images / "broken.png").write_bytes((small_capture / "images" / "right.png").read_bytes())
    out = tmp_path / "out"
    code = main(["eval", "depth", str(images), "--truth", str(truths), "-o", str(out)])
    assert code == EXIT_INCOMPLETE  # broken.mat could not be read: a failed row, not a crash
    rows = {r["name"]: r for r in _rows(out / "depth_errors.csv")}
    assert set(rows) == {"sample1", "broken"}
    assert rows["broken"]["status"] == "failed" and "broken.mat" in rows["broken"]["reason"]
    sample = rows["sample1"]
    assert sample["status"] == "done" and 0 < float(sample["mae_scale_shift"]) < 1.0
    assert float(sample["scale"]) > 0  # heights rise toward the camera: depth = -height
    # One photo (monocular mode): no second view backs anything, so its whole error is the guess's.
    assert float(sample["share_two_views"]) == 0 and np.isnan(float(sample["mae_two_views"]))
    assert float(sample["mae_one_view"]) == pytest.approx(float(sample["mae_scale_shift"]), rel=0.05)
    summary = (out / "summary.md").read_text()
    assert "nomap.png" in summary and "1 image(s) without a height map" in summary


def test_bad_arguments_are_one_sentence(tmp_path, capsys):
    assert main(["eval", "depth", str(tmp_path), "--truth", str(tmp_path / "missing"), "-o", str(tmp_path / "o")]) \
        == EXIT_INPUT
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "imgs").mkdir()
    assert main(["eval", "depth", str(tmp_path / "imgs"), "-o", str(tmp_path / "o")]) == EXIT_INPUT
    assert "not a capture folder" in capsys.readouterr().err
