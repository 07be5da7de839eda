"""What a fuse says of its registration: which views were registered, and the warnings a user needs to tell a 1°
capture from a 15° one without ground truth (``report.json``'s ``alignment`` and ``warnings``; each warning said on
stderr as well).

Each warning stands on a figure the fit reports: the alignment's residual, each pair's turn uncertainty from the fit's
curvature and its sensitivity to the focal (the focal probe), whether a view's outline closes at the fingertip,
whether the views' shared skin closes a loop, and the least turn the silhouettes allow. The thresholds and the
measurements behind them are in docs/measurements.md ("How sure it is"). Pure numpy on the alignment's own numbers.
"""
from __future__ import annotations

import sys
from typing import Sequence

import numpy as np

from .align.solve.global_opt import PIVOT_MIN_VIEWS, GlobalAlignment
from .scene import Capture
from .segment.silhouette import TIP_BASES

__all__ = ["MAX_RESIDUAL_PX", "MAX_TURN_UNCERTAINTY_DEG", "MAX_TURN_SENSITIVITY_DEG", "MAX_TURN_SHORTFALL_DEG", "AT_BOUND_DEG",
           "SKIN_LOOP_MIN_MATCHES", "NO_LOOP_WARNING", "NO_TIP_WARNING", "NO_TIP_SENSITIVITY_DEG", "alignment_status",
           "TWO_VIEWS_WARNING", "skin_loop", "warn", "warn_two_views", "warn_without_loop", "warn_without_tip",
           "SIDES_CUT_WARNING", "TIGHT_CROP_SHARE", "warn_sides_cut"]

MAX_RESIDUAL_PX = 3.0  # a global alignment residual above this (pixels across the ridges) means wrong cameras
MAX_TURN_UNCERTAINTY_DEG = 0.2  # a pair turn whose curvature-based sigma exceeds this is warned about (docs/measurements.md)
MAX_TURN_SENSITIVITY_DEG = 1.5  # a pair turn that moves more than this under the focal probe is warned about
MAX_TURN_SHORTFALL_DEG = 5.0  # a pair turned this much less than its silhouettes allow is warned about (align/width_check.py)
AT_BOUND_DEG = 1.0  # two views turned less than this beyond their least turn are held there by the bound, not the photos
SKIN_LOOP_MIN_MATCHES = 30
"""A pair closes a loop of views with this many skin matches or more in the registration's last round
(:func:`skin_loop`). Measured (docs/measurements.md, stop 99): the real rig's side cameras, 90 degrees apart, share
50-100 once the first alignment guides them; outer views 114 degrees apart share none."""


def warn(report: dict, message: str) -> None:
    """``message`` added to the report's warnings and said on stderr."""
    report.setdefault("warnings", []).append(message)
    print(f"fs3d fuse: warning: {message}", file=sys.stderr)


