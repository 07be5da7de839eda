"""The settings of the global alignment and of the dense photometric refinement, apart from their solvers.

Commands build their parsers from these defaults; kept free of torch so that ``fs3d fuse --help`` (and a bad
argument's one sentence) do not wait for it.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["GlobalAlignConfig", "PhotometricConfig", "PIVOT_MIN_VIEWS"]


@dataclass(frozen=True)
class GlobalAlignConfig:
    """Settings of the joint optimisation."""

    iterations: int = 0
    """Adam steps before L-BFGS (0: L-BFGS only; needs a start near the basin, as the spanning tree gives)."""
    learning_rate: float = 0.01
    """Initial Adam step size (parameters are normalised to O(1)); decays with a cosine schedule."""
    polish_iterations: int = 150
    """L-BFGS iterations per round."""
    polish_rounds: int = 2
    """L-BFGS restarts (a fresh curvature history helps after the robust weights settle)."""
    shared_focal: bool = True
    """One focal length for all views (same camera), else one per view."""
    optimize_focal: bool = True
    """Let the focal move away from the guess (needs >= 2 views with parallax)."""
    pivot_poses: bool = True
    """Each camera's translation unknown is where a point of the finger (on the root view's axis at its median depth)
    lies in the camera's frame, so that turning about the finger is a straight line in the unknowns
    (:class:`~fingersplat3d.align.solve.alignment_problem.AlignmentProblem`). Measured on another group's crops at
    rolls 45 degrees apart (docs/measurements.md): the wide triplets' worst pairs 5.7-9.8 -> 0.3-2.7 degrees."""
    field_knots: float = 8.0
    """Knot intervals of each view's depth field across the finger's short side (0 = no field)."""
    field_smoothness: float = 0.002
    """Bending penalty of the depth fields, with three views or more aligned (:data:`PIVOT_MIN_VIEWS`) that see the
    finger from three distinct places (:func:`~fingersplat3d.align.transfer.distinct_viewpoints`). Where the
    finger's section is not the pointmap prior's, the fields must bend to take the difference up; held stiff
    (0.05 until stop 78), the turns, the relief and the focal took it instead. Measured (docs/measurements.md, stop
    78): real captures, every camera pair 0.78 -> 0.68 degrees from the rig's mean (the held-out finger 1.06 / 1.16 /
    1.36 -> 0.76 / 1.14 / 1.22), focal spread 15 -> 12 %, two views predicting the third's silhouette 25.6 -> 12.5 %
    off; sections unlike the prior's and close-ups the frame cuts (synthetic) fewer turns off by degrees; a finger of the
    prior's own section 0.01 mm more depth error (0.042 -> 0.052 mm)."""
    two_view_field_smoothness: float = 0.05
    """The same penalty with two views aligned, or more from only two distinct places: their bas-relief valley is open,
    and stiffer fields keep them where the pair's own similarity put them (synthetic ring and CFPose, two views: 0.002
    moved the turns by degrees either way and doubled the depth error of some; another group's renders at rolls 47 and
    48, a degree apart, with a third view: worst pairs 1.7-4.4 degrees soft, 0.1-4.1 stiff, five of seven within 2
    against one, docs/measurements.md stop 84)."""
    field_prior: float = 1e-4
    """Pull of the field coefficients toward 0 (keeps coefficients no correspondence reaches bounded)."""
    robust_px: float = 1.0
    """Cauchy scale of the information-weighted reprojection error (pixels across the ridges)."""
    alpha_prior: float = 0.01
    """Pull of log relief scale toward 0."""
    focal_prior: float = 1e-4
    """Pull of log focal toward the guess."""
    solver: str = "lm"
    """``lm``: Levenberg-Marquardt on the sparse Jacobian (:mod:`~fingersplat3d.align.solve.levenberg`);
    ``lbfgs``: Adam (``iterations``) then L-BFGS (``polish_*``), which converges slowly on this problem."""
    lm_iterations: int = 40
    """Levenberg-Marquardt steps per round at most (it stops when the loss falls by less than ``lm_tolerance`` of
    itself in a step). Along the bas-relief valley the fit needs 20-40 steps: at 15 it had stopped partway on another
    group's crops at rolls 45 degrees apart, and on the real captures in one round of three."""
    lm_tolerance: float = 1e-4
    """The relative fall of the loss under which a round stops (1e-5 gave the same turns, 20 % slower)."""
    two_view_lm_iterations: int = 15
    """The same cap with fewer than :data:`PIVOT_MIN_VIEWS` views aligned: their valley is open, the data do not say
    where along it the turn lies, and the pair's own similarity the fit starts from is nearer the truth than where
    the priors stop a longer fit (synthetic ring, two views: 0.89 degrees at 15 steps; real, frames 0 and 1 alone
    carried into frame 2: texture correlation 0.12 at 15, 0.07 at 40)."""
    turn_bound_weight: float = 0.0
    """Weight of the hinge rows that keep each view pair turned at least as far as their silhouette widths allow
    (``min_turns`` of :func:`global_align`; :mod:`~fingersplat3d.align.width_check`). Off (1e3 before): the bounds had
    held the unfinished fit's turns up on flat fingers; with the rounds run to their end they only bind where they
    are wrong, when the capture's widest view is oblique to a flat section (another group's crops -45 / -18 / 14:
    bound 34 degrees, true 27; with the hinges 6.7 degrees off, without 0.1). Real and synthetic tables unchanged."""
    two_view_turn_bound_weight: float = 1e3
    """The same hinge rows with two views aligned. Their bas-relief valley is open, so the relief the turn trades
    against comes from the pointmap prior's section (0.95 as deep as wide), and on a flatter finger the turn comes out
    too small; the narrower view's silhouette then says how far it must at least be turned from the wider one. Measured
    on another group's renders of a flat finger (its nine rolls' silhouettes fit an ellipse 0.39 as deep as wide within
    0.6 px), ten pairs 18-92 degrees apart, focal fitted (docs/measurements.md, stop 81): error median 17.1 -> 8.8 degrees;
    the pairs with the pad-facing view 12.3 -> 1.7, 17.2 -> 3.8, 21.3 -> 8.1 degrees, those of two oblique views as
    before (the wider of two oblique views gives no bound that holds). The bound never binds on the real dev pairs nor on
    the synthetic ones (their sections 0.74-0.94 as deep as wide)."""
    shared_relief: bool = True
    """One relief scale for all views (they see one finger) instead of one per view. Measured (README,
    5 seeds): rotation error median on synthetic ``cfpose`` 3.93 -> 3.35 deg, ``uwa`` 1.99 -> 2.01 deg;
    real rig consistency 2.91 / 3.74 / 4.90 -> 2.38 / 1.83 / 3.01 deg."""


