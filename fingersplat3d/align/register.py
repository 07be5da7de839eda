"""Register the views of one finger from their photos: correspondences, pair similarities, global alignment.

The loop (all numbers scale with the measured ridge period):

1. **first guess of each pair** (``matcher='surface'``, the default): both views' ridge textures
   unwrapped on their cylinder charts, their shift voted by patches
   (:mod:`~fingersplat3d.align.correspond.chart_shift`), and guided matching through the charts with a
   search of two ridge periods (:mod:`~fingersplat3d.align.correspond.guided`), from a grid on each view of the pair
   (``first_guess_both_ways``), grown through the charts corrected by those matches; the classic matchers
   (``minutiae``, ``sift``, ...) of :mod:`~fingersplat3d.align.correspond.features` can stand in for it. From
   ``many_views`` views on, a pair whose views are each registered with ``first_guesses_per_view`` others already is
   left to the guided rounds (step 4);
2. **verification**: a robust fundamental matrix (:mod:`~fingersplat3d.align.correspond.epipolar`); a
   pair is registered when at least ``min_matches`` correspondences agree with it, and its
   similarity ``b_to_a`` comes from the two pointmaps at the matched pixels
   (:func:`~fingersplat3d.align.solve.pairwise.register_pair`);
3. **global alignment** of all registered pairs from their maximum spanning tree
   (:func:`~fingersplat3d.align.solve.global_opt.global_align`); a view no decisive vote placed is then tried at
   its undecided votes' best peaks, each placed and matched again through the model it makes, and placed by the
   peak its views agree with (``RegistrationConfig.undecided_peaks``);
4. **guided rounds**: every pair of aligned views is matched again, predicted through the 3D
   model (:class:`~fingersplat3d.align.correspond.model_predictor.ModelPredictor`) with a search of
   ``guided_search`` periods (pairs that had no first guess, such as views 90 degrees apart, get
   one now), from a grid on each view of the pair (``guided_both_ways``: the result does not depend on the
   photos' order), verified, and the alignment is refined from where it stands. The model's error
   shrinks each round, so the matches come closer to the truth and cover more of the overlap. A pair must
   also **agree**: ``min_agreement`` of the points the model puts on both views must match. Views of two
   fingers pass a chart vote and an epipolar check by chance now and then, never this; a view that only
   disagreeing pairs placed is placed no longer. After the first round, a view whose every pair agrees far below the
   capture's best pair is placed again from its votes' peaks as in step 3 (``weak_agreement_share``);
5. **pointmaps redrawn at the fitted focal and the finger's tilt** (with a ``redraw`` callable): the prior drew each
   view's relief through a guessed pinhole, and where the fitted focal is far from that guess (three views or more)
   the depth fields had to bend the surface to the fitted perspective against their smoothness, which held the focal
   up (real rig: fitted focal x 2.2 under the guess, spread 22 % over nine captures). And it swept its sections
   along a level axis: where the registered cameras put the finger's axis out of a photo's plane by
   ``redraw_tilt_deg`` or more (:mod:`.axis_tilt`, three views or more), each view is drawn tilted by it. The relief
   is drawn again and the last round solved once more from where it stands.

A pair that cannot be registered is not an error: its record says why, and the views that no
registered pair reaches stay unaligned (the caller decides what that means). Pure numpy/torch/OpenCV.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Callable, Sequence

import numpy as np

from ..device import per_item
from ..pointmaps.base import Pointmap
from ..scene import View
from ..segment.side_cut import SIDE_CUT_SHARE, capture_frames, sides_cut_share
from ..segment.silhouette import SIDE_CUT_WIDTHS, TIP_BASES, capture_axes, capture_finger_axes, silhouette_frame
from .axis_tilt import tilt_deg, view_tilts
from .correspond.chart import CylinderChart
from .correspond.chart_growth import grow_first_guess
from .correspond.chart_shift import (RIVAL_TURN_DEG, ChartPredictor, ChartShift, chart_shift_candidates,
                                     estimate_chart_shift, vote_area)
from .correspond.contours import contour_correspondences
from .correspond.epipolar import fundamental_inliers
from .correspond.guided import GuidedMatches, RidgeMaps, match_guided
from .correspond.model_predictor import ModelPredictor
from .correspond.texture import as_gray, estimate_ridge_period, ridge_texture
from .registration_config import CONTOUR_MIN_VIEWS, CONTOUR_MIN_VIEWS_FOCAL_HELD, MATCHERS, RegistrationConfig
from .solve.alignment_problem import median_depth
from .solve.global_opt import (PIVOT_MIN_VIEWS, GlobalAlignment, PairCorrespondences, global_align, reached,
                               spanning_tree, turn_uncertainty_of)
from .solve.photometric import refine_alignment
from .solve.rig import Rig, rig_align
from .solve.sensitivity import focal_probe, short_end
from .transfer import distinct_viewpoints
from .width_check import least_turns_deg

__all__ = ["RegistrationConfig", "Registration", "register_views", "distinct_viewpoints", "weak_view", "MATCHERS"]


@dataclass(frozen=True, eq=False)
class Registration:
    """The aligned views and what happened to each pair."""

    alignment: GlobalAlignment
    pairs: list[dict]
    """Per pair ``a``, ``b`` (names), ``ok``, ``reason``, the first guess (``turn_deg`` and its
    votes for ``surface``), and per round the verified matches."""
    period_px: float
    rounds: int
    correspondences: list[PairCorrespondences] = field(default_factory=list)
    """The verified correspondences the final alignment was fitted to (what a rig calibration pools)."""
    contours: list[PairCorrespondences] = field(default_factory=list)
    """The silhouette contours it was fitted to beside them (:mod:`~fingersplat3d.align.correspond.contours`; empty
    when none joined): a rig calibration pools them too."""
    tips: list[dict] = field(default_factory=list)
    """Per view, the end taken for the fingertip: ``side`` (of the image) and ``why`` (in words)."""
    photometric: dict = field(default_factory=dict)
    """The dense photometric refinement's record (texture agreement before and after, samples, seconds); empty when off."""
    pointmaps: list[Pointmap] = field(default_factory=list)
    """The pointmaps the final alignment stands on (redrawn at the fitted focal, or the ones given)."""
    redrawn_at_px: float | None = None
    """The focal the pointmaps were redrawn at (working pixels); None when they were not."""
    axis_tilts_deg: list[float | None] = field(default_factory=list)
    """Per view, how far the registered finger's axis runs out of the photo's plane (degrees; None: not measured,
    :mod:`.axis_tilt`), and whether the pointmaps were redrawn with it (``tilted``)."""
    tilted: bool = False
    turn_changes_deg: list[float] = field(default_factory=list)
    """Each guided round's largest change of a view pair's turn (degrees): for two views with the focal held, the rounds
    go on past ``guided_rounds`` while it is above ``RegistrationConfig.settled_turn_deg``."""