def alignment_status(capture: Capture, pairs: list[tuple[int, int]], alignment: GlobalAlignment, report: dict) -> dict:
    """Whether the views were registered; said on stderr and in the report when they were not."""
    names = capture.names
    missing = [names[v] for v in range(len(capture)) if not alignment.aligned[v]]
    monocular = len(capture) == 1 or not pairs
    status = {"ok": True, "mode": "monocular" if monocular else "multi-view"}
    if monocular:
        return status
    if missing:
        reasons = "; ".join(f"{p['a']}-{p['b']}: {p['reason']}" for p in report.get("pairs", []) if not p["ok"] and p["reason"])
        status.update(ok=False, not_registered=missing, reason=reasons)
        warn(report, f"view(s) {', '.join(missing)} could not be registered with the others ({reasons}); "
                     "their depth comes from the pointmap alone and they are left out of the fused cloud")
    elif np.isfinite(alignment.residual_px) and alignment.residual_px > MAX_RESIDUAL_PX:
        status.update(ok=False, reason=f"global alignment residual {alignment.residual_px:.1f} px")
        warn(report, f"global alignment residual is {alignment.residual_px:.1f} px (more than {MAX_RESIDUAL_PX:g} px): "
                     "the cameras are probably wrong")
    said = len(report.get("warnings", []))  # the warnings about the turns follow
    if alignment.turn_uncertainty_deg is not None:
        status["turn_uncertainty_deg"] = _per_pair(names, alignment.turn_uncertainty_deg, 3)
        loose = {pair: value for pair, value in status["turn_uncertainty_deg"].items() if value > MAX_TURN_UNCERTAINTY_DEG}
        if loose:
            settings = report.get("settings", {})
            focal_fitted = (sum(alignment.aligned) == 2 and settings.get("focal_px") is None
                            and settings.get("view_focals_px") is None and not report.get("exif_focal", {}).get("used"))
            warn(report, "the turn between " + ", ".join(f"{pair} (±{value:.1f}°)" for pair, value in loose.items())
                 + f" is poorly determined: its uncertainty from the fit's curvature is above {MAX_TURN_UNCERTAINTY_DEG:g}° "
                 "(well-determined pairs read about 0.1°, and the real error runs about ten times this figure)"
                 + ("; two views cannot fix the focal, and their turn follows it (5-17° off on real photos): give the "
                    "cameras' focal with --focal-px if it is known (photos whose EXIF records it give it themselves), or add a "
                    "view" if focal_fitted else ""))
    if alignment.turn_sensitivity_deg is not None:
        status["turn_sensitivity_deg"] = _per_pair(names, alignment.turn_sensitivity_deg, 2)
        loose = {pair: value for pair, value in status["turn_sensitivity_deg"].items() if value > MAX_TURN_SENSITIVITY_DEG}
        probe = alignment.focal_probe
        if probe is not None:
            status["focal_probe"] = probe
        if probe is not None and not probe["held"] and sum(alignment.aligned) >= 3:
            moved = max(status["turn_sensitivity_deg"].items(), key=lambda item: item[1])
            warn(report, "the photos do not hold the focal: the fit slides toward a longer, nearly orthographic one, and a "
                         f"focal {1 / probe['shorter_share']:.1f} times shorter fits about as well (the loss "
                         f"{100 * probe['shorter_loss_rise']:+.0f} %), with the turn between {moved[0]} {moved[1]:.1f}° "
                         "away; seen on crops without the fingertip whose outer views share no skin (real ones: turns up "
                         "to 19° off)" + _short_end_taken(probe)
                         + ": the cameras' focal (--focal-px, --rig, or photos whose EXIF records it) fixes it")
        elif loose:
            warn(report, "the turn between " + ", ".join(f"{pair} (moves {value:.1f}°)" for pair, value in loose.items())
                 + " follows the focal, which the photos fix only loosely: with the focal held 10 % longer than fitted, "
                 f"it moves more than {MAX_TURN_SENSITIVITY_DEG:g}° (real captures: errors up to three times that move)"
                 + _short_end_taken(probe) + "; the cameras' focal (--focal-px, --rig, or photos whose EXIF records it) or more views fix it")
    warn_without_tip(alignment, report)
    warn_sides_cut(alignment, report)
    warn_without_loop(alignment, status, report)
    _check_turns_against_widths(capture, alignment, status, report)
    warn_two_views(alignment, report, turn_warned=len(report.get("warnings", [])) > said)
    return status


def skin_loop(records: Sequence[dict], least: int = SKIN_LOOP_MIN_MATCHES) -> bool:
    """Whether the registered pairs (``report.json``'s ``pairs``: ``a``, ``b``, ``ok``, ``matches`` per round) close a
    loop of views on the skin they share: some cycle of views each of whose pairs matched ``least`` points or more in
    its last round. Without one, each pair's turn rests on that pair alone, as two views' does."""
    parent: dict[str, str] = {}

    def root_of(name: str) -> str:
        while parent.setdefault(name, name) != name:
            name = parent[name]
        return name

    for record in records:
        if not _shares_skin(record, least):
            continue
        a, b = root_of(record["a"]), root_of(record["b"])
        if a == b:
            return True
        parent[a] = b
    return False


