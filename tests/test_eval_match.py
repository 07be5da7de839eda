"""`fs3d eval match`: naming, pairs, both protocols end to end, bad input."""
import csv

import cv2
import numpy as np
import open3d as o3d
import pytest

from fingersplat3d.cli import main
from fingersplat3d.errors import EXIT_INPUT
from fingersplat3d.experiments.match import UWA_NAMING, parse_samples, real_pairs
from fingersplat3d.io.cameras import write_cameras
from fingersplat3d.io.gaussians_ply import write_gaussians_ply
from fingersplat3d.io.images import write_image
from fingersplat3d.splat.init import gaussians_from_cloud
from fingersplat3d.synth import SynthConfig, synthesize

pytest.importorskip("nbis")


def test_uwa_names_give_finger_capture_and_view(tmp_path):
    paths = [tmp_path / n for n in ("1_1_4_1_0.jpg", "1_1_4_1_1.jpg", "2_2_10_1_0.jpg", "1_1_7_1_0.jpg", "notes.png")]
    samples, unparsed = parse_samples(paths, UWA_NAMING)
    assert [(s.finger, s.capture, s.view) for s in samples] == [
        ("1_1", "1_1/4_1", "0"), ("1_1", "1_1/4_1", "1"), ("2_2", "2_2/10_1", "0"), ("1_1", "1_1/7_1", "0")]
    assert [p.name for p in unparsed] == ["notes.png"]
    pairs = real_pairs(samples)  # different captures, same view only
    assert sorted((samples[i].name, samples[j].name, g) for i, j, g in pairs) == [
        ("1_1_4_1_0", "1_1_7_1_0", True), ("1_1_4_1_0", "2_2_10_1_0", False), ("2_2_10_1_0", "1_1_7_1_0", False)]
    only_front, _ = parse_samples(paths, UWA_NAMING, views={"1"})
    assert [s.name for s in only_front] == ["1_1_4_1_1"]


def _moved(image: np.ndarray, degrees: float, shift: tuple[float, float]) -> np.ndarray:
    h, w = image.shape[:2]
    matrix = cv2.getRotationMatrix2D((w / 2, h / 2), degrees, 1.0)
    matrix[:, 2] += shift
    return cv2.warpAffine(image, matrix, (w, h), flags=cv2.INTER_LINEAR, borderValue=0.0)


@pytest.fixture(scope="module")
def match_data(tmp_path_factory, uwa640):
    """Finger 1_1: capture 1 (uwa640) and capture 2 (the same photos turned and shifted); finger 2_2: another
    synthetic finger; and a reconstruction of capture 1 built from its ground truth (cloud -> Gaussians)."""
    root = tmp_path_factory.mktemp("match")
    photos = root / "photos"
    other = synthesize(4, SynthConfig(size=(640, 512))).capture
    for k, view in enumerate(uwa640.views):
        write_image(photos / f"1_1_1_1_{k}.png", view.image)
        write_image(photos / f"1_1_2_1_{k}.png", _moved(view.image, 4.0, (12.0, -8.0)))
        write_image(photos / f"2_2_1_1_{k}.png", other.views[k].image)
    points, colours = [], []
    for view in uwa640.views:
        rows, cols = np.nonzero(view.mask & np.isfinite(view.depth))
        uv = np.stack([cols, rows], 1).astype(np.float64)
        points.append(view.camera.unproject(uv, view.depth[rows, cols]))
        colours.append(np.repeat(np.atleast_2d(view.image[rows, cols]).reshape(len(rows), -1)[:, :1], 3, 1))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.concatenate(points)))
    cloud.colors = o3d.utility.Vector3dVector(np.concatenate(colours).astype(np.float64))
    cloud = cloud.voxel_down_sample(0.04)
    rec = root / "rec_1_1_1_1"
    rec.mkdir()
    write_gaussians_ply(rec / "gaussians.ply", gaussians_from_cloud(cloud, 1, opacity=0.9))
    write_cameras(rec / "cameras.json", [(v.name, f"1_1_1_1_{k}.png", v.camera) for k, v in enumerate(uwa640.views)])
    return photos, rec