@dataclass(frozen=True, eq=False)
class _Prepared:
    textures: list[np.ndarray]
    masks: list[np.ndarray]
    grays: list[np.ndarray]
    period: float
    memo: dict = field(default_factory=dict)  # what is made once on first use (the ridge areas' unwrapped textures)

    @cached_property
    def outlines(self) -> list:
        """Each mask's :func:`~fingersplat3d.segment.silhouette.silhouette_frame`, made once (the contours of every
        guided round and view pair read them)."""
        return [silhouette_frame(mask, hint=hint) for mask, hint in zip(self.masks, capture_axes(self.masks))]

    def charts(self, frames) -> tuple[list[CylinderChart], list]:
        """Each view's cylinder chart on its silhouette frame (``frames``, one per view) and its ridge texture unwrapped
        on it, an eighth of a ridge period a step: what the first guesses' votes compare."""
        charts = [CylinderChart.from_frame(frame) for frame in frames]
        step = max(1.0, self.period / 8.0)
        return charts, per_item(lambda v: charts[v].unwrap(self.textures[v], self.masks[v], step), range(len(charts)))

    def ridge_unwrapped(self, charts: list[CylinderChart], unwrapped: list) -> list | None:
        """The textures unwrapped on their ridge areas alone where those are a small part of the finger in view
        (:func:`~.correspond.chart_shift.vote_area`; the other views as ``unwrapped`` has them), for the vote that comes
        before the whole fingers' and for its peaks where a pair stays undecided; None when every view votes whole.
        Made once."""
        if "ridges" not in self.memo:
            areas = per_item(vote_area, self.masks)
            whole = [(area == mask).all() for area, mask in zip(areas, self.masks)]
            self.memo["ridges"] = None if all(whole) else [
                flat if same else chart.unwrap(texture, area, flat.step)
                for chart, flat, texture, area, same in zip(charts, unwrapped, self.textures, areas, whole)]
        return self.memo["ridges"]

    def ridge_pair(self, charts: list[CylinderChart], unwrapped: list, a: int, b: int) -> tuple | None:
        """Views ``a`` and ``b`` unwrapped for a vote on their ridge areas (:meth:`ridge_unwrapped`), or None where
        neither's is a small part of its finger (their vote on the ridges would be the whole fingers')."""
        ridges = self.ridge_unwrapped(charts, unwrapped)
        if ridges is None or (ridges[a] is unwrapped[a] and ridges[b] is unwrapped[b]):
            return None
        return ridges[a], ridges[b]

    @cached_property
    def maps(self) -> list[RidgeMaps]:
        """Each view as guided matching reads it, with its derived maps kept across pairs and rounds."""
        return [RidgeMaps(texture, mask) for texture, mask in zip(self.textures, self.masks)]


def _prepare(views: Sequence[View], period_px: float | None = None) -> _Prepared:
    grays = [as_gray(view.image, f"view {view.name!r}") for view in views]
    masks = [np.asarray(view.mask, bool) for view in views]
    period = float(period_px) if period_px else float(np.median([estimate_ridge_period(gray, mask)
                                                                 for gray, mask in zip(grays, masks)]))
    textures = per_item(lambda v: ridge_texture(grays[v], masks[v], period), range(len(views)))
    return _Prepared(textures, masks, grays, period)


def _verified(matches: GuidedMatches, period: float, config: RegistrationConfig) -> GuidedMatches:
    if len(matches) < config.min_matches:
        return matches.subset(np.zeros(len(matches), bool))
    _, inliers = fundamental_inliers(matches.uv_a, matches.uv_b, max(1.0, config.epipolar_px * period))
    return matches.subset(inliers)


def _surface_guess(prepared: _Prepared, a: int, b: int, charts, unwrapped, config: RegistrationConfig, record: dict) -> GuidedMatches:
    """A pair's first guess from the vote of its unwrapped textures: on the ridge areas alone where either view's is a
    small part of its finger in view (:meth:`_Prepared.ridge_unwrapped`) and that vote is decisive, else on the whole
    fingers."""
    shift = None
    ridges = prepared.ridge_pair(charts, unwrapped, a, b)
    if ridges is not None:
        shift = estimate_chart_shift(*ridges, prepared.period)
        if shift is not None and shift.decisive:
            record["turn_voted_on"] = "ridge area"
        else:
            shift = None
    shift = shift or estimate_chart_shift(unwrapped[a], unwrapped[b], prepared.period)
    if shift is None:
        record["reason"] = "no patch of the unwrapped ridge textures correlates between the views"
        return GuidedMatches.empty()
    record.update(turn_deg=round(float(np.degrees(shift.turn)), 2), turn_votes=shift.support, turn_ratio=round(shift.ratio, 2))
    if not shift.decisive:
        record["reason"] = (f"the unwrapped ridge textures agree on no single turn ({shift.support} of {shift.patches} "
                            f"patches at the best one, {shift.ratio:.2f} times the runner-up)")
        return GuidedMatches.empty()
    return _chart_guess(prepared, a, b, charts, shift, config)