def _shares_skin(record: dict, least: int) -> bool:
    """Whether a pair of ``report.json``'s ``pairs`` was registered with ``least`` skin matches or more in its last
    round."""
    return bool(record.get("ok")) and bool(record.get("matches")) and record["matches"][-1] >= least


def warn_without_loop(alignment: GlobalAlignment, status: dict, report: dict) -> None:
    """A warning where three views or more were aligned with the focal fitted (its probe ran) and their shared skin
    closes no loop (:func:`skin_loop`): outer views too far apart to share skin leave each pair's turn to that pair's
    skin, the pointmaps' shape and the focal, as with two views, and the probes above can read quiet (another make's
    fingers at +-57 degrees, 45 mm away: 3.6 degrees off with the turns' curvature at 0.06 and their move under the
    focal probe 1.3; docs/measurements.md, stop 99). Not where no turn moves by :data:`NO_TIP_SENSITIVITY_DEG` with
    the focal probed (nearly orthographic cameras, whose turns the skin holds whatever the focal: another group's
    renders)."""
    if sum(alignment.aligned) < PIVOT_MIN_VIEWS or alignment.focal_probe is None:
        return
    status["skin_loop"] = skin_loop(report.get("pairs", []))
    if not status["skin_loop"] and not _turns_steady(alignment):
        shared = [f"{r['a']}-{r['b']}" for r in report.get("pairs", []) if _shares_skin(r, SKIN_LOOP_MIN_MATCHES)]
        warn(report, f"{NO_LOOP_WARNING} (only " + (", ".join(shared) or "no pair") + " share matched skin): "
                     "each turn rests on its own pair's skin and on the pointmaps' shape, and follows the focal, as "
                     "two views' do (another make's fingers 114° apart: up to 3.6° off with every other check "
                     "quiet); the cameras' focal (--focal-px, --rig, or photos whose EXIF records it) or views near "
                     "enough that each shares skin with two others fix it")


TWO_VIEWS_WARNING = "two views alone"
"""How the warning of :func:`warn_two_views` begins."""


def warn_two_views(alignment: GlobalAlignment, report: dict, turn_warned: bool) -> None:
    """A warning where exactly two views were aligned without a rig and no other warning spoke of their turn (the
    focal given, or taken from EXIF, and the fit's curvature quiet): where their skin does not overlap, the turn rests
    on the pointmaps' section of the finger, which two photos cannot check, and no figure of the fit tells a pair that
    turned off from one that did not (docs/measurements.md, stop 100: the fit's curvature and a softer solve's move
    read alike on real pairs within 1 degree and 2-5 degrees off). So it is said of every such pair, with what it costs
    on real fingers. Only where the fit reports its turns' curvature (``turn_uncertainty_deg``: the `prior` pointmaps'
    registration without a rig; a rig's poses are its own)."""
    if turn_warned or sum(alignment.aligned) != 2 or not _fitted_without_rig(alignment):
        return
    warn(report, f"{TWO_VIEWS_WARNING}: where their skin does not overlap, the turn between them rests on the "
                 "pointmaps' guess of the finger's section, which two photos cannot check, and the fit cannot tell how "
                 "far off it is (real fingers 45° apart with the focal given: median 2°, up to 4.4°, where three "
                 "views hold the same cameras within 1°; fingers whose section the guess fits: under 1°): a third "
                 "view fixes it")


NO_TIP_WARNING = "no view shows the fingertip"
"""How the warning of :func:`warn_without_tip` begins."""
NO_LOOP_WARNING = "the views' shared skin closes no loop"
"""How the warning of :func:`warn_without_loop` begins."""


NO_TIP_SENSITIVITY_DEG = 0.3
""":func:`warn_without_tip`: turns that move less than this under the focal probe (10 % longer) do not follow the focal,
and a capture without a tip is not warned about. Measured (docs/measurements.md, stop 79): the real crops' most
sensitive pairs move 0.8-2.8 degrees, another group's cropped renders (within 0.3 degrees of their rolls) 0.01 at most."""


