"""The settings of the registration (:func:`~fingersplat3d.align.register.register_views`), apart from it.

Commands build their parsers from these defaults; kept free of torch and of the registration's own imports so that
``fs3d fuse --help`` (and a bad argument's one sentence) do not wait for them.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .solve.settings import GlobalAlignConfig, PhotometricConfig

__all__ = ["RegistrationConfig", "MATCHERS", "CONTOUR_MIN_VIEWS", "CONTOUR_MIN_VIEWS_FOCAL_HELD"]

MATCHERS = ("surface", "minutiae", "sift", "rootsift", "akaze")


CONTOUR_MIN_VIEWS = 3
"""Silhouette contours join the alignment from this many aligned views seen from distinct places
(:func:`distinct_viewpoints`): with two, the turn and the relief trade freely (bas-relief), and pulling the surface
onto the other outline moved the turn instead (ring rig, 2 views: rotation 0.89 -> 1.62 degrees); with three or more
the matches hold the turns and the contours shape the skin. Three views of which two are 1 degree apart are two views
for the bas-relief: measured on another group's renders, a view beside the rolls 47 and 48 (-18 / 47 / 48,
-13 / 47 / 48, 0 / 47 / 48) came out 4.71, 3.92, 3.11 degrees off with the contours and 0.89, 0.16, 1.46 without
(docs/measurements.md)."""
CONTOUR_MIN_VIEWS_FOCAL_HELD = 2
"""The same with the focal held (``--focal-px``, photos whose EXIF records it, a rig): two views' turn no longer slides with
a fitted focal, and the contours shape the skin that only one of them sees instead of turning them. Measured on
synthetic pairs of six kinds (45-90 degrees apart, ring, uwa and CFPose rigs, a 50 mm close-up; 3-5 seeds each), the
true focal given: whole-view depth 0.10-0.45 -> 0.04-0.28 mm (median per kind), better on 24 captures of 26; the turns
mostly within 0.1 degree of before (two of 26 moved by 0.5 and 1.1) (docs/measurements.md)."""


@dataclass(frozen=True)
class RegistrationConfig:
    """Settings of :func:`register_views`."""

    matcher: str = "surface"
    """First guess of each pair: ``surface`` (cylinder charts + guided ridge matching) or a classic
    matcher of :mod:`fingersplat3d.align.correspond.features` (``minutiae``, ``sift``, ``rootsift``, ``akaze``)."""
    guided_rounds: int = 2
    """Rounds of model-guided matching and refinement after the first alignment (0 = none)."""
    extra_rounds: int = 4
    """Two views with the focal held (``--focal-px``, EXIF): rounds beyond ``guided_rounds``, one at a time, while the
    last round still turned them by more than ``settled_turn_deg``. One pair alone settles slowly where it shares a
    narrow strip of skin (synthetic 90-degree pairs: the second round turned them 1.2-2.8 degrees). Measured
    (docs/measurements.md, stop 74): real pairs with the focal given, 45 degrees apart 2.34 -> 1.07 degrees and 90 degrees
    apart 8.0 -> 3.5 (median). Not for three views or more: their loop of pairs holds the turns, and the rounds changed the
    real rig's figures within noise (0.70 / 0.77 / 0.58 -> 0.60 / 0.77 / 0.60 degrees) for a median fuse 21 -> 31 s. Not
    with a fitted focal: where the photos do not fix it (two views, crops without a tip) more rounds carried the turn along
    what they leave free (CFPose two views 3.4 -> 4.6 degrees, real crops 2.9 / 3.8 -> 4.0 / 4.4), so two rounds are an
    early stop there."""
    settled_turn_deg: float = 0.25
    """A round that turns no pair of views by more than this (degrees) ends the extra rounds."""
    first_search: float = 2.0
    """Search radius of the first guided matching through the charts, in ridge periods."""
    grow_first_guess: bool = True
    """Grow each pair's first guess through its charts corrected by the matches they gave
    (:mod:`~fingersplat3d.align.correspond.chart_growth`): on a flat finger the cylinder charts' predictions hold only
    mid-pad, and a wide pair's few first matches left its view unregistered."""
    guided_search: float = 0.7
    """Search radius of the model-guided rounds, in ridge periods (below half a period to one side
    of the prediction, a repeating ridge cannot be mistaken for its neighbour)."""
    guided_both_ways: bool = True
    """The guided rounds match each pair from a grid on either view, each sqrt(2) ridge periods apart (as many points as
    one grid a period apart), instead of from a grid on the first view alone. From one view, the result depended on the
    photos' order: over its six orders a real capture's turns moved by up to 1.7 degrees (median of nine 1.2) and its
    focal by up to 8 %; both ways, by 0.1-1.0 degrees (median 0.46) and up to 4.7 %. Measured (docs/measurements.md,
    stop 83): real captures, focal spread 12 -> 8 % in every order, the rig deviation averaged over the orders 0.68 /
    0.86 / 0.87 -> 0.58 / 0.71 / 0.81 degrees (in the rig's own order within its noise), two views with the focal
    fitted 7.3 / 6.1 -> 5.1 / 5.8, the warp check's ridge NCC 0.51 -> 0.54; synthetic 3 and 5 views the same or
    better."""
    first_guess_both_ways: bool = True
    """Each pair's first guess (through its cylinder charts, and its growth) is matched both ways too, a grid on either
    view sqrt(2) ridge periods apart, b's predicted in a through the inverse shift and grown through a correction of its
    own (:func:`~fingersplat3d.align.correspond.chart_growth.grow_first_guess`). From a's grid alone, the two guided
    rounds started from an order-dependent first alignment: a real capture's six orders still moved its turns by
    0.14-1.00 degrees (median of nine 0.51) and its focal by up to 4.7 %; both ways, 0.10-0.70 degrees (median 0.21) and
    up to 3.0 %; the rig's figures and the focal spread (7 %) as good or better in every order (docs/measurements.md,
    stop 84; ``tools/bench_real.py --orders``)."""
    min_matches: int = 40
    """Verified correspondences a pair needs to count as registered."""
    min_agreement: float = 0.125
    """Share of the points a guided round searched (those the model puts on the other view's finger) whose verified
    matches a pair needs to stay registered: views of one finger agree wherever they overlap, views of two fingers
    only by chance. Measured (verified / searched, every guided round): real dev pairs 18-86 % (the side views 90
    degrees apart 18-52 %), synthetic 47-100 %, another group's crops 19-100 %; a front view of one real finger
    against the side views of the other, with every chart vote taken as decisive, 3-9 %."""
    many_views: int = 6
    """From this many views on, each pair's guided matches are thinned for the alignment (``many_views_matches``)."""
    many_views_matches: int = 400
    """With ``many_views`` views or more, each pair's guided matches enter the alignment thinned to at most this many
    (evenly over the overlap, the pair's weight kept): ten views make 45 pairs of up to 1500 matches each, and forming
    the normal equations of ~90k correspondences was a quarter of the time. Measured (10 CFPose-style views, 3 seeds):
    the same errors (0.19 degrees, 0.051 mm), 59.9 -> 45.7 s, 1.67 -> 1.37 GB; at 200: 0.21 degrees, 43.9 s."""
    first_guesses_per_view: int = 2
    """With ``many_views`` views or more, a pair's first guess (step 1) is skipped when each of its views is already
    registered with this many others: its views are placed without it, and the guided rounds match it through the
    model like a pair that had no first guess. Every pair is guessed after all when a view ends unplaced. Ten views make
    45 first guesses, nearly half of the registration (0: every pair's, as below ``many_views``)."""
    epipolar_px: float = 0.1
    """Fundamental-matrix inlier threshold, in ridge periods (at least 1 pixel)."""
    global_align: GlobalAlignConfig = field(default_factory=GlobalAlignConfig)
    """The joint optimisation."""
    photometric: PhotometricConfig = field(default_factory=lambda: PhotometricConfig(iterations=0))
    """The dense photometric refinement after the guided rounds (without a rig). Off by default (``iterations=0``;
    ``PhotometricConfig()`` turns it on): measured, it brings the views' ridges into phase but does not make the
    synthetic depth better nor move the turns (docs/fuse.md)."""
    contour_weight: float = 1.0
    """Weight of each silhouette-contour correspondence (:mod:`~fingersplat3d.align.correspond.contours`) against a
    matched pair's (0 to 1 by its score) in the guided rounds' alignments, with :data:`CONTOUR_MIN_VIEWS` distinct views
    or more; 0 turns them off. Measured (3 seeds): whole-view depth error ring 3 / 5 views 0.109 / 0.064 -> 0.059 /
    0.041 mm, uwa 0.112 -> 0.071, cfpose 3 / 5 0.116 / 0.091 -> 0.066 / 0.058; real rig deviation finger 1 (tuned)
    0.62 / 1.09 / 1.20 -> 0.74 / 0.65 / 1.25 degrees, max 4.9 -> 2.3, finger 2 (held out) 0.81 / 1.24 / 1.49 -> 0.28 /
    1.10 / 1.00, max 3.8. Weight 0.3 and the outline itself instead of a pixel inside it were no better."""
    seed: int = 0
    """Seed of the random parts (RANSAC of the pair similarities)."""
    undecided_peaks: int = 3
    """A view no decisive chart vote placed is tried at this many peaks (with ``undecided_min_votes`` votes) of each of its
    undecided votes with a placed view: each peak's first guess placed, and the pair matched again through the model
    that makes. The peak whose views agree best places the view, when their agreement reaches
    ``undecided_agreement`` and ``undecided_margin`` times that of any peak turning the view elsewhere (beyond
    ``RIVAL_TURN_DEG``: peaks of one shift smeared in the vote place it alike). 0 turns this off. Measured: the
    weakest real pair with its contrast halved (vote 1.18 times its rival) agrees at 0.40 and is placed (the
    capture's three turns then 0.5-1.9 degrees from the rig's mean); a left-right mirrored side view's peaks agree at
    0.11-0.18, another finger's at 0; synthetic views with every vote undecided at 0.65-1.0."""
    undecided_min_votes: int = 5
    """The votes a peak needs to be tried so (``MIN_SUPPORT``, 18, for a decisive vote): through the model, not the vote,
    decides. Measured on real captures cropped to no fingertip (docs/measurements.md): their front-side votes' right
    peaks hold 6-17 votes (2_2_7_1's 9 votes at -53.7 degrees agrees at 0.64, 2_2_6_1's 6 at -38.3 at 0.75, and each
    places its view; at 10 votes, before, both views were lost). Views of other fingers agreed at 0.04-0.10 and a
    mirrored view at 0.18 at best when tried at every turn of a grid; the 18 captures of two fingers' views, tried from
    5 votes and 20 matches, at 0.11 at best."""
    undecided_min_matches: int = 20
    """The verified first-guess matches such a peak needs to be grown and tried through the model (``min_matches``, 40,
    for a decisive vote): a narrow crop's right peak verified 26 matches, which its growth took to 136, agreeing at
    0.75."""
    undecided_agreement: float = 0.25
    """The agreement through the model a peak must reach to place a view no decisive vote placed: twice
    ``min_agreement``, above a mirrored view's 0.18 (one finger's views at full contrast: 0.27-0.86 on the real
    front-side pairs)."""
    undecided_floor: float = 0.2
    """Below ``undecided_agreement``, a peak still places the view when it agrees at least this much and at least
    ``undecided_share`` of the best agreement of the capture's registered pairs (through the model in hand): a capture
    whose every pair agrees low, as views of one finger, is judged by its own level. Just above a mirrored real view's
    0.196 at most (the level holds those) and above another finger's 0.14. Measured: phone-like photos of a long finger whose ridges cover a fifth of it in
    view (the rest skin that matches little), its registered pair agreeing at 0.228 and the third view's right peak
    at 0.234: placed, where at 0.25 alone it was left unregistered; mirrored real side views at most 0.27 of their
    capture's level (docs/measurements.md)."""
    undecided_share: float = 0.9
    """See ``undecided_floor``."""
    undecided_margin: float = 1.5
    """How many times better than any peak turning the view elsewhere the placing peak must agree."""
    weak_agreement_share: float = 0.35
    """After the first guided round, a view whose every pair agrees at less than this share of the capture's best pair
    is placed again as a view no decisive vote placed (``undecided_peaks``): its first guess may have been a decisive
    vote's wrong peak, grown into a few matches that still pass ``min_agreement``. The new place is kept when its
    agreement is ``undecided_margin`` times the old one (else the view stays where it was). 0 turns this off.
    Measured: synthetic fingers of sections unlike the prior's (``fs3d synth --shapes wide``, seed 6), a side view at
    0.19 beside a pair at 0.99, 20.7 degrees off and reported registered, re-placed by its vote's third peak at 0.999
    (0.45 degrees). Real dev captures, first round: every view's best pair at 0.53-0.79, at least 0.78 of the capture's
    best (cropped to no fingertip: 0.43-0.82, at least 0.61; made dark, ``tools/degrade_photos.py --kind dark``: at least
    0.53), so none is placed again."""
    undecided_zooms: tuple[float, ...] = (1.25, 0.8, 1.5, 2.0 / 3.0)
    """Besides its peaks, such a view is tried with its texture unwrapped at these scales against the placed view's
    (a photo taken nearer or farther than the others: from a quarter larger or smaller the vote's patches no longer
    correlate), each scale's decisive vote tried alike (``pairs[].placed_at_zoom`` in the report). () turns this
    off. Measured on synthetic uwa captures with one photo enlarged or shrunk (docs/measurements.md)."""
    short_end_tolerance: float = 0.10
    """Where the focal probe finds that the photos do not hold the focal (the loss flat toward a longer one), the
    alignment is re-fitted with the focal held at the shortest one whose loss is within this share of the fit's
    (:func:`~fingersplat3d.align.solve.sensitivity.short_end`; ``alignment.focal_probe.taken_share`` in the report):
    the fit's slide toward a nearly orthographic camera is the valley's drift, and the true focal was on the short side
    of it every time it was measured. Three views or more (``PIVOT_MIN_VIEWS``), and two views where
    ``two_view_short_end_rise`` says so. 0 keeps the fitted focal."""
    two_view_short_end_rise: float = 0.25
    """Two views take the short end only where the focal probe's shorter focal raised the loss by less than this share:
    the valley's short side flat, as perspective cameras give (the real rig's, 1.3 times the photo's long side; synthetic
    fingers at that scale), where a two-view fit slides 1.1-1.6 times long and turns 5-26 degrees too far; near-orthographic
    cameras' valleys are steep there (+32 to +87 %), their fits slide 0-16 % and walking them short costs degrees
    (docs/measurements.md, two views' focal). Measured: real pairs 17.8 / 16.0 -> 7.3 / 6.1 degrees, synthetic pairs at
    the real scale 8.1 / 10.3 -> 2.5 / 2.2; 640x512 synthetic, sections unlike the prior's and another group's renders
    unchanged. 0 keeps two views' fitted focal."""
    redraw_tolerance: float = 0.05
    """With a ``redraw`` callable, the pointmaps are drawn again when the fitted focal is further than this share
    from the one they were drawn with (closer, the perspective barely changes the relief)."""
    redraw_tilt_deg: float = 3.0
    """With a ``redraw`` callable, the pointmaps are also drawn again, each tilted in depth as the registered finger's
    axis runs, when it runs out of some view's photo plane by this many degrees or more (:mod:`.axis_tilt`; 0: never).
    Measured on another make's fingers pitched ±12° (3 views ±45°): the skin one view alone sees 0.43 -> 0.19 mm;
    level fingers and the real rig (0-6°, four captures of nine drawn tilted) within the fits' scatter. Three views
    or more (two are never redrawn: :func:`~fingersplat3d.align.register._redrawn`)."""