def _chart_guess(prepared: _Prepared, a: int, b: int, charts, shift, config: RegistrationConfig,
                 zoom: float = 1.0) -> GuidedMatches:
    """A pair's first-guess matches: predicted through both charts shifted by ``shift`` (b seen ``zoom`` times as
    large), searched ``first_search`` ridge periods around, then grown through the charts corrected by those matches
    (:mod:`~fingersplat3d.align.correspond.chart_growth`, ``RegistrationConfig.grow_first_guess``)."""
    chart = ChartPredictor(charts[a], charts[b], shift, zoom)
    ways = (chart,)
    if config.first_guess_both_ways:  # b's grid read through the inverse shift: sigma_a = (sigma_b - zoom d) / zoom
        back = ChartShift(-shift.turn, -zoom * shift.d_sigma, shift.support, shift.patches, shift.ratio)
        ways += (ChartPredictor(charts[b], charts[a], back, 1.0 / zoom),)

    def match(*predictors, skip: GuidedMatches | None = None) -> GuidedMatches:
        return _matched(prepared, a, b, predictors, config.first_search * prepared.period, skip)

    first = match(*ways)
    if not config.grow_first_guess:
        return first
    grown, _ = grow_first_guess(ways, first, match, lambda m: _verified(m, prepared.period, config), config.min_matches,
                                0.1 * prepared.period)
    return grown


def _matched(prepared: _Prepared, a: int, b: int, predictors, search: float,
             skip: GuidedMatches | None = None) -> GuidedMatches:
    """The pair matched through ``predictors``, searched ``search`` px around: a to b alone (one predictor, a grid on a
    a ridge period apart), or both ways (two, a to b and b to a: a grid on each view sqrt(2) periods apart, as many
    points as one grid a period apart), read from a to b. ``skip``: matches held already, whose grid points each way
    leaves out."""
    stride = None if len(predictors) == 1 else np.sqrt(2.0) * prepared.period
    held = (None, None) if skip is None else (skip.uv_a, skip.uv_b)
    found = [match_guided(prepared.maps[x], prepared.maps[y], predictor, prepared.period, search, stride=stride,
                          skip=points) for predictor, (x, y), points in zip(predictors, ((a, b), (b, a)), held)]
    return found[0] if len(found) == 1 else found[0].joined(found[1].swapped())


def turn_change_deg(old: GlobalAlignment, new: GlobalAlignment) -> float:
    """The largest angle (degrees) by which the relative rotation of two views aligned in both ``old`` and ``new``
    changed between them; 0 with fewer than two such views."""
    import torch

    from ..rotations import rotation_angle

    both = [v for v in range(len(new.aligned)) if old.aligned[v] and new.aligned[v]]
    if len(both) < 2:
        return 0.0
    rotations = [torch.as_tensor(np.stack([np.asarray(al.world_to_cam[v])[:3, :3] for v in both]), dtype=torch.float64)
                 for al in (old, new)]
    relative = [r[None, :] @ r[:, None].transpose(-1, -2) for r in rotations]  # [b, a]: view b from view a
    return float(np.degrees(rotation_angle(relative[0], relative[1]).max().item()))


def _through_model(prepared: _Prepared, alignment: GlobalAlignment, a: int, b: int,
                   config: RegistrationConfig) -> tuple[GuidedMatches, GuidedMatches, float]:
    """A pair matched through the 3D model of ``alignment``: the matches, the verified ones, and their agreement (the
    verified share of the points searched; 0 where none was)."""
    ways = ((a, b), (b, a)) if config.guided_both_ways else ((a, b),)
    matches = _matched(prepared, a, b, [ModelPredictor.from_alignment(alignment, x, y) for x, y in ways],
                       config.guided_search * prepared.period)
    verified = _verified(matches, prepared.period, config)
    return matches, verified, len(verified) / max(matches.tried, 1)


def _similar_pair(pointmaps, a: int, b: int, verified: GuidedMatches, config: RegistrationConfig,
                  rng) -> tuple[PairCorrespondences | None, str]:
    """The pair's correspondences with the similarity its two pointmaps fit at the ``verified`` matches, or None and
    why not."""
    from .correspond.features import Matches
    from .solve.pairwise import register_pair

    similarity = register_pair(pointmaps[a], pointmaps[b], Matches(verified.uv_a, verified.uv_b, verified.score,
                                                                   config.matcher), rng=rng)
    if not similarity.ok:
        return None, similarity.reason
    return _pair_correspondences(a, b, verified, similarity.matrix), ""


def _classic_guess(prepared: _Prepared, a: int, b: int, config: RegistrationConfig) -> GuidedMatches:
    from .correspond.features import match_views

    matches = match_views(prepared.grays[a], prepared.masks[a], prepared.grays[b], prepared.masks[b],
                          method=config.matcher, densify=config.matcher == "minutiae", period_px=prepared.period)
    identity = np.broadcast_to(np.eye(2), (len(matches), 2, 2)).copy()
    return GuidedMatches(matches.uv_a, matches.uv_b, matches.score, identity, identity.copy())