def _short_end_taken(probe: dict | None) -> str:
    """The warnings' clause for a focal taken at the short end of its valley (``focal_probe.taken_share``), or ""."""
    taken = (probe or {}).get("taken_share")
    return f"; the focal is taken at the short end of what fits, {taken:.2f} of where the fit slid" if taken else ""

def warn_without_tip(alignment: GlobalAlignment, report: dict) -> None:
    """A warning where three views or more were aligned without a rig and no registered view's outline closes at the
    tip (each cut by the frame at both ends): what holds the turns is then the skin the views share alone. Real crops
    without the tip come out 1-5 degrees off with their photos seeming to hold the focal (docs/measurements.md, stop
    78), so the probes above do not catch them all; and 2-3 degrees off at the median (up to 7) with the rig's focal
    given (stop 99), where no probe runs: they are warned too, with the remedy a known focal cannot give. With the
    focal fitted, not where the focal probe found every turn steady whatever the focal (:data:`NO_TIP_SENSITIVITY_DEG`):
    nearly orthographic crops, whose turns the shared skin holds alone. Not with a rig (its poses are its own: no
    curvature is reported then)."""
    placed = _placed_tips(alignment, report)
    focal_given = alignment.focal_probe is None
    if focal_given and not _fitted_without_rig(alignment):
        return
    if len(placed) < 3 or any(tip is None for tip in placed):
        return
    if not focal_given and _turns_steady(alignment):
        return
    if all(tip["why"] != TIP_BASES["outline"] for tip in placed):
        said = (("the turns rest on the skin the views share alone, and the focal given does not hold the finger's "
                 "tilt (real crops without a tip with the rig's focal given: turns 2-3° off, up to 7°); a rig (--rig) "
                 "or photos that show the fingertip fix it") if focal_given else
                ("the turns and the focal rest on the skin the views share alone (real crops without a tip: turns "
                 "1-5° off, the focal up to 50 % off); the cameras' focal (--focal-px, --rig, or photos whose EXIF "
                 "records it) helps"))
        warn(report, f"{NO_TIP_WARNING} (the frame cuts every view at both ends): {said}")


SIDES_CUT_WARNING = "the frame cuts every view along the finger's sides"
"""How the warning of :func:`warn_sides_cut` begins."""
TIGHT_CROP_SHARE = 0.5
""":func:`warn_sides_cut`: a view the frame cuts along a side over this share of its stations along the finger (the
report's ``registration.tip[view].sides_cut``) shows no outline of the finger there. Real dev views cropped to 0.8 of
the finger's width: 0.8-1.0; whole real and synthetic views: 0 (docs/measurements.md, stop 104)."""


def warn_sides_cut(alignment: GlobalAlignment, report: dict) -> None:
    """A warning where two views or more were aligned without a rig and the frame cuts every registered one along the
    finger's sides (:data:`TIGHT_CROP_SHARE`): a tight crop or a close-up the finger fills across its width. No view
    shows the finger's width there, so the prior's section, and the turns the fit finds through it, are a guess: real
    dev captures cut so came out 4-33 degrees off at their worst pair (median; up to 58) with the focal fitted or
    given, four of nine with the focal given with no other warning (docs/measurements.md, stop 104). With the focal
    given too: it does not fix the section."""
    placed = _placed_tips(alignment, report)
    if not _fitted_without_rig(alignment) or len(placed) < 2 or any(tip is None for tip in placed):
        return
    if all(tip.get("sides_cut", 0.0) >= TIGHT_CROP_SHARE for tip in placed):
        warn(report, f"{SIDES_CUT_WARNING} (a tight crop or a close-up the finger fills across its width): no "
                     "view shows its width there, so its section is the prior's guess and the turns rest on it "
                     "(real captures cut so: the worst pair 4-33° off at the median, up to 58°, the focal fitted or "
                     "given); photos that show the finger's whole width fix it")


