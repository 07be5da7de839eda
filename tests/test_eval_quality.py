"""`fs3d eval quality`: leave-one-view-out renders scored against the photos."""
import csv

import pytest

from fingersplat3d.cli import main
from fingersplat3d.errors import EXIT_INCOMPLETE, EXIT_INPUT


@pytest.fixture(scope="module")
def small_capture(tmp_path_factory):
    folder = tmp_path_factory.mktemp("quality") / "uwa_small"
    assert main(["synth", "--rig", "uwa", "--seed", "3", "--size", "320x256", str(folder)]) == 0
    return folder


def test_every_view_is_left_out_and_scored(small_capture, tmp_path, capsys):
    pytest.importorskip("nbis")
    out = tmp_path / "q"
    assert main(["eval", "quality", str(small_capture), "--splat-preset", "fast", "--splat-iterations", "100", "-o",
                 str(out)]) == 0
    rows = list(csv.DictReader(open(out / "quality.csv")))
    assert [r["view"] for r in rows] == ["left", "center", "right"]
    for row in rows:
        assert row["status"] == "done" and row["view"] not in row["train_views"].split()
        assert len(row["train_views"].split()) == 2
        assert 10.0 < float(row["psnr"]) < 60.0 and 0.0 < float(row["ssim"]) <= 1.0
        assert float(row["psnr"]) >= float(row["psnr_placed"]) - 0.5  # the alignment never makes it much worse
        assert row["nfiq2_real"] != "" or row["nfiq2_failure"]
        # the left-out view rendered at its exposure against the fitted views': one light, one exposure, all alike
        assert 0.9 < float(row["exposure"]) < 1.1
        # the finger split by where the render comes from: the skin the fitted views saw and the completion's guess;
        # the two parts' errors make up the whole view's
        share = float(row["unseen_share"])
        assert 0.0 <= share <= 1.0 and 10.0 < float(row["psnr_seen"]) < 60.0
        if row["psnr_unseen"] != "":
            mse = lambda db: 10.0 ** (-float(db) / 10.0)  # noqa: E731
            parts = (1.0 - share) * mse(row["psnr_seen"]) + share * mse(row["psnr_unseen"])
            assert parts == pytest.approx(mse(row["psnr"]), rel=1e-3)
        # the seen skin beside the completion: scored where there is enough of it, its tone a difference of grey levels
        assert (row["psnr_beside_unseen"] == "") == (row["tone_beside_unseen"] == "")
        if row["psnr_beside_unseen"] != "":
            assert row["psnr_unseen"] != "" and 5.0 < float(row["psnr_beside_unseen"]) < 60.0
            assert -1.0 <= float(row["tone_beside_unseen"]) <= 1.0
    assert len(list((out / "views").glob("*.png"))) == 3
    summary = (out / "summary.md").read_text()
    assert "38.13" in summary and "| uwa_small | center |" in summary and "skin the fitted views saw" in summary
    assert "mean PSNR" in capsys.readouterr().out


def test_one_view_cannot_be_left_out(small_capture, tmp_path, capsys):
    out = tmp_path / "one"
    assert main(["eval", "quality", str(small_capture / "images" / "center.png"), "--no-nfiq2", "-o", str(out)]) == EXIT_INCOMPLETE
    assert "nothing to leave out" in (out / "summary.md").read_text()
    assert main(["eval", "quality", str(tmp_path / "missing"), "-o", str(tmp_path / "x")]) == EXIT_INPUT
    assert "not found" in capsys.readouterr().err and not (tmp_path / "x").exists()
