"""`fs3d eval register`: minutia pairing, the 2D baselines, mates, and the command end to end."""
import csv

import numpy as np
import pytest

from fingersplat3d.cli import main
from fingersplat3d.errors import EXIT_INPUT, InputError
from fingersplat3d.eval.minutiae_pairs import pair_minutiae
from fingersplat3d.eval.warp2d import BASELINES, cross_validated_errors, fit_similarity
from fingersplat3d.experiments.register import read_mates_csv, truth_mates


def _minutiae(rng, n=60, size=400.0):
    return rng.uniform(0, size, (n, 2)), rng.uniform(0, 360, n)


def _turned(xy, angles, degrees, shift, scale=1.0):
    turn = np.deg2rad(degrees)
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    return scale * xy @ rotation.T + shift, (angles + degrees) % 360.0


def test_pairing_recovers_the_mates_of_a_turned_print_among_extra_minutiae():
    rng = np.random.default_rng(0)
    xy, angles = _minutiae(rng)
    xy_b, angles_b = _turned(xy, angles, 25.0, np.array([40.0, -30.0]))
    xy_b += rng.normal(0, 1.5, xy_b.shape)
    extra_xy, extra_angles = _minutiae(rng, 25)
    xy_b, angles_b = np.vstack([xy_b[:45], extra_xy]), np.concatenate([angles_b[:45], extra_angles])
    index_a, index_b, votes = pair_minutiae(xy, angles, xy_b, angles_b)
    assert len(index_a) >= 30
    assert np.mean(index_a == index_b) > 0.95  # b's first 45 are a's first 45
    assert np.all(np.diff(votes) <= 0) or len(set(index_a)) == len(index_a)
    assert len(set(index_a)) == len(index_a) and len(set(index_b)) == len(index_b)  # one to one


def test_unrelated_prints_are_not_paired():
    rng = np.random.default_rng(1)
    index_a, _, _ = pair_minutiae(*_minutiae(rng), *_minutiae(rng))
    assert index_a.size == 0
    assert pair_minutiae(np.zeros((1, 2)), np.zeros(1), np.zeros((5, 2)), np.zeros(5))[0].size == 0


def test_similarity_ransac_ignores_outliers_and_tps_is_scored_on_unseen_mates():
    rng = np.random.default_rng(2)
    source = rng.uniform(0, 500, (40, 2))
    target, _ = _turned(source, np.zeros(40), 10.0, np.array([5.0, 7.0]), scale=0.9)
    target[:6] += rng.uniform(80, 150, (6, 2))  # outliers
    mapping, inliers = fit_similarity(source, target)
    assert inliers[6:].all() and not inliers[:6].any()
    assert np.abs(mapping(source[6:]) - target[6:]).max() < 1e-4  # OpenCV refines in float32
    # a smooth bend: TPS follows it, the similarity cannot
    bent = source + np.stack([0.0004 * (source[:, 1] - 250) ** 2, np.zeros(40)], 1)
    similarity = cross_validated_errors(source, bent, BASELINES["rigid 2D"])
    tps = cross_validated_errors(source, bent, BASELINES["TPS"])
    assert np.nanmean(tps) < 0.5 * np.nanmean(similarity)
    # mates of pure noise: an interpolating fit would score 0 on its own training data; held out it cannot
    noise = rng.uniform(0, 500, (40, 2))
    assert np.nanmean(cross_validated_errors(source, noise, BASELINES["TPS"])) > 50
    assert np.isnan(cross_validated_errors(source[:2], target[:2], BASELINES["TPS"])).all()


def test_mates_from_ground_truth_and_from_a_csv(tmp_path):
    minutiae = {"views": {"a": [{"id": 1, "uv": [1, 2], "visible": True}, {"id": 2, "uv": [3, 4], "visible": False},
                                {"id": 3, "uv": [5, 6], "visible": True}],
                          "b": [{"id": 3, "uv": [7, 8], "visible": True}, {"id": 1, "uv": [9, 10], "visible": True}]}}
    mates = truth_mates(minutiae, "a", "b")
    assert mates.xy_a.tolist() == [[1, 2], [5, 6]] and mates.xy_b.tolist() == [[9, 10], [7, 8]]
    assert truth_mates(minutiae, "a", "c") is None
    good = tmp_path / "m.csv"
    good.write_text("view_a,view_b,x_a,y_a,x_b,y_b\ncenter,left,1,2,3,4\ncenter,left,5,6,7,8\n")
    assert read_mates_csv(good)[("center", "left")].shape == (2, 4)
    (tmp_path / "cols.csv").write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="missing view_a"):
        read_mates_csv(tmp_path / "cols.csv")
    (tmp_path / "text.csv").write_text("view_a,view_b,x_a,y_a,x_b,y_b\ncenter,left,one,2,3,4\n")
    with pytest.raises(InputError, match="line 2"):
        read_mates_csv(tmp_path / "text.csv")


@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    rec = tmp_path_factory.mktemp("eval_register") / "uwa_seed0"
    assert main(["fuse", "data_samples/uwa_seed0", "-o", str(rec), "--no-splat"]) == 0
    return rec