def test_both_protocols_end_to_end(match_data, tmp_path, capsys):
    photos, rec = match_data
    (photos / "readme.png").write_bytes(b"")  # a name that does not parse: skipped, said
    out = tmp_path / "out"
    try:
        code = main(["eval", "match", str(photos), "--reconstructions", str(rec), "--angles=-20,0,20", "-o", str(out)])
    finally:
        (photos / "readme.png").unlink()
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "readme.png does not follow the naming pattern" in captured.err
    for name in ("scores.csv", "prints.csv", "summary.md", "det.png"):
        assert (out / name).is_file()
    assert len(list((out / "prints").glob("*.png"))) == 9 + 3
    rows = list(csv.DictReader(open(out / "scores.csv")))
    real = [r for r in rows if r["protocol"] == "real"]
    assert len(real) == 3 * 3  # per view: (c1, c2) genuine, (c1, f2) and (c2, f2) impostor
    genuine = [int(r["score"]) for r in real if r["genuine"] == "1"]
    impostor = [int(r["score"]) for r in real if r["genuine"] == "0"]
    assert min(genuine) > max(impostor)
    synthesized = [r for r in rows if r["protocol"] == "synthesized"]
    # the renders are compared with the gallery view (the middle camera: label 1) of the other captures
    assert {r["gallery"] for r in synthesized} == {"1_1_2_1_1", "2_2_1_1_1"}
    at_zero = {r["gallery"]: int(r["score"]) for r in synthesized if float(r["angle_deg"]) == 0.0}
    assert at_zero["1_1_2_1_1"] > at_zero["2_2_1_1_1"]
    summary = (out / "summary.md").read_text()
    assert "| real | 3 | 6 |" in summary and "| +20 |" in summary and "FMR_zero" in summary
    prints = list(csv.DictReader(open(out / "prints.csv")))
    assert all(r["nfiq2"] for r in prints if r["name"].startswith("1_1_1"))


def test_learned_minutiae_tell_the_same_finger_apart(match_data, tmp_path, capsys):
    """--minutiae leader: the same photos compared on pyfing's LEADER minutiae; the turned copy of a capture still
    scores above the other finger, and the summary names the extractor."""
    photos, _ = match_data
    out = tmp_path / "out"
    assert main(["eval", "match", str(photos), "--views", "1", "--minutiae", "leader", "-o", str(out)]) == 0
    rows = list(csv.DictReader(open(out / "scores.csv")))
    genuine = [int(r["score"]) for r in rows if r["genuine"] == "1"]
    impostor = [int(r["score"]) for r in rows if r["genuine"] == "0"]
    assert len(genuine) == 1 and len(impostor) == 2 and min(genuine) > max(impostor)
    assert (out / "summary.md").read_text().startswith("# Matching (leader + bozorth3)")
    capsys.readouterr()


def test_bad_input_is_one_sentence(match_data, tmp_path, capsys):
    photos, rec = match_data
    assert main(["eval", "match", str(photos / "1_1_1_1_0.png"), "-o", str(tmp_path / "a")]) == EXIT_INPUT
    assert "at least two captures" in capsys.readouterr().err
    assert main(["eval", "match", str(photos), "--naming", "(?P<x>.*)", "-o", str(tmp_path / "b")]) == EXIT_INPUT
    assert "named groups" in capsys.readouterr().err
    assert main(["eval", "match", str(photos), "--reconstructions", str(photos), "-o", str(tmp_path / "c")]) == EXIT_INPUT
    assert "not a reconstruction folder" in capsys.readouterr().err
    assert main(["eval", "match", str(photos), "--angles", "left", "-o", str(tmp_path / "d")]) == EXIT_INPUT
    assert not any((tmp_path / n).exists() for n in "abcd")


def test_real_captures_make_prints_nfiq2_scores_and_a_table(real_dev, tmp_path):
    # Two captures of each of the two dev fingers, front camera: every photo becomes a scored print.
    photos = [real_dev / f"{c}_0.jpg" for c in ("1_1_1_1", "1_1_2_1", "2_2_8_1", "2_2_9_1")]
    out = tmp_path / "real"
    assert main(["eval", "match", *map(str, photos), "-o", str(out)]) == 0
    prints = list(csv.DictReader(open(out / "prints.csv")))
    assert len(prints) == 4 and all(20 < int(p["minutiae"]) and 0 <= float(p["nfiq2"]) <= 100 for p in prints)
    rows = list(csv.DictReader(open(out / "scores.csv")))
    assert sum(r["genuine"] == "1" for r in rows) == 2 and sum(r["genuine"] == "0" for r in rows) == 4
    assert "| real | 2 | 4 |" in (out / "summary.md").read_text()


