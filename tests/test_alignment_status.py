"""What a fuse says of its registration: whether the views' shared skin closes a loop, and the warning where it does
not; the warning that two views alone rest their turn on the section."""
from types import SimpleNamespace

import numpy as np
import pytest

from fingersplat3d.alignment_status import (NO_LOOP_WARNING, NO_TIP_SENSITIVITY_DEG, SKIN_LOOP_MIN_MATCHES,
                                            TWO_VIEWS_WARNING, skin_loop, warn_two_views, warn_without_loop)

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


def _two(aligned=(True, True), curvature=True):
    n = len(aligned)
    return SimpleNamespace(aligned=list(aligned), turn_uncertainty_deg=np.full((n, n), 0.1) if curvature else None)


@pytest.mark.parametrize("alignment, turn_warned, warned", [
    (_two(), False, True),  # two views, the focal given: nothing else speaks of their turn
    (_two(), True, False),  # another warning already did (curvature, focal, least turn)
    (_two((True, True, True)), False, False),  # three views hold their turns
    (_two((True, True, False)), False, True),  # a third view lost: the two left are two views alone
    (_two((True, False)), False, False),  # nothing was aligned to anything
    (_two(curvature=False), False, False),  # a rig's poses (no curvature reported)
])
def test_two_views_alone_are_said_to_rest_on_the_section(alignment, turn_warned, warned):
    report = {"warnings": []}
    warn_two_views(alignment, report, turn_warned)
    said = [w for w in report["warnings"] if w.startswith(TWO_VIEWS_WARNING)]
    assert len(said) == int(warned)
    if warned:
        assert "third view" in said[0] and "--focal-px" not in said[0]