def _contours(alignment, prepared: _Prepared, config: RegistrationConfig, on_rig: bool = False) -> list[PairCorrespondences]:
    """Every aligned view's surface against every other aligned view's outline
    (:mod:`~fingersplat3d.align.correspond.contours`), as one-way correspondences. ``on_rig``: a rig holds the cameras
    and their focal, so two views take them as with a focal held."""
    placed = [v for v, ok in enumerate(alignment.aligned) if ok]
    held = on_rig or not config.global_align.optimize_focal
    least = CONTOUR_MIN_VIEWS_FOCAL_HELD if held else CONTOUR_MIN_VIEWS
    if config.contour_weight <= 0 or distinct_viewpoints(alignment.world_to_cam, placed) < least:
        return []
    found = []
    for a in placed:
        for b in placed:
            if a == b:
                continue
            uv_a, uv_b, information = contour_correspondences(alignment, prepared.masks, a, b, prepared.period,
                                                              outline=prepared.outlines[b])
            if len(uv_a):
                found.append(PairCorrespondences(a, b, uv_a, uv_b, np.full(len(uv_a), config.contour_weight), np.eye(4),
                                                 np.zeros_like(information), information))
    return found


def _pair_correspondences(a: int, b: int, matches: GuidedMatches, b_to_a: np.ndarray, cap: int = 0) -> PairCorrespondences:
    """The pair's correspondences for the alignment; with ``cap`` > 0 at most that many, evenly along the grids they
    were matched from (each in raster order: a's, then b's), each weighing as much more as the pair's total weight
    stays the same."""
    weight = np.clip(matches.score, 1e-3, 1.0)
    if 0 < cap < len(matches):
        keep = np.unique(np.linspace(0, len(matches) - 1, cap).round().astype(int))
        weight = weight[keep] * (weight.sum() / weight[keep].sum())
        matches = matches.subset(keep)
    return PairCorrespondences(a, b, matches.uv_a, matches.uv_b, weight, b_to_a, matches.information_a,
                               matches.information_b)


