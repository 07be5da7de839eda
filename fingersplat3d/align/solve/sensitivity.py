"""How far each view pair's turn hangs on the focal, which the photos leave loosely fixed.

The curvature of the solved alignment (:func:`~fingersplat3d.align.solve.levenberg.turn_uncertainty_deg`) says how
sharply the matches pin a turn *given* the model; it cannot see a turn pinned sharply in the wrong place. On the real
captures that place is set by the focal: three views of a finger 60 mm away fix it only to about 7 % (one camera's
fitted focal spread by 14 % over the dev captures), and the turns follow it (a wide pair by about 0.15 degree per
1 %), which is where their rig inconsistency comes from (docs/measurements.md, real captures).

So the probe holds the focal :data:`FOCAL_STEP` (10 %) longer than solved, re-fits everything else from the solved
state (the fit's own Levenberg-Marquardt steps) and records how far every pair's turn went: the pair's
*sensitivity*, in degrees. A probe, not a standard deviation.

**When the photos do not hold the focal at all.** Three views fix the focal through the skin all of them see, the
fingertip's cap above all. A crop with no fingertip whose two outer views share no skin leaves two front-side pairs
and nothing between them: the loss is flat toward a longer focal and the fit slides toward a nearly orthographic one
(real captures cropped about their centre: fitted 1.8-21.6k px against the rig's 1.66k, turns up to 19 degrees off), where
a 10 % step moves nothing and the probe above read 0.1-0.3 degree. So when the loss rises by less than
:data:`FLAT_LOSS_RISE` with the focal held longer, a second probe holds it *shorter*, where the finger's angular width
(its width in pixels over the focal) is :data:`PERSPECTIVE_STEP` larger. If the photos exclude that focal too (the loss
rises by more than :data:`EXCLUDED_LOSS_RISE`: renders that are near-orthographic, whose turns do not hang on the
focal) the focal stands; else the focal is not held by the photos, and that probe's moves are the pair's sensitivity.

Tried and left out: the same probe on the relief scale (held 20 % flatter). Each view's depth field takes the change
up, so once the fit has converged no turn moves (another group's crops: 0.0 degree on every pair, 6.7 degrees off on
the worst), and the moves it had shown before were the unconverged fit still finding its way.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
import torch

from ...rotations import rotation_angle
from ...segment.silhouette import widest_disc
from .global_opt import GlobalAlignConfig, GlobalAlignment, PairCorrespondences, global_align

__all__ = ["FOCAL_STEP", "FLAT_LOSS_RISE", "PERSPECTIVE_STEP", "EXCLUDED_LOSS_RISE", "SHORT_END_STEP", "FocalProbe",
           "focal_probe", "short_end"]

FOCAL_STEP = 0.10
"""The focal probe: the focal held this much longer than solved (a share)."""
FLAT_LOSS_RISE = 0.015
"""With the focal held :data:`FOCAL_STEP` longer, a loss that rises by less than this share (or falls) does not hold
the focal from the long side. Measured: whole real captures 1.7-5.3 % (finger 1, tuned on: 2.5-5.3 %; finger 2, held
out: 1.7-4.5 %); synthetic captures 4-41 %; the real captures cropped to no fingertip (``tools/bench_real.py
--crop-tip``) -10.2 to +1.4 % (finger 1: -4.4 to +0.9 %; finger 2: -10.2 to +1.4 %); another group's
near-orthographic renders 0.1-0.3 %."""
PERSPECTIVE_STEP = 0.05
"""The shorter probe: the finger's angular width (its width over the focal, radians) this much larger. On the real
crops a focal 1.2-3.3 times shorter, which moves their turns by 0.5-6.1 degrees."""
EXCLUDED_LOSS_RISE = 1.0
"""The shorter probe's focal is excluded by the photos when the loss rises by more than this share (doubles). Measured:
the real crops -14 to +77 %; the near-orthographic renders +185 to +977 %."""


@dataclass(frozen=True)
class FocalProbe:
    """What the focal probes found (the module docstring)."""

    moves: np.ndarray
    """``[N, N]`` degrees: each pair's sensitivity (the shorter probe's moves where it counts, else the longer's)."""
    longer_loss_rise: float
    """How much the loss rose (a share; negative: fell) with the focal held :data:`FOCAL_STEP` longer."""
    shorter_share: float | None = None
    """The shorter probe's focal over the solved one, when it ran."""
    shorter_loss_rise: float | None = None
    """How much the loss rose at the shorter probe's focal, when it ran."""

    @property
    def held(self) -> bool:
        """Whether the photos hold the focal: False when neither probe raised the loss as a fixed focal does."""
        return not _fits_as_well(self.shorter_loss_rise)

    def summary(self) -> dict:
        """The report's ``focal_probe`` entry."""
        rise = round(self.longer_loss_rise, 4) if np.isfinite(self.longer_loss_rise) else None
        entry = {"held": self.held, "longer_loss_rise": rise}
        if self.shorter_share is not None:
            shorter = round(self.shorter_loss_rise, 4) if np.isfinite(self.shorter_loss_rise) else None
            entry |= {"shorter_share": round(self.shorter_share, 3), "shorter_loss_rise": shorter}
        return entry