def _gallery_rows(out):
    return [r for r in csv.DictReader((out / "scores.csv").open()) if r["protocol"] == "photos vs gallery"]


def _contact_gallery(tmp_path):
    """Two shipped synthetic fingers: their front photos as probes, their true rolled prints as a contact gallery
    (named by finger)."""
    import shutil
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "data_samples"
    probes, gallery = tmp_path / "probes", tmp_path / "gallery"
    probes.mkdir()
    gallery.mkdir()
    for finger, sample in (("7_1", "uwa_seed0"), ("8_1", "uwa_seed1")):
        shutil.copy(root / sample / "images" / "center.png", probes / f"{finger}_1_1_0.png")
        shutil.copy(root / sample / "rolled_print.png", gallery / f"{finger}.png")
    return root, probes, gallery


def _genuine_above_impostors(rows) -> list[int]:
    genuine = [int(r["score"]) for r in rows if r["genuine"] == "1"]
    assert min(genuine) > max(int(r["score"]) for r in rows if r["genuine"] == "0")
    return genuine


def test_photos_against_a_contact_gallery_either_way_round(tmp_path, capsys):
    """The photos' prints against the gallery as it is and mirrored as inked prints are: the way round read from the
    scores, each photo's own finger above the impostors either way."""
    root, probes, gallery = _contact_gallery(tmp_path)
    out = tmp_path / "out"
    status = main(["eval", "match", str(probes), "--gallery", str(gallery), "--rolled", str(root / "uwa_seed0"),
                   "-o", str(out)])
    assert status == 2 and "naming pattern" in capsys.readouterr().err  # a capture folder's photos are not UWA-named
    assert main(["eval", "match", str(probes), "--gallery", str(gallery), "--gallery-naming", "(?P<who>.+)",
                 "-o", str(tmp_path / "o2")]) == 2
    assert main(["eval", "match", str(probes), "--gallery", str(gallery), "-o", str(out)]) == 0
    gallery_rows = _gallery_rows(out)
    assert len(gallery_rows) == 4 and sum(int(r["genuine"]) for r in gallery_rows) == 2
    _genuine_above_impostors(gallery_rows)  # the photos' prints match their own fingers' rolled prints
    assert "photos vs gallery" in (out / "summary.md").read_text()
    # Against the flat-laid gallery the photos are unrolled first; compared with each other they are not.
    assert {p.name for p in (out / "prints").iterdir()} >= {"7_1_1_1_0.png", "7_1_1_1_0@unrolled.png"}
    # The default reads the gallery's way round from the scores: these true rolled prints keep a photo's handedness
    assert all(r["mirrored"] == "0" for r in gallery_rows)
    assert "compared as they are (the gallery's way round read from the scores" in (out / "summary.md").read_text()
    # A gallery the other way round (as inked or live-scan prints are): found so, and the photos mirrored to meet it
    inked = tmp_path / "inked"
    inked.mkdir()
    for path in gallery.iterdir():
        cv2.imwrite(str(inked / path.name), cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)[:, ::-1])
    assert main(["eval", "match", str(probes), "--gallery", str(inked), "-o", str(tmp_path / "found")]) == 0
    found = _gallery_rows(tmp_path / "found")
    assert all(r["mirrored"] == "1" for r in found)
    _genuine_above_impostors(found)


