"""How far each view pair's turn hangs on the focal, which the photos leave loosely fixed.

The curvature of the solved alignment (:func:`~fingersplat3d.align.solve.levenberg.turn_uncertainty_deg`) says how
sharply the matches pin a turn *given* the model; it cannot see a turn pinned sharply in the wrong place. On the real
captures that place is set by the focal: three views of a finger 60 mm away fix it only to about 7 % (one camera's
fitted focal spread by 14 % over the dev captures), and the turns follow it (a wide pair by about 0.15 degree per
1 %), which is where their rig inconsistency comes from (docs/measurements.md, real captures).

So the probe holds the focal :data:`FOCAL_STEP` (10 %) longer than solved, re-fits everything else from the solved
state (the fit's own Levenberg-Marquardt steps) and records how far every pair's turn went: the pair's
*sensitivity*, in degrees. A probe, not a standard deviation.

Tried and left out: the same probe on the relief scale (held 20 % flatter). Each view's depth field takes the change
up, so once the fit has converged no turn moves (another group's crops: 0.0 degree on every pair, 6.7 degrees off on
the worst), and the moves it had shown before were the unconverged fit still finding its way.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np
import torch

from ...rotations import rotation_angle
from .global_opt import GlobalAlignConfig, GlobalAlignment, PairCorrespondences, global_align

__all__ = ["FOCAL_STEP", "turn_sensitivity_deg"]

FOCAL_STEP = 0.10
"""The focal probe: the focal held this much longer than solved (a share)."""


def _turns(alignment: GlobalAlignment) -> np.ndarray:
    """``[N, N]`` degrees between every two views' rotations."""
    rotations = torch.as_tensor(np.stack([pose[:3, :3] for pose in alignment.cam_to_world]), dtype=torch.float64)
    return np.degrees(rotation_angle(rotations[:, None], rotations[None, :]).numpy())


def turn_sensitivity_deg(alignment: GlobalAlignment, depths: Sequence[np.ndarray], focal_guess,
                         pairs: Sequence[PairCorrespondences], config: GlobalAlignConfig,
                         min_turns: np.ndarray | None = None) -> np.ndarray | None:
    """``[N, N]`` degrees: how far each pair's turn moves with the focal held :data:`FOCAL_STEP` longer (the module
    docstring); None when the focal is held anyway (a known focal, a rig).

    ``alignment`` is the solved alignment of ``depths``, ``focal_guess``, ``pairs``, ``config`` and ``min_turns``
    (as :func:`~fingersplat3d.align.solve.global_opt.global_align` was called for it). NaN where a view is not
    aligned; 0 on the diagonal.
    """
    if not config.optimize_focal:
        return None
    aligned = np.asarray(alignment.aligned, bool)
    result = np.zeros((len(depths), len(depths)))
    if aligned.sum() >= 2:
        longer = 1.0 + FOCAL_STEP  # the shape kept: lateral size goes as 1/focal, so the relief and the field do too
        start = replace(alignment, focals=[f * longer for f in alignment.focals],
                        relief_scale=[a / longer for a in alignment.relief_scale],
                        fields=[np.asarray(f) / longer for f in alignment.fields])
        moved = global_align(depths, focal_guess, pairs, replace(config, optimize_focal=False), previous=start,
                             min_turns=min_turns, uncertainty=False)
        result = np.abs(_turns(moved) - _turns(alignment))
    result[~aligned, :] = np.nan
    result[:, ~aligned] = np.nan
    return result