SHORT_END_STEP = 0.9
""":func:`short_end` walks the focal down by this factor a step."""
SHORT_END_STEPS = 12
"""At most this many steps (a focal 0.28 times the solved one)."""


def short_end(alignment: GlobalAlignment, depths: Sequence[np.ndarray], focal_guess, pairs: Sequence[PairCorrespondences],
              config: GlobalAlignConfig, tolerance: float, min_turns: np.ndarray | None = None
              ) -> tuple[GlobalAlignment, float] | None:
    """Where the photos do not hold the focal (:class:`FocalProbe` ``held`` False), the alignment re-fitted with the
    focal held at the short end of the flat valley: the shortest focal whose loss is within ``tolerance`` (a share)
    of the solved one, walked down :data:`SHORT_END_STEP` a step and interpolated (in the log of the focal) to where
    the rise meets ``tolerance``; with the share of the solved focal it holds. None when no shorter focal fits within
    ``tolerance`` or the losses cannot be compared.

    Why the short end: the valley is flat because three cameras on a ring fix the focal only through the prior's
    relief, and a relief unlike the finger's lets the fit slide toward a nearly orthographic camera. Measured where the
    photos did not hold the focal (docs/measurements.md): the true focal lay on the short side every time, at a loss
    +10 to +27 % (synthetic close-ups and flat fingers) and +10 to +145 % (real crops without a fingertip), so a walk
    that stops at +10 % comes toward it, not past it, wherever the fit had slid (one real crop whose fit had not slid,
    its focal within 1 % of the rig's, was taken 22 % short by the walk)."""
    last_share, last_rise, found = 1.0, 0.0, None
    share = 1.0
    for _ in range(SHORT_END_STEPS):
        share *= SHORT_END_STEP
        held = _held_at(alignment, depths, focal_guess, pairs, config, min_turns, share)
        rise = _loss_rise(held, alignment)
        if not np.isfinite(rise):
            return found
        if rise > tolerance:
            if found is None:
                return None
            # the share where the rise meets the tolerance, between the last step within it and this one
            t = (tolerance - last_rise) / max(rise - last_rise, 1e-12)
            between = float(np.exp(np.log(last_share) + t * (np.log(share) - np.log(last_share))))
            at = _held_at(alignment, depths, focal_guess, pairs, config, min_turns, between)
            at_rise = _loss_rise(at, alignment)
            return (at, between) if np.isfinite(at_rise) and at_rise <= tolerance * 1.5 else found
        last_share, last_rise, found = share, rise, (held, share)
    return found