def register_views(views: Sequence[View], pointmaps: Sequence[Pointmap], config: RegistrationConfig = RegistrationConfig(),
                   pairs: Sequence[tuple[int, int]] | None = None, progress=None, rig: "Rig | None" = None,
                   period_px: float | None = None,
                   redraw: Callable[[float | None, list | None], Sequence[Pointmap]] | None = None) -> Registration:
    """Align ``views`` (with masks) given their own-frame ``pointmaps`` (see the module docstring).

    ``pairs``: the view pairs to try (default: all ``a < b``). ``progress``: an optional callable
    taking a short text, told what the loop is doing. ``rig``: a calibrated rig
    (:mod:`~fingersplat3d.align.solve.rig`) whose camera poses and focal are kept fixed; the views are
    its cameras in order. ``period_px``: the views' ridge period (the median of theirs), when already measured.
    ``redraw``: the views' pointmaps drawn through a given focal (pixels; None: their own) and with given depth gradients
    along their images (:func:`.axis_tilt.view_tilts`; None: level), for step 5 of the module docstring.
    """
    say = progress or (lambda text: None)
    n_views = len(views)
    pairs = [(a, b) for a in range(n_views) for b in range(a + 1, n_views)] if pairs is None else list(pairs)
    say("ridge texture")
    prepared = _prepare(views, period_px)
    records = {pair: {"a": views[pair[0]].name, "b": views[pair[1]].name, "ok": False, "reason": "", "matches": []}
               for pair in pairs}
    # One tip end for the whole capture: on crops cut at both ends a view's own choice can disagree
    # with the others', and charts running opposite ways share no turn.
    frames = capture_frames(prepared.masks)
    shares = [sides_cut_share(mask, frame) for mask, frame in zip(prepared.masks, frames)]
    tips = [{"side": frame.tip_side, "why": TIP_BASES[frame.tip_basis]}
            | ({"widths": SIDE_CUT_WIDTHS} if frame.widths_from_views else {})
            | ({"sides_cut": round(share, 2)} if share > SIDE_CUT_SHARE else {})
            for frame, share in zip(frames, shares)]
    if config.matcher == "surface":
        charts, unwrapped = prepared.charts(frames)
    rng = np.random.default_rng(config.seed)
    registered = []

    def first_guess(a: int, b: int) -> None:
        say(f"first guess {views[a].name}-{views[b].name}")
        record = records[(a, b)]
        record["method"] = config.matcher
        record.pop("first_guess_skipped", None)
        guess = (_surface_guess(prepared, a, b, charts, unwrapped, config, record) if config.matcher == "surface"
                 else _classic_guess(prepared, a, b, config))
        verified = _verified(guess, prepared.period, config)
        record["matches"].append(len(verified))
        if len(verified) < config.min_matches:
            record["reason"] = record["reason"] or (f"only {len(verified)} of {len(guess)} matches agree on the epipolar "
                                                    f"geometry; {config.min_matches} are needed")
            return
        pair, why = _similar_pair(pointmaps, a, b, verified, config, rng)
        if pair is None:
            record["reason"] = f"the pointmaps do not fit one similarity: {why}"
            return
        registered.append(pair)
        record.update(ok=True, reason="")

    def placed_enough(a: int, b: int) -> bool:
        """From ``many_views`` views on: each of the pair's views already registered with ``first_guesses_per_view``
        others, so its first guess is left to the guided rounds."""
        if n_views < config.many_views or config.first_guesses_per_view <= 0:
            return False
        partners = np.bincount([view for p in registered for view in (p.a, p.b)], minlength=n_views)
        return min(partners[a], partners[b]) >= config.first_guesses_per_view

    for a, b in pairs:
        if placed_enough(a, b):
            records[(a, b)]["first_guess_skipped"] = True
        else:
            first_guess(a, b)
    depths = [pointmap.depth for pointmap in pointmaps]
    focals = [pointmap.focal for pointmap in pointmaps]
    say("global alignment")
    sizes = [(view.width, view.height) for view in views]

    def align(d, f, matches, cfg, previous=None, min_turns=None, contours=()):
        """The views aligned on ``matches`` and the silhouette ``contours`` (which shape the skin, never place a view)."""
        if rig is None:  # each solve without its curvature: only the last one's is reported, asked for once at the end
            return global_align(d, f, list(matches) + list(contours), cfg, previous=previous, min_turns=min_turns,
                                uncertainty=False)
        return rig_align(d, f, matches, cfg, rig, sizes, previous, contours)

    alignment = align(depths, focals, registered, config.global_align)
    skipped = [pair for pair in pairs if records[pair].get("first_guess_skipped")]
    if skipped and not all(alignment.aligned):  # a view the others did not place after all: every pair's guess
        for a, b in skipped:
            first_guess(a, b)
        alignment = align(depths, focals, registered, config.global_align)
    if ((config.undecided_peaks > 0 or config.undecided_zooms) and config.matcher == "surface" and rig is None
            and not all(alignment.aligned)):
        say("undecided votes: their peaks and other zooms through the model")
        alignment = _placed_by_agreement(alignment, registered, pairs, records, prepared, charts, unwrapped, pointmaps,
                                         align, config, rng, say)
    solved_with = (registered, None)  # what the alignment in hand was fitted to (its matches, its least turns)
    contours: list[PairCorrespondences] = []
    # Each pair's least turn from the silhouettes: held by hinge rows only where GlobalAlignConfig.turn_bound_weight > 0.
    min_turns = np.radians(least_turns_deg(prepared.masks, alignment.depths, alignment.focals, prepared.outlines))
    placed = np.asarray(alignment.aligned, bool)
    min_turns[~placed, :], min_turns[:, ~placed] = np.nan, np.nan
    fitted = registered
    rounds = 0
    turn_changes: list[float] = []  # each guided round's largest change of a pair's turn, degrees
    cap = config.many_views_matches if n_views >= config.many_views else 0  # each pair's matches in the alignment
    check_weak = (config.matcher == "surface" and rig is None and config.undecided_peaks > 0
                  and config.weak_agreement_share > 0)  # once, after the first round
    limit = config.guided_rounds if registered else 0
    # Two views with the focal held: more rounds until their turn settles (RegistrationConfig.extra_rounds).
    settling = rig is None and not config.global_align.optimize_focal
    while rounds < limit:
        rounds += 1
        refined, disagreed, agreements = _guided_pass(views, prepared, alignment, pairs, records, config, cap,
                                                      lambda pair: say(f"guided round {rounds} {pair}"))
        if check_weak:
            check_weak = False
            replaced = _weak_views_replaced(alignment, agreements, registered, pairs, records, prepared, charts,
                                            unwrapped, pointmaps, align, config, rng, say)
            if replaced is not None:  # the round again, from the new place
                for pair in agreements:
                    records[pair]["matches"].pop()
                    records[pair]["agreement"].pop()
                alignment, registered = replaced
                fitted, rounds = registered, rounds - 1
                continue
        # A view placed only by pairs this round found disagreeing is placed no longer; a pair that merely found too
        # few matches through the model still holds its views by its earlier ones.
        fitted = [p for p in fitted if (p.a, p.b) not in disagreed]
        alignment = _still_reached(alignment, refined + fitted)
        refined = [p for p in refined if alignment.aligned[p.a] and alignment.aligned[p.b]]
        if not refined:
            break
        contours = _contours(alignment, prepared, config, on_rig=rig is not None)
        say(f"global alignment, round {rounds}")
        before = alignment
        alignment = align(depths, focals, refined, config.global_align, previous=alignment, min_turns=min_turns,
                          contours=contours)
        solved_with = (refined + contours, min_turns)
        fitted = refined
        moved = turn_change_deg(before, alignment)
        turn_changes.append(round(moved, 3))
        if (settling and sum(alignment.aligned) == 2 and rounds == limit and moved > config.settled_turn_deg
                and limit < config.guided_rounds + config.extra_rounds):
            limit += 1
    redrawn_at, tilts, tilted = None, [None] * n_views, False
    if redraw is not None and rig is None and fitted:
        tilts = view_tilts(alignment.cam_to_world, alignment.focals, sizes, capture_finger_axes(prepared.masks),
                           alignment.aligned)
        redrawn = _redrawn(alignment, depths, focals, solved_with, redraw, config, tilts)
        if redrawn is not None:
            alignment, pointmaps, redrawn_at, tilted = redrawn
            say("pointmaps redrawn" + (" at the fitted focal" if redrawn_at is not None else "")
                + (" with the finger's tilt" if tilted else ""))
            depths, focals = [pm.depth for pm in pointmaps], [pm.focal for pm in pointmaps]
    photometric = {}
    if rig is None and config.photometric.iterations > 0 and fitted and sum(alignment.aligned) >= config.photometric.min_views:
        say("photometric refinement")
        alignment, photometric = refine_alignment(alignment, depths, focals, fitted, config.global_align, prepared.textures,
                                                  prepared.masks, prepared.period, config.photometric, min_turns)
    if rig is None and config.global_align.solver == "lm":
        alignment = _how_sure(alignment, depths, focals, solved_with, config, say)
    return Registration(alignment, [records[pair] for pair in pairs], prepared.period, rounds, fitted, tips=tips,
                        photometric=photometric, pointmaps=list(pointmaps), redrawn_at_px=redrawn_at, contours=contours,
                        axis_tilts_deg=[tilt_deg(tilt) for tilt in tilts], tilted=tilted,
                        turn_changes_deg=turn_changes)


