"""Minutiae by pyfing's LEADER, matched by bozorth3 through an ISO 19794-2 record (eval/learned_minutiae.py,
eval/iso_minutiae.py, analyse(extractor="leader"))."""
import sys

import numpy as np
import pytest

from fingersplat3d.errors import InputError
from fingersplat3d.eval.contact import contact_like
from fingersplat3d.eval.iso_minutiae import MAX_MINUTIAE, iso_minutiae_record
from fingersplat3d.synth import SynthConfig, synthesize


@pytest.fixture(scope="module")
def shots():
    """Two synthetic fingers, two poses each (the CFPose-like rig)."""
    return {seed: synthesize(seed, SynthConfig(rig="cfpose", size=(384, 480), poses=2)).capture for seed in (0, 1)}


def _kinds(found):
    return ["bifurcation" if "BIF" in str(m.kind()).upper() else "ending" for m in found]


def test_the_record_is_the_one_nbis_writes_and_scores_alike(shots):
    """mindtct's own minutiae written here are nbis-py's record to the byte, and bozorth3 scores them alike."""
    pytest.importorskip("nbis")
    import cv2

    from fingersplat3d.eval.fingerprint import _extractor

    extractor = _extractor(False)
    templates, ours = [], []
    for seed in (0, 1):
        view = shots[seed].views[0]
        image = contact_like(view.image, view.mask).image
        template = extractor.extract_minutiae(cv2.imencode(".png", image)[1].tobytes())
        record, found = template.to_iso_19794_2_2005(), template.get()
        quality = [record[26 + 6 * k + 5] for k in range(len(found))]  # nbis's own quality bytes
        written = iso_minutiae_record(image.shape[1], image.shape[0], [(m.x(), m.y()) for m in found],
                                      [m.angle() for m in found], _kinds(found), quality)
        assert written == record
        templates.append(template)
        ours.append(extractor.load_iso_19794_2_2005(written))
    assert ours[0].compare(ours[0]) == templates[0].compare(templates[0]) > 100
    assert ours[0].compare(ours[1]) == templates[0].compare(templates[1])


def test_the_record_keeps_the_best_minutiae_in_their_order_and_refuses_what_it_cannot_hold():
    rng = np.random.default_rng(0)
    count = MAX_MINUTIAE + 40
    xy, angles, quality = rng.uniform(0, 300, (count, 2)), rng.uniform(0, 360, count), rng.uniform(0, 100, count)
    record = iso_minutiae_record(320, 320, xy, angles, ["ending"] * count, quality)
    assert record[25] == MAX_MINUTIAE and len(record) == 26 + 6 * MAX_MINUTIAE
    assert int.from_bytes(record[8:12], "big") == len(record)
    kept = np.sort(np.argsort(-quality)[:MAX_MINUTIAE])
    first = int.from_bytes(record[26:28], "big") & 0x3FFF
    assert first == round(xy[kept[0], 0])  # the best, in the order given
    assert iso_minutiae_record(10, 10, np.zeros((0, 2)), [], [], [])[25] == 0  # none: an empty record
    with pytest.raises(ValueError, match="same minutiae"):
        iso_minutiae_record(10, 10, np.zeros((2, 2)), [0.0], ["ending"], [1.0, 2.0])
    with pytest.raises(ValueError, match="a side"):
        iso_minutiae_record(0, 10, np.zeros((0, 2)), [], [], [])
    with pytest.raises(ValueError, match="finite"):
        iso_minutiae_record(10, 10, [[np.nan, 1.0]], [0.0], ["ending"], [1.0])


def test_leader_finds_minutiae_on_the_finger_and_bozorth3_tells_fingers_apart(shots):
    """LEADER's minutiae, in the photo's pixels and directions, lie on the finger, and their templates score a finger
    against itself far above another finger."""
    pytest.importorskip("nbis")
    from fingersplat3d.eval.fingerprint import analyse, match_score

    prints = {}
    for seed in (0, 1):
        view = shots[seed].views[0]
        found = prints[seed] = analyse(contact_like(view.image, view.mask), nfiq2=False, extractor="leader")
        assert found.count > 10 and found.template is not None and np.isfinite(found.minutiae).all()
        assert ((found.minutiae[:, 2] >= 0) & (found.minutiae[:, 2] < 360)).all()
        assert ((found.minutiae[:, 3] >= 0) & (found.minutiae[:, 3] <= 1)).all()
        assert set(found.kinds) <= {"ending", "bifurcation"}
        cols, rows = np.rint(found.minutiae[:, :2]).astype(int).T
        inside = view.mask[np.clip(rows, 0, view.mask.shape[0] - 1), np.clip(cols, 0, view.mask.shape[1] - 1)]
        assert inside.mean() > 0.95
    assert match_score(prints[0], prints[0]) > 3 * max(match_score(prints[0], prints[1]), 10)
    other_pose = analyse(contact_like(shots[0].views[1].image, shots[0].views[1].mask), nfiq2=False, extractor="leader")
    assert match_score(other_pose, prints[0]) > 2 * match_score(other_pose, prints[1])  # the same finger, rolled


def test_leader_and_mindtct_agree_on_directions(shots):
    """The two extractors' directions share one convention: minutiae both find within 3 px point alike."""
    pytest.importorskip("nbis")
    from scipy.spatial import cKDTree

    from fingersplat3d.eval.fingerprint import analyse

    view = shots[0].views[0]
    contact = contact_like(view.image, view.mask)
    mindtct, leader = analyse(contact, nfiq2=False), analyse(contact, nfiq2=False, extractor="leader")
    distance, index = cKDTree(leader.minutiae[:, :2]).query(mindtct.minutiae[:, :2])
    near = distance < 3.0
    assert near.sum() >= 10
    turn = (mindtct.minutiae[near, 2] - leader.minutiae[index[near], 2] + 180.0) % 360.0 - 180.0
    assert np.median(np.abs(turn)) < 20.0


def test_no_minutiae_and_bad_names_are_clear(monkeypatch):
    pytest.importorskip("nbis")
    from fingersplat3d.eval.contact import ContactImage
    from fingersplat3d.eval.fingerprint import analyse, match_score
    from fingersplat3d.eval.learned_minutiae import leader_minutiae

    blank = analyse(ContactImage.of_print(np.full((300, 300), 255, np.uint8)), nfiq2=False, extractor="leader")
    assert blank.count == 0 and "LEADER found no minutiae" in blank.failure and match_score(blank, blank) == 0
    with pytest.raises(InputError, match="unknown minutiae extractor"):
        analyse(ContactImage.of_print(np.full((300, 300), 255, np.uint8)), extractor="veri")
    with pytest.raises(ValueError, match="8-bit gray"):
        leader_minutiae(np.zeros((10, 10), np.float32))
    monkeypatch.setitem(sys.modules, "pyfing", None)  # import pyfing -> ImportError
    with pytest.raises(InputError, match="pip install 'fingersplat3d\\[learned\\]'"):
        leader_minutiae(np.full((64, 64), 255, np.uint8))