def _turns(alignment: GlobalAlignment) -> np.ndarray:
    """``[N, N]`` degrees between every two views' rotations."""
    rotations = torch.as_tensor(np.stack([pose[:3, :3] for pose in alignment.cam_to_world]), dtype=torch.float64)
    return np.degrees(rotation_angle(rotations[:, None], rotations[None, :]).numpy())


def _held_at(alignment: GlobalAlignment, depths, focal_guess, pairs, config: GlobalAlignConfig, min_turns,
             share: float) -> GlobalAlignment:
    """Everything re-fitted from the solved state with the focal held at ``share`` times the solved one (the shape
    kept: lateral size goes as 1/focal, so the relief and the field do too)."""
    start = replace(alignment, focals=[f * share for f in alignment.focals],
                    relief_scale=[a / share for a in alignment.relief_scale],
                    fields=[np.asarray(f) / share for f in alignment.fields])
    return global_align(depths, focal_guess, pairs, replace(config, optimize_focal=False), previous=start,
                        min_turns=min_turns, uncertainty=False)


def _fits_as_well(shorter_rise: float | None) -> bool:
    """Whether the shorter probe's focal fits about as well as the solved one (a finite rise, at most
    :data:`EXCLUDED_LOSS_RISE`); no probe, or a loss that could not be compared, says nothing."""
    return shorter_rise is not None and bool(np.isfinite(shorter_rise)) and shorter_rise <= EXCLUDED_LOSS_RISE


def _loss_rise(moved: GlobalAlignment, alignment: GlobalAlignment) -> float:
    """How much the final loss rose from ``alignment`` to ``moved`` (a share); NaN where either has none to compare."""
    if not (alignment.loss_history and moved.loss_history):
        return float("nan")
    before, after = float(alignment.loss_history[-1]), float(moved.loss_history[-1])
    return after / before - 1.0 if before > 0 and np.isfinite(before) and np.isfinite(after) else float("nan")


def focal_probe(alignment: GlobalAlignment, depths: Sequence[np.ndarray], focal_guess,
                pairs: Sequence[PairCorrespondences], config: GlobalAlignConfig,
                min_turns: np.ndarray | None = None) -> FocalProbe | None:
    """How far each pair's turn moves with the focal held off its solved value (the module docstring); None when the
    focal is held anyway (a known focal, a rig).

    ``alignment`` is the solved alignment of ``depths``, ``focal_guess``, ``pairs``, ``config`` and ``min_turns``
    (as :func:`~fingersplat3d.align.solve.global_opt.global_align` was called for it). Moves are NaN where a view is not
    aligned, 0 on the diagonal.
    """
    if not config.optimize_focal:
        return None
    aligned = np.asarray(alignment.aligned, bool)
    moves, rise, shorter, shorter_rise = np.zeros((len(depths), len(depths))), 0.0, None, None
    if aligned.sum() >= 2:
        longer = _held_at(alignment, depths, focal_guess, pairs, config, min_turns, 1.0 + FOCAL_STEP)
        moves, rise = np.abs(_turns(longer) - _turns(alignment)), _loss_rise(longer, alignment)
        if rise < FLAT_LOSS_RISE:  # NaN (no loss to compare) is no evidence either way: the focal stands
            width = float(np.median([widest_disc(np.isfinite(d)) for d, a in zip(alignment.depths, aligned) if a]))
            focal = float(alignment.focals[0])
            if width > 0 and np.isfinite(focal) and focal > 0:
                shorter = 1.0 / (1.0 + PERSPECTIVE_STEP * focal / width)  # width / f' = width / f + PERSPECTIVE_STEP
                held = _held_at(alignment, depths, focal_guess, pairs, config, min_turns, shorter)
                shorter_rise = _loss_rise(held, alignment)
                if _fits_as_well(shorter_rise):
                    moves = np.maximum(moves, np.abs(_turns(held) - _turns(alignment)))
    moves[~aligned, :] = np.nan
    moves[:, ~aligned] = np.nan
    return FocalProbe(moves, rise, shorter, shorter_rise)