def _guided_pass(views: Sequence[View], prepared: _Prepared, alignment: GlobalAlignment, pairs, records: dict,
                 config: RegistrationConfig, cap: int, say) -> tuple[list[PairCorrespondences], set, dict]:
    """One guided round: each pair of placed views matched through the model. The pairs' correspondences that hold,
    the pairs whose views agree too little to be one finger's, and each pair's agreement (0 where nothing was tried);
    each pair's record told its outcome. ``say``: told each pair's names."""
    refined, disagreed, agreements = [], set(), {}
    for a, b in pairs:
        if not (alignment.aligned[a] and alignment.aligned[b]):
            continue
        say(f"{views[a].name}-{views[b].name}")
        matches, verified, agreement = _through_model(prepared, alignment, a, b, config)
        record = records[(a, b)]
        record["matches"].append(len(verified))
        record.setdefault("agreement", []).append(round(agreement, 3) if matches.tried else None)
        agreements[(a, b)] = agreement if matches.tried else 0.0
        if matches.tried and agreement < config.min_agreement:
            disagreed.add((a, b))
            record.update(ok=False, reason=f"the views agree at {agreement:.0%} of the {matches.tried} points the model "
                                           f"puts on both (views of one finger: {config.min_agreement:.1%} or more); "
                                           f"they may show different fingers")
        elif len(verified) < config.min_matches:
            record.update(ok=False, reason=f"only {len(verified)} of {len(matches)} matches through the 3D model agree "
                                           f"on the epipolar geometry; {config.min_matches} are needed")
        else:
            refined.append(_pair_correspondences(a, b, verified, np.eye(4), cap))
            record.update(ok=True, reason="")
    return refined, disagreed, agreements


def _how_sure(alignment: GlobalAlignment, depths, focals, solved_with: tuple, config: RegistrationConfig,
              say) -> GlobalAlignment:
    """The alignment with how sure it is: the focal probe (and, where the photos do not hold the focal, the alignment
    re-fitted at the short end of its valley: :func:`_takes_short_end`), then the turns' uncertainty from the curvature
    of the alignment reported. ``solved_with``: the correspondences and least turns it was fitted to."""
    solved_config = config.global_align  # what the reported alignment was solved with
    if sum(alignment.aligned) >= 2:
        say("how sure: probing the focal")
        probe = focal_probe(alignment, depths, focals, solved_with[0], config.global_align, solved_with[1])
        if probe is not None:
            summary = probe.summary()
            if not probe.held and config.short_end_tolerance > 0 and _takes_short_end(alignment, probe, config):
                say("the focal not held: its short end")
                shorter = short_end(alignment, depths, focals, solved_with[0], config.global_align,
                                    config.short_end_tolerance, solved_with[1])
                if shorter is not None:
                    summary["taken_share"] = round(shorter[1], 3)
                    alignment, solved_config = shorter[0], replace(config.global_align, optimize_focal=False)
            alignment = replace(alignment, turn_sensitivity_deg=probe.moves, focal_probe=summary)
    # The curvature once, of the alignment reported (the probes neither read nor change it).
    return replace(alignment, turn_uncertainty_deg=turn_uncertainty_of(alignment, depths, focals, solved_with[0],
                                                                       solved_config, solved_with[1]))


def _takes_short_end(alignment: GlobalAlignment, probe, config: RegistrationConfig) -> bool:
    """Whether an alignment whose focal the photos do not hold is re-fitted at the short end of its valley: with three
    views or more, always; with two, where the probe's shorter focal fits nearly as well
    (``RegistrationConfig.two_view_short_end_rise``: the valley's short side flat)."""
    if sum(alignment.aligned) >= PIVOT_MIN_VIEWS:
        return True
    rise = probe.shorter_loss_rise
    return rise is not None and rise < config.two_view_short_end_rise  # a NaN rise compares False