@pytest.mark.slow
def test_a_contact_gallerys_options_flat_mirror_and_scale(tmp_path):
    """The same gallery with each option that overrides a default (5 runs of the command, ~35 s: slow): photos laid
    flat, the gallery's way round fixed either way, and a gallery scanned coarser compared at scales about the photos'
    ridge period or as it is."""
    _, probes, gallery = _contact_gallery(tmp_path)
    out = tmp_path / "out"
    assert main(["eval", "match", str(probes), "--gallery", str(gallery), "--flat", "-o", str(tmp_path / "flat")]) == 0
    assert not any("@unrolled" in p.name for p in (tmp_path / "flat" / "prints").iterdir())
    _genuine_above_impostors(_gallery_rows(tmp_path / "flat"))
    assert main(["eval", "match", str(probes), "--gallery", str(gallery), "--no-mirror", "-o", str(out)]) == 0
    genuine = _genuine_above_impostors(_gallery_rows(out))
    assert main(["eval", "match", str(probes), "--gallery", str(gallery), "--mirror", "-o", str(out),
                 "--overwrite"]) == 0
    mirrored = _gallery_rows(out)
    assert max(int(r["score"]) for r in mirrored if r["genuine"] == "1") < min(genuine)  # handedness matters
    assert all(r["mirrored"] == "1" for r in mirrored)
    assert "as --mirror or --no-mirror fixes it" in (out / "summary.md").read_text()
    # Fingers whose ridges lie closer than the photos' 9 px (or a gallery scanned coarser): each gallery print is
    # compared at scales about the photos' ridge period, each pair at its best
    coarse = tmp_path / "coarse"
    coarse.mkdir()
    for path in gallery.iterdir():
        cv2.imwrite(str(coarse / path.name), cv2.resize(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), None, fx=0.8,
                                                        fy=0.8, interpolation=cv2.INTER_AREA))
    for flag, folder in (([], "scaled"), (["--gallery-as-is"], "own_scale")):
        assert main(["eval", "match", str(probes), "--gallery", str(coarse), *flag, "-o", str(tmp_path / folder)]) == 0
    scaled, own = _gallery_rows(tmp_path / "scaled"), _gallery_rows(tmp_path / "own_scale")
    assert all(1.0 < float(r["gallery_scale"]) < 1.6 for r in scaled) and {r["gallery_scale"] for r in own} == {"1.0"}
    for probe in {r["probe"] for r in scaled}:
        best, plain = ([int(r["score"]) for r in rows if r["genuine"] == "1" and r["probe"] == probe][0]
                       for rows in (scaled, own))
        assert best > plain


def test_a_galleries_handedness_is_read_from_the_best_scores_alone():
    from fingersplat3d.eval.handedness import gallery_handedness, median_best

    nan = float("nan")
    # three probes, four gallery prints: the right way round each probe's best is its own finger's print
    as_is = np.array([[7.0, 9, 6, 8], [5, 6, 8, 7], [9, 5, 6, 6]])
    mirrored = np.array([[40.0, 9, 6, 8], [5, 31, 8, 7], [9, 5, 6, 12]])
    way = gallery_handedness(as_is, mirrored)
    assert way.mirrored and way.best_mirrored == 31.0 and way.best_as_is == 9.0  # medians of the rows' best
    assert not gallery_handedness(mirrored, as_is).mirrored
    # a tie, or nothing told apart: kept as they are; a probe with no minutiae (a NaN row) is left out
    assert not gallery_handedness(as_is, as_is).mirrored
    with_gap = np.vstack([mirrored, [nan] * 4])
    assert median_best(with_gap) == median_best(mirrored) == 31.0
    # one way never compared (every template empty): the other is taken, and no comparison at all keeps them as they are
    assert gallery_handedness(np.full((2, 3), nan), mirrored[:2]).mirrored
    assert not gallery_handedness(np.full((2, 3), nan), np.full((2, 3), nan)).mirrored
    with pytest.raises(ValueError, match="probes, gallery"):
        median_best(np.zeros(3))


def test_a_rolled_print_is_compared_with_photos_at_scales_about_their_ridge_period():
    """The rolled print of a model against photos (protocol 'rolled vs photos'): five scales about the photos' ridge
    period, each with its minutiae; the print itself where no period is read."""
    from pathlib import Path

    from fingersplat3d.eval.contact import SCALE_STEPS, ContactImage
    from fingersplat3d.eval.fingerprint import analyse, match_score
    from fingersplat3d.experiments.match import _about_period, _Print

    image = cv2.imread(str(Path(__file__).resolve().parents[1] / "data_samples" / "uwa_seed1" / "rolled_print.png"),
                       cv2.IMREAD_GRAYSCALE)
    fingerprint = analyse(ContactImage.of_print(image), nfiq2=False)
    about = _about_period(_Print("rolled", fingerprint, "", image), "mindtct")
    assert len(about) == len(SCALE_STEPS) and all(f.count > 20 for f in about)
    # the print reads 7.9 px a ridge: brought to 9 px it is 1.14 times as large, so the smallest step (0.87) lies
    # nearest its own scale and matches it best, the largest worst
    scores = [match_score(f, fingerprint) for f in about]
    assert scores[0] == max(scores) and scores[-1] == min(scores)
    blank = np.full((300, 300), 255, np.uint8)
    assert _about_period(_Print("blank", fingerprint, "", blank), "mindtct") == (fingerprint,)
