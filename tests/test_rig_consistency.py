"""The rig check of real captures (eval/rig_consistency.py): portrait cameras, crops of other sizes, crops measured
against the whole captures' rig."""
import numpy as np
from scipy.spatial.transform import Rotation

from fingersplat3d.align.solve.rig import quarter_turn
from fingersplat3d.eval.rig_consistency import deviation_against, rig_consistency

RIG = [np.eye(3), Rotation.from_euler("x", 45, degrees=True).as_matrix(), Rotation.from_euler("x", -44, degrees=True).as_matrix()]


def _record(name, seed, sizes=((1280, 1024),) * 3, portrait=None, error=None, noise_deg=0.2):
    """One capture of the rig: each camera's world_to_cam = its rig rotation after the capture's own world turn (and a
    little noise); ``portrait``: that camera stored turned by a quarter turn; ``error``: (camera, rotation vector in
    degrees) put onto that camera."""
    rng = np.random.default_rng(seed)
    world = Rotation.random(random_state=seed).as_matrix()
    poses = []
    for k, rig in enumerate(RIG):
        rotation = Rotation.from_rotvec(np.radians(rng.normal(0, noise_deg, 3))).as_matrix() @ rig @ world
        if error is not None and error[0] == k:
            rotation = Rotation.from_rotvec(np.radians(error[1])).as_matrix() @ rotation
        if portrait == k:
            rotation = quarter_turn(1) @ rotation
        pose = np.eye(4)
        pose[:3, :3] = rotation
        poses.append(pose.tolist())
    sizes = [list(s) for s in sizes]
    if portrait is not None:
        sizes[portrait] = sizes[portrait][::-1]
    return {"capture": name, "registered": 3, "sizes": sizes, "world_to_cam": poses}


def test_a_portrait_camera_is_turned_back_and_captures_of_other_sizes_are_not():
    """One capture stores camera 0 portrait: its quarter turn is taken out (every deviation within the noise). Captures
    whose photos differ in size but not in orientation (crops) are not taken for portrait ones."""
    records = [_record(f"c{i}", i, sizes=((1280 - 40 * i, 1024),) * 3) for i in range(5)] + [_record("p", 9, portrait=0)]
    rig = rig_consistency(records)
    assert max(d for pair in rig.values() for d in pair["deviation_deg"].values()) < 1.5
    assert [r["capture"] for r in records if "roll_corrected" in r] == ["p"]
    assert abs(rig["01"]["mean_angle_deg"] - 45) < 0.5 and abs(rig["12"]["mean_angle_deg"] - 89) < 0.5


def test_crops_are_measured_against_the_whole_captures_rig():
    """Crops of the same captures (taller than wide, whatever the whole photos were) against the whole captures' rig:
    a crop with its cameras right reads the noise, one with camera 2 turned 3 degrees reads 3 on its pairs with 2; the
    crop of the capture whose camera 0 was stored portrait is turned back as its whole capture was."""
    whole = [_record(f"c{i}", i) for i in range(5)] + [_record("p", 9, portrait=0)]
    tall = ((300, 1024),) * 3
    crops = [_record("c0", 0, sizes=tall), _record("c1", 1, sizes=tall, error=(2, (0, 3.0, 0))),
             _record("p", 9, sizes=tall, portrait=0), _record("unknown", 7, sizes=tall)]
    deviations = deviation_against(crops, whole)
    assert set(deviations["01"]) == {"c0", "c1", "p"}  # a capture the reference lacks is left out
    assert all(deviations[pair]["c0"] < 1.0 and deviations[pair]["p"] < 1.0 for pair in deviations)
    assert deviations["01"]["c1"] < 1.0 and 2.0 < deviations["02"]["c1"] < 4.0 and 2.0 < deviations["12"]["c1"] < 4.0
    assert all("roll_corrected" not in r for r in whole)  # the reference records are not written to