def _placed_by_agreement(alignment: GlobalAlignment, registered: list[PairCorrespondences], pairs, records: dict,
                         prepared: _Prepared, charts, unwrapped, pointmaps, align, config: RegistrationConfig,
                         rng, say) -> GlobalAlignment:
    """The alignment with the views no decisive vote placed placed, where they can be, by agreement through the model
    (``RegistrationConfig.undecided_peaks``, ``undecided_zooms``, ``undecided_floor``); ``registered`` grows by the
    pairs that place them.
    ``say``: told each pair and turn tried (a capture that will not register spends 20-40 s here at 1280x1024)."""
    import torch

    from ..rotations import rotation_angle

    depths, focals = [pm.depth for pm in pointmaps], [pm.focal for pm in pointmaps]
    period = prepared.period
    # A peak's first guess is grown and verified from fewer matches: the agreement through the model decides.
    trying = replace(config, min_matches=min(config.min_matches, config.undecided_min_matches))
    done = set()  # pairs tried: a view placed here can reach further views on the next pass
    known: list = [None, 0.0]  # the model the capture's level was read through, and the level

    def level() -> float:
        """The best agreement of the pairs registered so far, through the model in hand (read once per model)."""
        if known[0] is not alignment:
            held = {(p.a, p.b) for p in registered if alignment.aligned[p.a] and alignment.aligned[p.b]}
            known[:] = [alignment, max((_through_model(prepared, alignment, a, b, config)[2] for a, b in sorted(held)),
                                       default=0.0)]
        return known[1]

    placing = True
    while placing:
        placing = False
        for view in range(len(alignment.aligned)):
            if alignment.aligned[view]:
                continue
            tried = []  # (agreement, pair, first-guess correspondences, trial alignment, zoom)
            for pair in pairs:
                a, b = pair
                record = records[pair]
                other = a if b == view else b if a == view else None
                if other is None or not alignment.aligned[other] or record["ok"] or pair in done:
                    continue
                done.add(pair)
                say(f"undecided votes: {record['a']}-{record['b']}, their peaks and other zooms")
                # a pair whose first guess was skipped has not voted yet: its peaks are computed here
                voted = "turn_ratio" in record or record.get("first_guess_skipped", False)
                for shift, zoom, source in _candidate_shifts(a, b, prepared, charts, unwrapped, config, voted):
                    entry = {"turn_deg": round(float(np.degrees(shift.turn)), 2), "votes": shift.support}
                    if source is not None:
                        entry["voted_on"] = source
                    if zoom != 1.0:
                        entry["zoom"] = round(zoom, 3)
                    record.setdefault("undecided_peaks", []).append(entry)
                    if shift.support < config.undecided_min_votes:
                        continue
                    say(f"undecided votes: {record['a']}-{record['b']} tried at {entry['turn_deg']:g}°"
                        + (f", zoom {zoom:.2f}" if zoom != 1.0 else ""))
                    verified = _verified(_chart_guess(prepared, a, b, charts, shift, trying, zoom), period, trying)
                    entry["matches"] = len(verified)
                    if len(verified) < trying.min_matches:
                        continue
                    first, _ = _similar_pair(pointmaps, a, b, verified, config, rng)
                    if first is None:
                        continue
                    trial = align(depths, focals, registered + [first], config.global_align)
                    if not (trial.aligned[a] and trial.aligned[b]):
                        continue
                    _, _, agreement = _through_model(prepared, trial, a, b, config)
                    entry["agreement"] = round(agreement, 3)
                    tried.append((agreement, pair, first, trial, zoom))
            if not tried:
                continue
            tried.sort(key=lambda t: -t[0])
            best = tried[0]
            # The runner-up is the best peak that turns the view elsewhere: peaks of one shift smeared in the vote place
            # it alike (seen against a view placed before, as the trials may root their trees apart).
            anchor = alignment.root

            def turn(trial: GlobalAlignment) -> torch.Tensor:
                return torch.as_tensor(trial.world_to_cam[view][:3, :3] @ trial.world_to_cam[anchor][:3, :3].T)

            runner_up = max((agreement for agreement, _, _, trial, _ in tried[1:]
                             if float(torch.rad2deg(rotation_angle(turn(trial), turn(best[3])))) > RIVAL_TURN_DEG),
                            default=0.0)
            if peak_places(best[0], runner_up, level, config):
                registered.append(best[2])
                alignment = best[3]
                records[best[1]].update(ok=True, reason="", placed_by_agreement=round(best[0], 3))
                if best[0] < config.undecided_agreement:  # placed by the capture's own level
                    records[best[1]]["registered_agreement"] = round(known[1], 3)
                if best[4] != 1.0:
                    records[best[1]]["placed_at_zoom"] = round(best[4], 3)
                placing = True
    return alignment


def peak_places(agreement: float, runner_up: float, level: Callable[[], float], config: RegistrationConfig) -> bool:
    """Whether a view no decisive vote placed is placed by the peak whose views agree best through the model
    (``agreement``): ``undecided_margin`` times the best peak turning it elsewhere (``runner_up``), and at least
    ``undecided_agreement``, or at least ``undecided_floor`` and ``undecided_share`` of the capture's level (``level()``:
    its registered pairs' best agreement, read only when asked)."""
    if agreement < config.undecided_margin * runner_up:
        return False
    if agreement >= config.undecided_agreement:
        return True
    return agreement >= config.undecided_floor and agreement >= config.undecided_share * level()


def weak_view(agreements: dict[tuple[int, int], float], share: float, root: int) -> tuple[int | None, float]:
    """``(view, its best agreement)`` for the one view (never ``root``) whose every pair in ``agreements`` (a guided
    round's, per pair of views) agreed at less than ``share`` of the best pair's; ``(None, nan)`` when there is no
    such view, or more than one (then no pair of the others places it again)."""
    best = max(agreements.values(), default=0.0)
    own: dict[int, float] = {}
    for (a, b), agreement in agreements.items():
        for view in (a, b):
            own[view] = max(own.get(view, 0.0), agreement)
    weak = [view for view, agreement in own.items() if agreement < share * best and view != root]
    return (weak[0], own[weak[0]]) if len(weak) == 1 else (None, float("nan"))


def _weak_views_replaced(alignment: GlobalAlignment, agreements: dict, registered: list[PairCorrespondences], pairs,
                         records: dict, prepared: _Prepared, charts, unwrapped, pointmaps, align,
                         config: RegistrationConfig, rng, say):
    """``(alignment, registered)`` with the one view whose every pair agreed far below the capture's best pair
    (``RegistrationConfig.weak_agreement_share``) placed again by its votes' peaks, or None when no view was that weak,
    or its new place agrees no better by ``undecided_margin`` (the records then as they were)."""
    import copy

    if not all(alignment.aligned):  # the others all placed: they place it again
        return None
    view, own = weak_view(agreements, config.weak_agreement_share, alignment.root)
    if view is None:
        return None
    kept = [p for p in registered if view not in (p.a, p.b)]
    base = _still_reached(alignment, kept)
    if base.aligned[view] or sum(base.aligned) != len(base.aligned) - 1:  # the others still reached without it
        return None
    saved = {pair: copy.deepcopy(records[pair]) for pair in pairs if view in pair}
    for pair in saved:  # as a view no vote placed: what placed it before says nothing of the new place
        records[pair].update(ok=False)
        records[pair].pop("placed_by_agreement", None)
        records[pair].pop("placed_at_zoom", None)
    first = next(iter(saved))
    say(f"view {records[first]['a' if first[0] == view else 'b']} agrees weakly: placed again")
    grown = list(kept)
    placed = _placed_by_agreement(base, grown, pairs, records, prepared, charts, unwrapped, pointmaps, align, config,
                                  rng, say)
    new = max((records[pair].get("placed_by_agreement", 0.0) for pair in saved), default=0.0)
    if placed.aligned[view] and new >= config.undecided_margin * own:
        for pair in saved:
            records[pair]["replaced_from_agreement"] = round(own, 3)
        return placed, grown
    for pair, record in saved.items():
        records[pair].clear()
        records[pair].update(record)
    return None