def test_command_with_ground_truth_mates(fused, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["eval", "register", str(fused), "-o", str(out)]) == 0  # minutiae.json found beside images/
    rows = list(csv.DictReader(open(out / "register_errors.csv")))
    assert {(r["view_a"], r["view_b"]) for r in rows} == {("center", "left"), ("center", "right")}
    assert all(r["mates_source"] == "ground truth" and r["status"] == "done" for r in rows)
    error = {(r["view_b"], r["method"]): float(r["mean_px"]) for r in rows}
    for side in ("left", "right"):
        assert error[(side, "3D")] < 5.0  # 640x512, through the fused geometry
        assert error[(side, "3D")] < error[(side, "rigid 2D")]
    for row in rows:  # the mates-free check: A's ridges land on B's, in phase
        if row["method"] == "3D":
            assert float(row["warp_shift_px"]) < 2.0 and float(row["warp_ncc"]) > 0.4
            # what is left after a smooth flow: at least as much agreement, under a pixel of shift across the ridges
            assert float(row["warp_ncc_flowed"]) >= float(row["warp_ncc"]) - 0.02
            assert 0.0 <= float(row["warp_residual_depth_px"]) < 1.0
    assert len(list((out / "pictures").glob("*.png"))) == 2 and len(list((out / "mates").glob("*.csv"))) == 2
    summary = (out / "summary.md").read_text()
    assert "52.27" in summary and "| uwa_seed0 | center -> left |" in summary
    assert "3D: mean" in capsys.readouterr().out


def test_command_with_user_mates_and_bad_input(fused, tmp_path, capsys):
    mates = tmp_path / "mates.csv"
    mates.write_text("view_a,view_b,x_a,y_a,x_b,y_b\n" + "".join(
        f"left,center,{x},{y},{x + 1},{y}\n" for x, y in [(300, 250), (320, 260), (340, 240), (310, 230), (330, 270)]))
    out = tmp_path / "user"
    code = main(["eval", "register", str(fused), "--pairs", "center:left", "--mates", str(mates), "-o", str(out)])
    rows = list(csv.DictReader(open(out / "register_errors.csv")))
    assert code in (0, 4) and {r["mates_source"] for r in rows} == {"csv"} and rows[0]["mates"] == "5"
    # A pair without mates is not scored, yet still gets the mates-free warp check.
    out = tmp_path / "partly"
    main(["eval", "register", str(fused), "--pairs", "center:left,center:right", "--mates", str(mates), "-o", str(out)])
    right = [r for r in csv.DictReader(open(out / "register_errors.csv")) if r["view_b"] == "right"]
    assert len(right) == 1 and right[0]["status"] == "failed" and "no rows" in right[0]["reason"]
    assert float(right[0]["warp_shift_px"]) < 2.0 and float(right[0]["warp_ncc"]) > 0.4
    assert "Median ridge NCC over 2 pairs" in (out / "summary.md").read_text()
    assert main(["eval", "register", str(fused), "--pairs", "center:nope", "-o", str(tmp_path / "a")]) == EXIT_INPUT
    assert "no view named 'nope'" in capsys.readouterr().err
    assert main(["eval", "register", str(fused), "--pairs", "center", "-o", str(tmp_path / "b")]) == EXIT_INPUT
    assert main(["eval", "register", str(tmp_path), "-o", str(tmp_path / "c")]) == EXIT_INPUT
    assert "not a reconstruction folder" in capsys.readouterr().err
    assert main(["eval", "register", str(fused), "--matcher", "--truth", str(mates), "-o", str(tmp_path / "d")]) == EXIT_INPUT
    assert not any((tmp_path / n).exists() for n in "abcd")


def test_the_summary_says_when_the_warp_check_is_in_sample():
    from fingersplat3d.experiments.register import summary_markdown

    def row(name, fitted):
        return {"reconstruction": name, "view_a": "f0", "view_b": "f1", "status": "failed", "reason": "no mates",
                "warp_shift_px": 0.3, "warp_ncc": 0.5, "warp_fitted": fitted}

    plain = summary_markdown([row("a", False), row("b", False)])
    assert "Median ridge NCC over 2 pairs: 0.50" in plain and "in-sample" not in plain
    marked = summary_markdown([row("a", False), row("b", True)])
    assert "b: made with `fs3d fuse --photometric`" in marked and "in-sample" in marked


def test_the_warp_residual_experiment_fits_one_pair_and_scores_the_other(fused):
    """tools/bench_warp_residual.py's rows: a depth corrected by one pair's flow keeps that pair's ridges as close or
    brings them closer (the property it is built on); the pair it was not fitted to is scored too; no other finger
    here, so no control. The sample's pairs start ridge-true (warp NCC 0.84 / 0.86 since stop 83; the flow's depth
    residual 0.8 / 0.1 px), and the correction moves them by -0.012 / +0.019; where the fuse had left the left pair at
    0.81 (a 1.9 px residual), it raised it to 0.84."""
    from fingersplat3d.experiments.warp_residual import warp_residual_rows

    rows = warp_residual_rows([fused])
    assert {(r["view_a"], r["view_b"]) for r in rows} == {("left", "center"), ("right", "center")}
    for row in rows:
        assert row["depth_fitted_ncc_after"] > row["depth_fitted_ncc"] - 0.02
        assert np.isfinite(row["depth_held_out_ncc_after"]) and np.isnan(row["impostor_ncc_flowed"])
        assert row["warp_ncc_flowed"] >= row["warp_ncc"] - 0.02
