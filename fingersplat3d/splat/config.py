"""Settings of the Gaussian-splat fit, and the ``fast`` / ``balanced`` / ``accurate`` presets.

Every knob is a dataclass field with a docstring; presets are instances, overridden with
:func:`dataclasses.replace` (``fs3d fuse --splat-preset fast --splat-iterations 500``). The figures
that chose the preset values are in the README (``tools/bench_splat.py``).
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

__all__ = ["SplatConfig", "PRESETS", "preset", "differences_from_preset", "DEFAULT_PRESET", "BACKENDS"]

BACKENDS = ("auto", "numba", "torch", "gsplat")
"""The rasterizer's backends (:func:`~fingersplat3d.splat.rasterize.rasterize`), here so that the settings, and the
parsers built from them, are read without torch."""


@dataclass(frozen=True)
class SplatConfig:
    """Fitting of Gaussians to the input photos (SH degree 0, 0.8 L1 + 0.2 D-SSIM inside the finger)."""

    preset: str = ""
    """The preset these settings started from (``fast``, ``balanced``, ``accurate``; empty: none),
    so that ``report.json`` can name it and list what differs from it."""
    iterations: int = 300
    """Optimisation steps; each step renders one input view (views are visited in shuffled rounds)."""
    lambda_dssim: float = 0.2
    """Weight of ``1 - SSIM`` in the loss (the paper's 0.2; L1 gets ``1 - lambda_dssim``)."""
    lambda_silhouette: float = 0.1
    """Weight of the mean rendered opacity outside the finger mask (keeps Gaussians off the background,
    so the mask cleaning has little to remove; 0 = photometric loss only)."""
    lambda_solid: float = 0.3
    """Weight of the mean rendered transparency (1 - opacity) on the finger: a solid finger shows nothing of what lies
    behind its skin. Fitted against a dark background, 3DGS skin stays 5-25 % see-through, and the unseen skin's
    Gaussians (:attr:`unseen_skin`) showed through it. Measured (docs/measurements.md): 0.3 keeps them hidden on real
    captures (training views within 0.5 dB of without them) and costs synthetic views 0.2-0.3 dB; 1.0 cost 0.6 dB."""
    lambda_depth: float = 10.0
    """Weight of the rendered depth's relative L1 distance to the geometry stage's depth, inside the
    mask (0 = free: the photos alone decide where the surface goes; measured worse, README)."""
    polish_fraction: float = 0.2
    """Steps after the mask cleaning, as a fraction of ``iterations`` (poses fixed, no densification):
    they repair what removing and splitting boundary Gaussians changed inside the finger."""
    coarse_fraction: float = 0.0
    """Steps at the start of the fit, as a fraction of ``iterations``, that compare renders at half the photos'
    resolution with the photos halved (area averaged; ridges of 8 px or more keep 4 px or more): the model's
    shape and colours settle at a quarter of the pixels' cost before the full-resolution steps refine them. A step
    costs ~60 % of a full one at 640x512, not 25 %: the per-Gaussian work (projection, tiling, the update) stays.
    Measured at 0.4 (docs/measurements.md, "The splat fit starts at half resolution"): the shipped sample's fit
    7.9-9.2 -> 6.6-7.2 s (``fast``) and 30.9-31.9 -> 26.3-27.2 s (``balanced``), a real 1280x1024 capture's 27-46 %
    shorter, training views within 0.25 dB; synthetic held-out views (``tools/bench_splat.py``) ``fast`` 32.7 -> 32.9 dB,
    ``balanced`` 32.8 -> 32.7 dB. ``accurate`` keeps every step at full resolution."""
    # --- model size -------------------------------------------------------------------------
    gaussians_per_cell: float = 1.0
    """Gaussian budget density: Gaussians per (quarter ridge period)^2 of finger area, summed over
    views and divided by ``view_overlap``. The budget caps the initial cloud and densification."""
    view_overlap: float = 1.5
    """How many views see an average skin point (turns summed per-view areas into surface area)."""
    min_gaussians: int = 2000
    """Floor of the budget (tiny images still get a model)."""
    max_gaussians: int = 400_000
    """Ceiling of the budget (memory)."""
    init_opacity: float = 0.5
    """Opacity of the initial Gaussians."""
    init_scale_factor: float = 0.7
    """Initial scale = this x mean distance to the 3 nearest neighbours."""
    flatten: float | None = 0.3
    """Initialise each Gaussian as a disc in the surface's tangent plane, this thick relative to its
    width (the scene is a skin surface); None = isotropic."""
    # --- learning rates (Adam, per parameter group) --------------------------------------------
    lr_means: float = 1e-3
    """Initial learning rate of the centres, times the scene extent (decays exponentially); 6x the
    3DGS default for a fit of hundreds of steps, not 30k. 4e-3 fitted the photos ~1 dB better but
    moved the surface off the true depth (tools/bench_splat.py, README)."""
    lr_means_final: float = 1e-5
    """Final learning rate of the centres, times the scene extent."""
    lr_scales: float = 0.02
    """Learning rate of the log scales."""
    lr_quats: float = 0.001
    """Learning rate of the quaternions."""
    lr_opacity: float = 0.1
    """Learning rate of the opacity logits."""
    lr_colors: float = 0.01
    """Learning rate of the SH DC coefficients (4x the 3DGS default). 0.05, set for fits of 100 steps, let each
    Gaussian's colour chase one view: at 0.01 real left-out views +0.5 dB on both fingers (with the exposures
    matched) and the synthetic held-out views +0.5-0.6 dB (docs/measurements.md, stop 68)."""
    # --- densification and pruning (3DGS's adaptive density control) ----------------------------
    densify_from: int = 100
    """First step that may densify."""
    densify_until_fraction: float = 0.6
    """Densification stops after this fraction of the iterations."""
    densify_every: int = 100
    """Steps between densify/prune passes."""
    grad_threshold: float = 0.0002
    """Mean view-space positional gradient (NDC units, as 3DGS) above which a Gaussian is densified."""
    percent_dense: float = 0.01
    """Gaussians larger than this fraction of the scene extent are split, smaller ones cloned."""
    prune_opacity: float = 0.005
    """Gaussians less opaque than this are removed."""
    prune_scale: float = 0.1
    """Gaussians larger than this fraction of the scene extent are removed."""
    # --- cameras -------------------------------------------------------------------------------
    refine_poses: bool = False
    """Jointly refine the camera poses (InstantSplat-style; the first view stays fixed). Off by default since stop 48:
    the registration's poses are already within a fraction of a degree, and the refinement's Adam steps, one view a
    step, kept them moving by about their own size to the end, so the views' ridges left the fit out of phase.
    Measured (``tools/bench_splat.py --seeds 5 --presets balanced``, synthetic ring 640x512): held-out PSNR 29.6 ->
    32.8 dB (every seed better, the worst 26.9 -> 31.8), training views' median 42.6 -> 45.2 dB, the Gaussians'
    depth 0.074 -> 0.059 mm; real captures' leave-one-view-out (``fs3d eval quality``, fast) the same within 0.1 dB
    (1_1_2_1 21.2 / 21.1, 2_2_8_1 18.0 / 17.9 dB, on / off); see docs/measurements.md, "Gaussian splatting"."""
    lr_pose_rotation: float = 1e-3
    """Learning rate of the pose corrections' axis-angle (radians)."""
    lr_pose_translation: float = 1e-3
    """Learning rate of the pose corrections' translation, times the scene extent."""
    # --- shading -------------------------------------------------------------------------------
    facing_shading: bool = True
    """Darken each Gaussian's colour by the cosine at which a camera sees it, to the power of the capture's
    exponent estimated from the registered geometry before the fit (:mod:`~fingersplat3d.splat.shading`);
    False: one colour per Gaussian whatever the view, the plain SH degree 0 model."""
    match_exposures: bool = True
    """Fit every photo at the fitted views' mean exposure: each divided by its exposure, estimated with the shading
    exponent from the skin two registered views see (:mod:`~fingersplat3d.splat.shading_estimate`), so that the
    Gaussians' colours are the skin at one exposure, not a compromise between cameras that differ by 5-15 % on the
    real captures. A view rendered to look like its photo is multiplied by its exposure
    (:meth:`~fingersplat3d.splat.shading_estimate.ShadingEstimate.gains`). Measured (docs/measurements.md): real
    left-out views +0.4 dB (held-out finger) and +1.5 dB (the finger the splat settings were tuned on)."""
    # --- completion ------------------------------------------------------------------------------
    unseen_skin: bool = True
    """After the fit, add Gaussians on the skin next to the fitted views' surface that none of them sees
    (:mod:`fingersplat3d.unseen_skin`: each ring's circle carried past its seen arc; in the nearest fitted skin's
    tone, held still in the polish): a left-out view or a new view past the cameras shows that skin, which a fit of
    the seen surface alone leaves as a hole."""
    # --- rendering -----------------------------------------------------------------------------
    near_fraction: float = 0.01
    """Near plane as a fraction of the camera-to-finger distance."""
    rasterizer: str = "auto"
    """Rasterizer backend while fitting (:func:`~fingersplat3d.splat.rasterize.rasterize`): ``auto``
    (the compiled ``numba`` kernels on the CPU; on a GPU gsplat's kernels when installed, else ``torch``),
    ``numba``, ``torch`` or ``gsplat``."""
    seed: int = 0
    """Seed of the view order and of densification."""

    def __post_init__(self) -> None:
        if self.rasterizer not in BACKENDS:
            raise ValueError(f"SplatConfig.rasterizer must be one of {', '.join(BACKENDS)}, got {self.rasterizer!r}")
        if self.iterations < 0:
            raise ValueError("SplatConfig.iterations must be >= 0")
        if not 0.0 <= self.lambda_dssim <= 1.0:
            raise ValueError("SplatConfig.lambda_dssim must be in [0, 1]")
        if not self.lambda_solid >= 0.0:
            raise ValueError("SplatConfig.lambda_solid must be >= 0")
        if not 0.0 <= self.polish_fraction <= 1.0:
            raise ValueError("SplatConfig.polish_fraction must be in [0, 1]")
        if not 0.0 <= self.coarse_fraction < 1.0:
            raise ValueError("SplatConfig.coarse_fraction must be in [0, 1)")
        if self.gaussians_per_cell <= 0 or self.min_gaussians < 1 or self.max_gaussians < self.min_gaussians:
            raise ValueError("SplatConfig: the Gaussian budget settings must be positive and min <= max")

    @property
    def densify_until(self) -> int:
        return int(self.iterations * self.densify_until_fraction)

    @property
    def polish_iterations(self) -> int:
        return int(self.iterations * self.polish_fraction)


PRESETS: dict[str, SplatConfig] = {
    "fast": SplatConfig(preset="fast", iterations=100, gaussians_per_cell=0.6, densify_from=50, densify_every=50,
                        coarse_fraction=0.4),
    "balanced": SplatConfig(preset="balanced", iterations=300, gaussians_per_cell=1.0, densify_from=100, densify_every=100,
                            coarse_fraction=0.4),
    "accurate": SplatConfig(preset="accurate", iterations=1000, gaussians_per_cell=1.5, densify_from=200, densify_every=100),
}
DEFAULT_PRESET = "balanced"


def preset(name: str, **overrides) -> SplatConfig:
    """The named preset with any fields overridden; unknown names or fields are a clear error."""
    if name not in PRESETS:
        raise ValueError(f"unknown splat preset {name!r}; available: {', '.join(PRESETS)}")
    known = {f.name for f in fields(SplatConfig)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise ValueError(f"unknown splat setting(s) {', '.join(unknown)}")
    return replace(PRESETS[name], **{k: v for k, v in overrides.items() if v is not None and k != "preset"})


def differences_from_preset(config: SplatConfig) -> dict:
    """The settings of ``config`` that differ from its preset's (all of them when it names none)."""
    base = PRESETS.get(config.preset)
    return {f.name: getattr(config, f.name) for f in fields(SplatConfig)
            if f.name != "preset" and (base is None or getattr(config, f.name) != getattr(base, f.name))}
