"""The same photos in every order (experiments/orders.py): the cameras put back in the capture's own order, the
spread over the orders, the table; on a stand-in for the fuse (the fuse's own order test is in tests/test_register.py)."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingersplat3d.experiments import orders
from fingersplat3d.scene import Capture, View

YAW = {"front": 0.0, "left": 45.0, "right": -44.0}  # each camera's true turn about y


def _pose(degrees: float) -> list:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("y", degrees, degrees=True).as_matrix()
    return pose.tolist()


def _fake_measure(wobble_deg: float = 0.0, focal_step: float = 0.0):
    """A stand-in for measure_real: each view's camera from its name (turned ``wobble_deg`` more for each place it
    moved from the capture's order), the focal ``focal_step`` more per such place."""
    def measure(capture, config=None):
        names = [view.name for view in capture.views]
        moved = sum(name != original for name, original in zip(names, YAW))
        return {"capture": "c", "finger": "1_1", "registered": 3, "seconds": 1.0, "peak_rss_mb": 1.0,
                "residual_px": 0.3, "focal": 1000.0 + focal_step * moved,
                "world_to_cam": [_pose(YAW[name] + (wobble_deg * moved if name == "left" else 0.0)) for name in names],
                "sizes": [[64 + k, 48] for k, _ in enumerate(names)]}
    return measure


@pytest.fixture
def capture():
    return Capture(tuple(View(name, np.zeros((48, 64))) for name in YAW), {"name": "c"})


def test_every_order_comes_back_in_the_captures_own_order(monkeypatch, capture):
    from fingersplat3d.experiments import real

    monkeypatch.setattr(real, "measure_real", _fake_measure())
    by_order = orders.in_every_order(capture)
    assert sorted(by_order) == ["012", "021", "102", "120", "201", "210"]
    for key, record in by_order.items():
        assert record["order"] == key
        turns = [Rotation.from_matrix(np.asarray(pose)[:3, :3]).as_euler("yxz", degrees=True)[0]
                 for pose in record["world_to_cam"]]
        np.testing.assert_allclose(turns, list(YAW.values()), atol=1e-9)
        assert record["angles_deg"]["01"] == pytest.approx(45.0) and record["angles_deg"]["12"] == pytest.approx(89.0)
        # the sizes follow their views: view k was given at the place order.index(k)
        assert [size[0] - 64 for size in record["sizes"]] == [key.index(str(view)) for view in range(3)]
    spread = orders.order_spread(by_order)
    assert spread["turn_deg"] == pytest.approx(0.0, abs=1e-6) and spread["focal"] == 0.0
    assert spread["registered_orders"] == 6


def test_the_spread_is_the_largest_turn_between_two_orders(monkeypatch, capture):
    from fingersplat3d.experiments import real

    monkeypatch.setattr(real, "measure_real", _fake_measure(wobble_deg=0.2, focal_step=10.0))
    by_order = orders.in_every_order(capture)
    spread = orders.order_spread(by_order)
    # "left" turns 0.2 degrees per view moved from its place: 0 in "012", 3 views moved in "120" and "201"
    assert spread["turn_deg"] == pytest.approx(0.6, abs=1e-6)
    assert spread["focal"] == pytest.approx(30.0 / np.median([r["focal"] for r in by_order.values()]))
    table = orders.orders_table({"c": by_order, "d": by_order})
    assert "| 0, 1, 2 |" in table and "| 2, 1, 0 |" in table
    assert "| c | 6 of 6 | 0.60 |" in table and "| **median** (range) | | **0.60** (0.60–0.60)" in table


def test_an_order_that_lost_a_view_is_left_out_of_the_spread(monkeypatch, capture):
    from fingersplat3d.experiments import real

    monkeypatch.setattr(real, "measure_real", _fake_measure(wobble_deg=0.2))
    by_order = orders.in_every_order(capture)
    for key in ("120", "201"):
        by_order[key]["registered"] = 2
    spread = orders.order_spread(by_order)
    assert spread["registered_orders"] == 4 and spread["turn_deg"] == pytest.approx(0.4, abs=1e-6)
    assert np.isnan(orders.order_spread({"012": by_order["012"]})["turn_deg"])