def _placed_tips(alignment: GlobalAlignment, report: dict) -> list[dict | None]:
    """The report's ``registration.tip`` entry of each registered view (None where it has none)."""
    tips = report.get("registration", {}).get("tip", {})
    return [tips.get(name) for name, aligned in zip(report.get("views", []), alignment.aligned) if aligned]


def _fitted_without_rig(alignment: GlobalAlignment) -> bool:
    """Whether the turns were fitted to the photos' matches on the `prior` pointmaps, with no rig holding the poses:
    only such a fit reports its turns' curvature (``turn_uncertainty_deg``; None with a rig or the dust3r backend)."""
    return alignment.turn_uncertainty_deg is not None


def _turns_steady(alignment: GlobalAlignment) -> bool:
    """Whether the focal probe moved no turn by :data:`NO_TIP_SENSITIVITY_DEG` or more: nearly orthographic cameras,
    whose turns the shared skin holds whatever the focal (the no-tip and no-loop warnings stand aside for them)."""
    moves = alignment.turn_sensitivity_deg
    return moves is not None and bool(np.isfinite(moves).any()) and np.nanmax(moves) < NO_TIP_SENSITIVITY_DEG


def _per_pair(names: Sequence[str], values: np.ndarray, digits: int) -> dict[str, float]:
    """``{"a-b": value}`` for every view pair with a finite entry of the ``[N, N]`` table ``values``."""
    return {f"{names[a]}-{names[b]}": round(float(values[a, b]), digits)
            for a in range(len(names)) for b in range(a + 1, len(names)) if np.isfinite(values[a, b])}


def _check_turns_against_widths(capture: Capture, alignment: GlobalAlignment, status: dict, report: dict) -> None:
    """Each aligned pair's least turn allowed by the silhouettes (:mod:`~fingersplat3d.align.width_check`); a warning
    where the solved turn falls short of it."""
    from .align.width_check import least_turns_deg
    from .eval.poses import view_turn_deg

    names, placed = capture.names, [v for v in range(len(capture)) if alignment.aligned[v]]
    if len(placed) < 2:
        return
    bounds = least_turns_deg([view.mask for view in capture.views], alignment.depths, alignment.focals)
    least, short, held = {}, [], {}
    for i, a in enumerate(placed):
        for b in placed[i + 1:]:
            if not np.isfinite(bounds[a, b]):
                continue
            pair = f"{names[a]}-{names[b]}"
            least[pair] = round(float(bounds[a, b]), 1)
            turn = view_turn_deg(alignment.cam_to_world[a][:3, :3].T, alignment.cam_to_world[b][:3, :3].T)[0]
            if bounds[a, b] - turn > MAX_TURN_SHORTFALL_DEG:
                short.append(f"{pair} ({turn:.0f}°, at least {bounds[a, b]:.0f}°)")
            elif len(placed) < PIVOT_MIN_VIEWS and turn - bounds[a, b] < AT_BOUND_DEG:  # the hinges' own condition
                held[pair] = turn
    status["turn_at_least_deg"] = least
    if held:  # the hinge rows of two views (GlobalAlignConfig.two_view_turn_bound_weight) hold it: its curvature says nothing
        status["turn_held_at_bound"] = list(held)
        turns = ", ".join(f"{pair} ({turn:.0f}°)" for pair, turn in held.items())
        warn(report, f"the turn between {turns} is held at the least turn the views' silhouette widths allow: the photos "
             "alone would turn it less, against the prior's rounder section, and it may be larger still (another "
             "group's flat finger, measured: 1.7-9.4° short); a third view fixes it")
    if short:
        warn(report, "the turn between " + ", ".join(short) + " is smaller than the views' silhouette widths allow "
             "if the widest view faces the finger's widest extent (turning about a finger cannot narrow it faster "
             "than cos(turn)): either the turn is too small, or that view is oblique to a flat finger (then the bound "
             "does not hold)")