def _candidate_shifts(a: int, b: int, prepared: _Prepared, charts, unwrapped, config: RegistrationConfig,
                      voted: bool) -> list[tuple]:
    """``(shift, zoom, what voted: None for the whole fingers)`` to try for a pair no decisive vote registered: the
    ``undecided_peaks`` best peaks of its vote (where it voted at all), then those of its vote on the ridge areas alone
    where either view's is a small part of its finger in view (:meth:`_Prepared.ridge_unwrapped`), then, for each of
    ``undecided_zooms``, b's texture unwrapped at that many times a's step (a photo taken nearer or farther, or zoomed:
    its ridges a quarter or half again as large or small, which decorrelates the vote's patches) and the vote's best
    peak where it is decisive."""
    found = ([(shift, 1.0, None) for shift in chart_shift_candidates(unwrapped[a], unwrapped[b], prepared.period,
                                                                      config.undecided_peaks)] if voted else [])
    ridges = prepared.ridge_pair(charts, unwrapped, a, b) if voted else None
    if ridges is not None:
        near = np.radians(RIVAL_TURN_DEG) / 4  # a peak the whole vote gave already is not tried twice
        found += [(shift, 1.0, "ridge area") for shift in chart_shift_candidates(*ridges, prepared.period,
                                                                                  config.undecided_peaks)
                  if all(abs(shift.turn - other.turn) > near for other, _, _ in found)]
    for zoom in config.undecided_zooms:
        scaled = charts[b].unwrap(prepared.textures[b], prepared.masks[b], unwrapped[b].step * zoom)
        shift = estimate_chart_shift(unwrapped[a], scaled, prepared.period)
        if shift is not None and shift.decisive:
            found.append((shift, float(zoom), None))
    return found


def _still_reached(alignment: GlobalAlignment, holding: list[PairCorrespondences]) -> GlobalAlignment:
    """``alignment`` with the views that ``holding`` (matched pairs) no longer reach from its root marked not aligned
    (the contours alone never hold a view)."""
    _, tree = spanning_tree(len(alignment.aligned), holding, alignment.root)
    still = reached(len(alignment.aligned), alignment.root, tree)
    aligned = [bool(was and now) for was, now in zip(alignment.aligned, still)]
    if aligned == list(alignment.aligned):
        return alignment
    uncertainty = alignment.turn_uncertainty_deg
    if uncertainty is not None:
        uncertainty = uncertainty.copy()
        lost = ~np.asarray(aligned)
        uncertainty[lost, :], uncertainty[:, lost] = np.nan, np.nan
    return replace(alignment, aligned=aligned, tree=[(a, b) for a, b in alignment.tree if aligned[a] and aligned[b]],
                   turn_uncertainty_deg=uncertainty)


def _redrawn(alignment: GlobalAlignment, depths: list[np.ndarray], focals: list[float], solved_with: tuple,
             redraw: Callable[[float | None, list | None], Sequence[Pointmap]], config: RegistrationConfig,
             tilts: Sequence[np.ndarray | None] | None = None):
    """The alignment solved again on pointmaps drawn through its own focal and with the finger's tilt ``tilts``
    (:func:`.axis_tilt.view_tilts`): ``(alignment, pointmaps, focal or None, tilted)``, or None when there is neither
    to draw. Only with :data:`PIVOT_MIN_VIEWS` views aligned or more: two views cannot fix the focal (their fitted one
    is no better than the guess), and their turn, in its valley, moves with any new start (measured: synthetic ring
    pairs drawn tilted 0.30 -> 1.57 and 4.24 -> 5.42 degrees off, their tilts right within 0.7 degrees). The focal is
    drawn when the views share a fitted one that is a finite positive number further than ``redraw_tolerance`` from the
    guess; the tilts when some view's reaches ``redraw_tilt_deg``."""
    if sum(alignment.aligned) < PIVOT_MIN_VIEWS:
        return None
    align_config = config.global_align
    focal = None
    if align_config.shared_focal and align_config.optimize_focal:
        fitted, guess = float(alignment.focals[0]), float(np.exp(np.mean(np.log(focals))))
        if np.isfinite(fitted) and fitted > 0 and abs(np.log(fitted / guess)) > np.log1p(config.redraw_tolerance):
            focal = fitted  # a fit that lost its focal keeps the pointmaps it had (the caller reports the fit)
    angles = [tilt_deg(tilt) for tilt in (tilts or [])]
    tilted = config.redraw_tilt_deg > 0 and any(a is not None and a >= config.redraw_tilt_deg for a in angles)
    if focal is None and not tilted:
        return None
    pointmaps = list(redraw(focal, [None if t is None else tuple(float(g) for g in t) for t in tilts] if tilted else None))
    # The start: the solved poses; each view's scale and relief such that its median depth and relief stay where they
    # were (the new pointmaps stand at about the new focal instead of the guess, with the same relief in pixels),
    # the fields flat. One relief for all views when it is shared: their mean change.
    ratio = np.array([median_depth(pm.depth) / median_depth(old) for pm, old in zip(pointmaps, depths)])
    reliefs = np.asarray(alignment.relief_scale) * (ratio if not align_config.shared_relief else np.exp(np.mean(np.log(ratio))))
    start = replace(alignment, fields=[np.zeros_like(f) for f in alignment.fields], relief_scale=list(reliefs),
                    scales=list(np.asarray(alignment.scales) / ratio))
    solved = global_align([pm.depth for pm in pointmaps], [pm.focal for pm in pointmaps], solved_with[0], align_config,
                          previous=start, min_turns=solved_with[1], uncertainty=False)
    return solved, pointmaps, focal, tilted