PIVOT_MIN_VIEWS = 3
"""Views a capture needs for :attr:`GlobalAlignConfig.pivot_poses`. Two views leave the bas-relief valley open (their
turn and the relief trade with no data against it); pivoted, the fit slides along it to where the priors stop it,
further from the truth than the pair's own similarity it starts from (synthetic ring, two views 45 degrees apart: 0.89
-> 4.98 degrees, 3 seeds), so two views keep the camera centres as unknowns."""



@dataclass(frozen=True)
class PhotometricConfig:
    """Settings of :func:`photometric_refine` (0 iterations: off)."""

    iterations: int = 30
    """L-BFGS iterations per round."""
    rounds: int = 2
    """Rounds; each decides the samples' visibility afresh."""
    stride_periods: float = 0.5
    """Sample spacing on each view's finger, in ridge periods."""
    weight: float = 1.0
    """Weight of the photometric mean against the alignment's own loss."""
    robust: float = 1.0
    """Cauchy scale of the texture difference (the textures have unit local RMS)."""
    fine_knots: float = 24.0
    """Knot intervals of the finer depth field across the finger's short side (0: none)."""
    fine_smoothness: float = 0.05
    """Bending penalty of the finer fields."""
    fine_prior: float = 1e-3
    """Pull of the finer fields toward 0 (beyond the samples a bent field would otherwise run on as a ramp)."""
    poses: bool = False
    """Refine the poses, focal, scales and relief too (after the surface, each round). Off: measured on the real
    dev captures, the turns moved by less than 0.05 deg (the verified matches already pin them) at 1.5 s more."""
    pose_iterations: int = 20
    """L-BFGS iterations of the pose block per round."""
    min_views: int = 3
    """Views a capture needs for the stage. With two, ridges that run along the one epipolar direction leave
    the depth free to take up what is left of the pose error (synthetic two-view ring captures: whole-view
    depth error, median of 3 seeds, 0.087 -> 0.104 mm)."""
