"""What a fuse says of its registration: whether the views' shared skin closes a loop, and the warning where it does
not."""
from types import SimpleNamespace

import numpy as np
import pytest

from fingersplat3d.alignment_status import (NO_LOOP_WARNING, NO_TIP_SENSITIVITY_DEG, SKIN_LOOP_MIN_MATCHES, skin_loop,
                                            warn_without_loop)

ENOUGH = SKIN_LOOP_MIN_MATCHES


def _pair(a, b, matches, ok=True):
    return {"a": a, "b": b, "ok": ok, "reason": "", "matches": list(matches)}


SIDES = [_pair("l", "c", [400, 420]), _pair("c", "r", [380, 410])]


@pytest.mark.parametrize("records, closed", [
    (SIDES + [_pair("l", "r", [0, 89])], True),  # the real rig's side cameras, matched once guided
    (SIDES + [_pair("l", "r", [245, 0])], False),  # matched at the first guess only
    ([_pair("l", "c", [400]), _pair("c", "r", [410]), _pair("l", "r", [ENOUGH - 1])], False),
    ([_pair("l", "c", [400]), _pair("c", "r", [410]), _pair("l", "r", [ENOUGH])], True),
    ([_pair("l", "c", [400]), _pair("c", "r", [410]), _pair("l", "r", [300], ok=False)], False),  # refused: no loop
    ([_pair(a, b, [50]) for a, b in ("ab", "bc", "cd", "de")], False),  # a chain of five views
    ([_pair(a, b, [50]) for a, b in ("ab", "bc", "cd", "bd")], True),  # a loop of three in four
    ([_pair("l", "c", [])], False),
    ([], False),
])
def test_a_loop_needs_every_pair_of_a_cycle_matched_in_the_last_round(records, closed):
    assert skin_loop(records) is closed


def _alignment(views=3, probe=True, moves=1.3):
    return SimpleNamespace(aligned=[True] * views, focal_probe={"held": True} if probe else None,
                           turn_sensitivity_deg=None if moves is None else np.full((views, views), moves))


CHAIN = SIDES + [_pair("l", "r", [245, 0])]
LOOP = SIDES + [_pair("l", "r", [0, 89])]


@pytest.mark.parametrize("alignment, records, loop, warned", [
    (_alignment(), CHAIN, False, True),  # outer views sharing no skin, focal fitted
    (_alignment(), LOOP, True, False),
    (_alignment(probe=False), CHAIN, None, False),  # the focal given (no probe): the turns do not slide with it
    (_alignment(moves=NO_TIP_SENSITIVITY_DEG / 2), CHAIN, False, False),  # no turn follows the focal (orthographic)
    (_alignment(moves=None), CHAIN, False, True),
    (_alignment(views=2), CHAIN[:1], None, False),  # two views: their own warnings say it
])
def test_views_whose_skin_closes_no_loop_are_warned_with_the_focal_fitted(alignment, records, loop, warned):
    report, status = {"pairs": records, "warnings": []}, {}
    warn_without_loop(alignment, status, report)
    said = [w for w in report["warnings"] if w.startswith(NO_LOOP_WARNING)]
    assert bool(said) == warned and status.get("skin_loop") is loop
    if warned:
        assert "only l-c, c-r share" in said[0] and "--focal-px" in said[0]
