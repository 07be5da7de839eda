"""The end-to-end ``fs3d fuse`` geometry run: pointmaps → pairwise → global alignment → ICP → fusion.

Configured by dataclasses (:class:`FuseConfig`); returns a :class:`Reconstruction` in memory, which
:func:`write_reconstruction` writes as the reconstruction folder of the design (fused.ply,
cameras.json, depth/, mesh.ply, report.json).
"""
from __future__ import annotations

import platform
import resource
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from . import __version__
from .align.register import RegistrationConfig, register_views
from .align.solve.global_opt import GlobalAlignment, global_align
from .align.solve.icp import ICPConfig, refine_poses
from .align.solve.rig import Rig, RigCapture
from .align.transfer import MIN_PARALLAX_DEG, backed_shares, multi_view_backing
from .alignment_status import alignment_status, warn
from .device import per_item, resolve_device
from .errors import InputError
from .sampling import map_on_grid
from .scene import Camera, Capture, View
from .splat.config import DEFAULT_PRESET, PRESETS, SplatConfig
from .splat.voting import CleanConfig
from .working_scale import RIDGE_PX, SPLAT_RIDGE_PX, TUNED_PX_PER_RIDGE, WorkingScale, working_views

__all__ = ["FuseConfig", "Reconstruction", "fuse", "cloud_of_views", "unseen_skin_of", "write_reconstruction", "MIN_VIEWS",
           "refuse_focal_with_rig"]

MIN_VIEWS = 1  # one image is allowed: it is fused with itself (the paper's monocular mode)
EXIF_FOCAL_AGREEMENT = 0.02
"""The views' EXIF focal lengths (photo pixels) must agree within this share to be used: one camera at one zoom."""


@dataclass(frozen=True)
class FuseConfig:
    """Settings of ``fs3d fuse`` (geometry)."""

    backend: str = "prior"
    """Pointmap backend name (``prior`` needs no weights; ``dust3r`` needs ``checkpoint``)."""
    checkpoint: str | None = None
    """Weights of a learned backend (``dust3r``: a DUSt3R .pth checkpoint); never downloaded."""
    device: str = "auto"
    """Where the learned backend and the splat fit run: ``auto`` (CUDA when available, else CPU), ``cpu``,
    ``cuda``, ``cuda:N``."""
    pair_batch: int = 4
    """Image pairs a learned backend decodes at once."""
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    """Correspondences, pair similarities and the global alignment (:mod:`fingersplat3d.align.register`)."""
    icp: bool = False
    """Refine poses with Open3D ICP after the global alignment. Off by default: a finger is nearly a
    cylinder, and ICP slides about its axis: on exact geometry it moved views by 1-16 degrees
    (tools/bench_fuse.py, README); its guard rejects such updates, so it only costs time."""
    icp_config: ICPConfig = field(default_factory=ICPConfig)
    """ICP settings."""
    min_confidence: float = 0.05
    """Pointmap confidence below which pixels are left out of the fused cloud."""
    voxel: float = 0.002
    """Voxel of the fused cloud, as a fraction of its extent (0 = keep every point)."""
    ridge_px: float | None = RIDGE_PX
    """Working pixels per ridge period of the geometry: photos that sample the ridges more finely are scaled down for
    the masks, pointmaps, registration and alignment, and the outputs put back on the photos' grid
    (:mod:`fingersplat3d.working_scale`); None: the photos' own resolution."""
    splat_ridge_px: float | None = SPLAT_RIDGE_PX
    """Working pixels per ridge period of the splat fit (None: the photos' own resolution): the geometry's cameras and
    depth maps are carried onto its grid, so that the fit sees the ridges as the camera sampled them."""
    focal_px: float | None = None
    """The cameras' focal length in the photos' pixels, when known (one camera model for every view): the pointmaps
    are made with it and the alignment keeps it instead of fitting one. Two views cannot fix the focal themselves
    (their optical axes meet at the finger), and their turn follows it: on the real dev captures two views alone
    turned 5-17 degrees off with the focal fitted (taken at the short end of its valley), 1-5 with it given
    (docs/measurements.md, real captures)."""
    view_focals_px: tuple[float, ...] | None = None
    """Each view's focal in its photo's pixels, when known view by view and not alike (photos whose EXIF records other
    zooms): the pointmaps are made with them and the alignment keeps each. ``focal_px`` takes precedence."""
    exif_focal: bool = True
    """Take the focal the photos' EXIF records (:mod:`~fingersplat3d.io.exif`: phones and cameras write it) as
    known, like ``focal_px``, when every view has one, the ``prior`` backend is used, and neither ``focal_px`` nor a
    rig gives the focal: one for all when they agree within :data:`EXIF_FOCAL_AGREEMENT` (one camera, one zoom), else
    each view its own (``view_focals_px``: another zoom, another phone)."""
    px_per_mm: float | None = None
    """Metric hint: image pixels per millimetre at the finger (first view)."""
    finger_width_mm: float | None = None
    """Metric hint: the finger's width in mm (used when px_per_mm is not given)."""
    mesh: bool = False
    """Also build a triangle mesh (Poisson, cleaned with pymeshlab)."""
    splat: SplatConfig | None = field(default_factory=lambda: PRESETS[DEFAULT_PRESET])
    """Fit Gaussians to the photos on top of the fused cloud (None = geometry only, ``--no-splat``)."""
    clean: CleanConfig = field(default_factory=CleanConfig)
    """Multi-view mask voting and boundary decomposition of the fitted Gaussians."""


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """What ``fuse`` produced, in memory."""

    capture: Capture  # the input views, with the masks that were used
    cameras: list[Camera]
    depths: list[np.ndarray]  # [H, W] float32 per view, NaN off the finger
    confidences: list[np.ndarray]
    cloud: object  # open3d.geometry.PointCloud
    units: str
    scale_mm_per_unit: float | None
    report: dict
    mesh: object | None = None
    gaussians: object | None = None  # fingersplat3d.splat.Gaussians (cleaned), when the splat stage ran
    splat_depths: list[np.ndarray] | None = None  # [H, W] expected depth of the Gaussians per view
    backing: list[np.ndarray | None] | None = None
    """Per view, where a second view backs its surface (:func:`~.align.transfer.multi_view_backing`, at the
    resolution the geometry worked at; None for a view not aligned), as the report's shares were counted; None:
    not computed (``overview.png`` then computes it)."""

    @property
    def registered(self) -> bool:
        """Whether every view was registered with the others (or there was nothing to register:
        one view, or identical images, the paper's monocular mode)."""
        return bool(self.report["alignment"]["ok"])


class _Stages:
    """Per-stage wall time and peak memory for the report."""

    def __init__(self) -> None:
        self.records: dict[str, dict] = {}

    @contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        from .heap import release_free_memory

        start = time.perf_counter()
        yield
        peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        release_free_memory()  # what the stage freed, back to the system before the next one
        self.records[name] = {"seconds": round(time.perf_counter() - start, 3), "peak_rss_mb": round(peak_kb / 1024, 1)}


def _at_working_scale(capture: Capture, ridge_px: float | None, factor: float | None = None, windows: bool = False
                      ) -> tuple[Capture, Capture, WorkingScale]:
    """(the photos with their masks, the same at the working resolution, the scale between them); ``windows``: large
    photos whose finger covers little of them cut to a window round it (:mod:`~fingersplat3d.working_window`)."""
    photo, working, scale = working_views(capture.views, ridge_px, factor, windows)
    return Capture(tuple(photo), capture.metadata), Capture(tuple(working), capture.metadata), scale


def _swollen(capture: Capture) -> list[str]:
    """A sentence for each view whose mask swells well past the finger's width somewhere
    (:func:`~.segment.silhouette.outline_swell`): something beside the finger, of the skin's colour and touching it,
    was kept in the mask, and the view's outline then misleads its turns (phone-like photos on clutter: 10 degrees off,
    docs/measurements.md, stop 88). On the working masks, the outlines the geometry uses (a 20-megapixel photo's own
    mask took 0.76 s a view, its working copy at a quarter of the side 0.02 s)."""
    from .segment.silhouette import OUTLINE_SWELL, outline_swell

    said = []
    for view in capture.views:
        swell = outline_swell(view.mask) if view.mask is not None else None
        if swell is not None and swell > OUTLINE_SWELL:
            said.append(f"view {view.name!r}: its finger mask is {swell:.1f} times the finger's width at its widest: "
                        "something touching the finger may have been taken for it, and the turns to this view can be "
                        "far off; a plainer background, or the finger apart from what it touches, avoids it")
    return said


def _ridgeless(photos: Capture, scale: WorkingScale) -> list[str]:
    """A sentence for each view whose photo shows no ridges (out of focus, blurred: its ridge period, measured for the
    working resolution, is missing or coarser than a finger has; :func:`~.align.correspond.texture.no_ridges`): the
    registration works on ridges, so such a view is unlikely to register, and the user should know why. None
    measured (``--ridge-px 0``): no sentence."""
    from .align.correspond.texture import no_ridges
    from .segment.silhouette import widest_disc

    said = []
    for view, period in zip(photos.views, scale.view_periods_px):
        why = no_ridges(period, widest_disc(view.mask))
        if why is not None:
            said.append(f"view {view.name!r}: {why}; the registration works on the ridges")
    return said


def _in_working_pixels(config: FuseConfig, scale: WorkingScale) -> FuseConfig:
    """``config`` with the alignment's robust scale made the working resolution's: the same share of a ridge period
    as at the resolution it was tuned at (:data:`~fingersplat3d.working_scale.TUNED_PX_PER_RIDGE`), so that the fit
    weighs its matches against its priors alike at any resolution. Photos used as they are keep it."""
    if config.focal_px is not None:  # a known focal: in working pixels, and held
        align = replace(config.registration.global_align, optimize_focal=False)
        config = replace(config, focal_px=config.focal_px * scale.factor, view_focals_px=None,
                         registration=replace(config.registration, global_align=align))
    elif config.view_focals_px is not None:  # each view's own: in working pixels, each held
        align = replace(config.registration.global_align, optimize_focal=False, shared_focal=False)
        focals = tuple(f * scale.view_factor(v) for v, f in enumerate(config.view_focals_px))
        config = replace(config, view_focals_px=focals,
                         registration=replace(config.registration, global_align=align))
    if scale.factor == 1.0:
        return config
    align = config.registration.global_align
    per_ridge = scale.period_px / TUNED_PX_PER_RIDGE if np.isfinite(scale.period_px) else 1.0  # else a photo pixel
    robust = align.robust_px * scale.factor * per_ridge
    return replace(config, registration=replace(config.registration, global_align=replace(align, robust_px=robust)))


def _on_photo_grid(photos: Capture, scale: WorkingScale, cameras: list[Camera], maps: Sequence[list[np.ndarray] | None],
                   report: dict, backing: list[np.ndarray | None] | None = None) -> tuple[list[Camera], list, list | None]:
    """Cameras and per-view maps of the working resolution put back on the photos' pixel grid (a windowed view's
    outside its window: NaN, and its camera's principal point moved back to the photo's centre); ``backing``:
    :func:`~.align.transfer.multi_view_backing`'s maps, put back at their own stride (-1 outside a window)."""
    sizes = [(view.width, view.height) for view in photos.views]
    if scale.factor == 1.0 and not scale.windowed and not scale.regrown:
        return cameras, list(maps), backing
    regions = scale.region_sizes(sizes)
    grow = [region[0] / camera.width for camera, region in zip(cameras, regions)]
    cameras = [camera.resized(region) for camera, region in zip(cameras, regions)]
    cuts = [view.mask if scale.window(v) is None else scale.window(v).cut(view.mask)
            for v, view in enumerate(photos.views)]
    out = [None if views is None else [map_on_grid(values, region, mask)
                                       for values, region, mask in zip(views, regions, cuts)] for views in maps]
    for v in range(len(photos)):
        window = scale.window(v)
        if window is not None:
            cameras[v] = window.camera_on_photo(cameras[v])
            for views in out:
                if views is not None:
                    views[v] = window.padded(views[v])
            if backing is not None and backing[v] is not None:
                backing[v] = _backing_on_photo(backing[v], window)
    alignment = report.get("alignment", {})
    if alignment.get("focals_px") is not None:
        alignment["focals_px"] = [float(f) * g for f, g in zip(alignment["focals_px"], grow)]
    registration = report.get("registration", {})
    if registration.get("pointmaps_redrawn_at_px") is not None:  # one focal for all views: the first view's growth
        registration["pointmaps_redrawn_at_px"] = float(registration["pointmaps_redrawn_at_px"]) * grow[0]
    return cameras, out, backing


def _backing_on_photo(backing: np.ndarray, window) -> np.ndarray:
    """A windowed view's backing map (its window's pixels at a stride) as the photo's at about the same stride."""
    import cv2

    stride = window.width / backing.shape[1]
    inside = (max(1, round(window.width / stride)), max(1, round(window.height / stride)))
    whole = cv2.resize(backing, inside, interpolation=cv2.INTER_NEAREST)
    out = np.full((max(1, round(window.photo_height / stride)), max(1, round(window.photo_width / stride))), -1, np.int8)
    top, left = round(window.top / stride), round(window.left / stride)
    rows, cols = min(inside[1], out.shape[0] - top), min(inside[0], out.shape[1] - left)
    out[top:top + rows, left:left + cols] = whole[:rows, :cols]
    return out


def _on_splat_grid(photos: Capture, capture: Capture, scale: WorkingScale, ridge_px: float | None, cameras: list[Camera],
                   maps: Sequence[list[np.ndarray]], report: dict) -> tuple[Capture, WorkingScale, list[Camera], list, list[float]]:
    """The working capture, its cameras and per-view maps carried from the geometry's grid onto the splat fit's
    (``ridge_px`` working pixels per ridge, :data:`~fingersplat3d.working_scale.SPLAT_RIDGE_PX` by default; in the
    windows of :func:`_splat_windows`), with that grid's scale and each view's growth (its pixels per geometry pixel);
    as they are where the two grids are one."""
    sizes = [(view.width, view.height) for view in photos.views]
    boxes = _splat_windows(photos, scale)
    fit = replace(scale, windows=boxes).at(ridge_px, sizes)
    if boxes == scale.windows:
        if fit.factor == scale.factor:
            return capture, scale, cameras, list(maps), [1.0] * len(cameras)
        views = (list(photos.views) if fit.factor == 1.0 and not scale.windowed and not fit.regrown
                 else working_views(photos.views, None, fit.factor, scale.windows, scale.growth)[1])
        grow = [view.width / camera.width for view, camera in zip(views, cameras)]
        cameras = [camera.resized((view.width, view.height)) for camera, view in zip(cameras, views)]
        maps = [[map_on_grid(values, (view.width, view.height), view.mask) for values, view in zip(per_view, views)]
                for per_view in maps]
    else:  # through the photo's grid, from the geometry's windows to the fit's
        views = working_views(photos.views, None, fit.factor, boxes, scale.growth)[1]
        regions, fitted = scale.region_sizes(sizes), fit.region_sizes(sizes)
        grow = [view.width / box[0] * region[0] / camera.width
                for view, box, region, camera in zip(views, fitted, regions, cameras)]
        on_photo, maps, _ = _on_photo_grid(photos, scale, cameras, maps, {})
        cameras = [(camera if box is None else box.camera_in_window(camera)).resized((view.width, view.height))
                   for camera, box, view in zip(on_photo, boxes, views)]
        maps = [[map_on_grid(values if box is None else box.cut(values), (view.width, view.height), view.mask)
                 for values, box, view in zip(per_view, boxes, views)] for per_view in maps]
    registration = report.get("registration", {})
    if registration.get("pointmaps_redrawn_at_px") is not None:  # one focal for all views: the first view's growth
        registration["pointmaps_redrawn_at_px"] = float(registration["pointmaps_redrawn_at_px"]) * grow[0]
    return Capture(tuple(views), capture.metadata), fit, cameras, maps, grow


def _splat_windows(photos: Capture, scale: WorkingScale) -> tuple:
    """Each view's window for the splat fit: where the geometry worked in a window about the photo's centre, round the
    finger's own box (:func:`~.working_window.box_window`: the fit takes the cameras as given, so the principal point
    need not stay the window's centre; a long finger in a phone's photo fitted on 55 % of the pixels, in half the
    time), else the geometry's."""
    from .working_window import box_window

    if not scale.windowed:
        return scale.windows
    return tuple(None if scale.window(v) is None else box_window(view.mask, (view.width, view.height)) or scale.window(v)
                 for v, view in enumerate(photos.views))


def _backend(config: FuseConfig):
    """The pointmap backend, given only the options it takes (weights options go to learned backends)."""
    from .pointmaps import get_backend

    if config.backend == "dust3r":
        if config.focal_px is not None:
            raise InputError("a known focal (--focal-px) is used by the prior backend; the dust3r backend's pointmaps "
                             "come with the focal its network predicts")
        return get_backend("dust3r", checkpoint=config.checkpoint, device=config.device, batch_size=config.pair_batch)
    if config.checkpoint is not None:
        raise InputError(f"a checkpoint is only used by the dust3r backend, not by {config.backend!r}")
    if config.focal_px is not None:
        return get_backend(config.backend, focal_px=config.focal_px)
    if config.view_focals_px is not None:
        return get_backend(config.backend, view_focals_px=tuple(config.view_focals_px))
    return get_backend(config.backend)


NO_PARALLAX_SHARE = 0.05
"""Registered views of which none has this share of its surface seen by another from :data:`MIN_PARALLAX_DEG` away are
warned about: their registration holds, their depth is the prior's."""

SAME_PICTURE = 0.05
"""Two images of one size whose difference (RMS) is under this share of the first's own spread are the same picture:
one photo given twice, as a copy, in another format or re-encoded (measured on a real 1280x1024 photo: JPEG again at
quality 95 / 60 0.002 / 0.025, saved at 16 bits 0.004, noise of 2 grey levels added 0.039), where another shot of the
finger differs by its ridges (the same photo moved by one pixel 0.065, CFPose-style rolls 10 degrees apart 0.23-0.40,
the real rig's cameras 0.53)."""


RESIZED_COPY = 0.02
"""Images whose sides differ by more than this share, both by one factor (to the pixel), are compared at the smaller's
size for :data:`SAME_PICTURE`: a copy at another size (a thumbnail, a photo exported smaller); a crop of a row or two is
another picture."""


def _same_picture(a: np.ndarray, b: np.ndarray) -> bool:
    """See :data:`SAME_PICTURE` and :data:`RESIZED_COPY`."""
    if a.shape != b.shape:
        if a.shape[0] * a.shape[1] > b.shape[0] * b.shape[1]:
            a, b = b, a  # a the smaller
        (rows_a, cols_a), (rows_b, cols_b) = a.shape[:2], b.shape[:2]
        across, down = cols_a / cols_b, rows_a / rows_b  # the shrink factors, each to the pixel
        if (a.shape[2:] != b.shape[2:] or across > 1.0 - RESIZED_COPY
                or abs(across - down) > 1.0 / min(rows_b, cols_b)):
            return False
        import cv2

        b = cv2.resize(np.asarray(b, np.float32), (cols_a, rows_a), interpolation=cv2.INTER_AREA)
    spread = float(np.std(a))
    if spread == 0.0:
        return bool(np.array_equal(a, b))
    return bool(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)) <= SAME_PICTURE * spread)


def _distinct_pairs(capture: Capture, copies: dict[int, int] | None = None) -> list[tuple[int, int]]:
    """View pairs ``a < b`` that are not the same picture (:data:`SAME_PICTURE`): one photo twice has no parallax, the
    paper's monocular mode. ``copies``: :func:`_copies` of the capture (or of its photos), when already found."""
    copies = _copies(capture) if copies is None else copies
    picture = [copies.get(v, v) for v in range(len(capture))]  # each view's first copy of its picture
    return [(a, b) for a in range(len(capture)) for b in range(a + 1, len(capture)) if picture[a] != picture[b]]


def _copies(capture: Capture) -> dict[int, int]:
    """Each view that is the same picture (:data:`SAME_PICTURE`) as an earlier view, to that view's index."""
    views, copies = capture.views, {}
    for b in range(len(views)):
        for a in range(b):
            if a not in copies and _same_picture(views[a].image, views[b].image):
                copies[b] = a
                break
    return copies


def _fused_once(capture: Capture, copies: dict[int, int], config: FuseConfig | None, progress: bool) -> Reconstruction:
    """The capture fused with each picture once: a copy of a photo beside other photos adds no view of the finger, and
    as a view of its own it made a two-place capture fit as a three-view one (a real pair's turn 20° off, against 5°
    for the two photos alone). The copies are named in a warning and in ``report["same_picture_as"]``."""
    names, said = capture.names, {}
    for b, a in copies.items():
        warn(said, f"view {names[b]!r} is the same picture as view {names[a]!r} (a copy, re-encoded or resized): it "
                   f"is fused once, as {names[a]!r}; a copy adds no view of the finger")
    kept = Capture(tuple(view for v, view in enumerate(capture.views) if v not in copies), capture.metadata)
    result = fuse(kept, config, progress)
    result.report["warnings"] = said["warnings"] + result.report.get("warnings", [])
    result.report["same_picture_as"] = {names[b]: names[a] for b, a in copies.items()}
    return result


def _pointmaps(capture: Capture, pairs: list[tuple[int, int]], config: FuseConfig, report: dict):
    """Own-frame pointmaps of every view and, from a pairwise backend, the ``pairs``' pointmaps (else None)."""
    backend = _backend(config)
    pointmaps = backend.predict_views(capture.views)
    for pointmap, view in zip(pointmaps, capture.views):
        if not np.any(pointmap.valid & view.mask):
            raise InputError(f"view {view.name!r}: the {config.backend} backend gave no finite 3D point on the finger")
    pair_pointmaps = None
    if hasattr(backend, "predict_pairs"):  # learned pairwise pointmaps replace image matching
        pair_pointmaps = {(p.i, p.j): p for p in backend.predict_pairs(capture.views, pairs)} if pairs else {}
    if getattr(backend, "stats", None):
        report["pointmap_inference"] = [asdict(record) for record in backend.stats]
    return pointmaps, pair_pointmaps


def _with_exif_focal(capture: Capture, config: FuseConfig, rig: Rig | None, report: dict) -> FuseConfig:
    """``config`` with the focal the views' EXIF records (:attr:`FuseConfig.exif_focal`), said in ``report["exif_focal"]``
    (``used``, ``focal_px``, per view where it came from or why not), when the capture's loader read one."""
    found = capture.metadata.get("exif_focal")
    if not found:  # a capture not read from photo files (a capture folder, an array)
        return config
    views = {name: found.get(name, {}).get("how", "not read") for name in capture.names}
    values = [found.get(name, {}).get("focal_px") for name in capture.names]
    record = {"used": False, "focal_px": None, "views": views}
    report["exif_focal"] = record
    reasons = ((not config.exif_focal, "--no-exif-focal"), (config.focal_px is not None, "--focal-px gives the focal"),
               (rig is not None, "the rig gives the focal"),
               (config.backend != "prior", "a learned backend brings its own focal"),
               (any(v is None for v in values), "not every view's EXIF records one"))
    why_not = next((reason for applies, reason in reasons if applies), None)
    if why_not:
        record["why_not"] = why_not
        return config
    if max(values) > (1.0 + EXIF_FOCAL_AGREEMENT) * min(values):  # another zoom or another camera: each its own
        record.update(used=True, focals_px={name: float(value) for name, value in zip(capture.names, values)},
                      per_view=f"the views' EXIF focal lengths differ ({min(values):.0f}-{max(values):.0f} px: another "
                               "zoom): each view keeps its own")
        return replace(config, view_focals_px=tuple(float(value) for value in values))
    focal = float(np.median(values))
    record.update(used=True, focal_px=focal)
    return replace(config, focal_px=focal)


def _redraw(capture: Capture, config: FuseConfig):
    """The views' pointmaps drawn again through a given focal (None: the one they were drawn with) and with given
    tilts, for :func:`~fingersplat3d.align.register.register_views`, where the backend is the prior; else None (a
    learned backend's pointmaps come with their own focal and shape). The registration asks for a focal only where it
    fitted one: a known focal is held in its alignment (:func:`_in_working_pixels`), so it is never redrawn."""
    if config.backend != "prior":
        return None
    backend = _backend(config)

    def redraw(focal: float | None, tilts: list | None):
        moved = {} if focal is None else {"focal_px": float(focal)}
        return replace(backend, **moved, view_tilts=None if tilts is None else tuple(tilts)).predict_views(capture.views)
    return redraw


def _register(capture: Capture, pairs: list[tuple[int, int]], pointmaps, pair_pointmaps, config: FuseConfig,
              report: dict, say, rig: Rig | None = None, period_px: float | None = None) -> tuple[GlobalAlignment, list]:
    """Pair relations of the distinct ``pairs`` and the global alignment: image correspondences, or the
    backend's pairwise pointmaps. Also the pointmaps the alignment stands on (redrawn at its focal, or as given)."""
    identical = [{"a": capture.views[a].name, "b": capture.views[b].name, "ok": False,
                  "reason": "identical images (the same picture, or a copy of it re-encoded): no parallax (monocular mode)"}
                 for a in range(len(capture)) for b in range(a + 1, len(capture)) if (a, b) not in pairs]
    if pair_pointmaps is None:
        registration = register_views(capture.views, pointmaps, config.registration, pairs, progress=say, rig=rig,
                                      period_px=period_px, redraw=_redraw(capture, config))
        report["pairs"] = registration.pairs + identical
        report["registration"] = {"ridge_period_px": round(registration.period_px, 2), "guided_rounds": registration.rounds,
                                  "turn_changes_deg": registration.turn_changes_deg,
                                  "tip": {view.name: tip for view, tip in zip(capture.views, registration.tips)},
                                  "photometric": registration.photometric,
                                  "pointmaps_redrawn_at_px": registration.redrawn_at_px,
                                  "axis_tilt_deg": {view.name: None if tilt is None else round(tilt, 2)
                                                    for view, tilt in zip(capture.views, registration.axis_tilts_deg)},
                                  "pointmaps_tilted": registration.tilted}
        return registration.alignment, registration.pointmaps
    if rig is not None:
        raise InputError("a rig (--rig) is used with image correspondences; the dust3r backend's pairwise pointmaps "
                         "do not take one")
    from .align.solve.pointmap_pairs import register_pointmap_pair

    rng = np.random.default_rng(config.registration.seed)
    registered, records = [], []
    views = capture.views
    for a, b in pairs:
        result = register_pointmap_pair(pointmaps[a], pointmaps[b], pair_pointmaps[(a, b)], pair_pointmaps.get((b, a)),
                                        mask_a=views[a].mask, mask_b=views[b].mask, rng=rng)
        records.append({"a": views[a].name, "b": views[b].name, "method": "pointmaps", "ok": result.ok,
                        "reason": result.reason, "correspondences": result.n_correspondences,
                        "residual": float(result.residual)})
        if result.ok:
            registered.append(result.correspondences)
    report["pairs"] = records + identical
    return global_align([pm.depth for pm in pointmaps], [pm.focal for pm in pointmaps], registered,
                        config.registration.global_align), pointmaps


def refuse_focal_with_rig(focal_px: float | None, rig: Rig | None) -> None:
    """A known focal and a rig cannot both hold the cameras' focal: one sentence, before any work."""
    if focal_px is not None and rig is not None:
        raise InputError("a rig (--rig) holds its own focal; leave out --focal-px")


def _check_rig(capture: Capture, rig: Rig) -> None:
    if len(capture) != len(rig.names):
        raise InputError(f"the rig has {len(rig.names)} cameras ({', '.join(rig.names)}) but the capture has "
                         f"{len(capture)} views ({', '.join(capture.names)})")
    for v, view in enumerate(capture.views):
        try:
            rig.turns_for(v, (view.width, view.height))
        except ValueError as error:
            raise InputError(f"view {view.name!r}: {error}") from None


def register_capture(capture: Capture, config: FuseConfig | None = None, rig: Rig | None = None,
                     factor: float | None = None) -> RigCapture:
    """A capture up to its registration (masks, pointmaps, correspondences, its own alignment): what a
    rig calibration (:func:`~fingersplat3d.align.solve.rig.calibrate_rig`) pools. With ``rig``, the
    guided matching runs through that rig's model (a calibration's re-matching round).

    ``factor``: the working resolution to use (every capture of a calibration must share one: the focal lengths
    it pools are in working pixels); None measures it. The result's sizes are the photos' own, its focal
    lengths, depths and correspondences the working resolution's."""
    config = FuseConfig() if config is None else config
    if rig is not None:
        _check_rig(capture, rig)
    photos, capture, scale = _at_working_scale(capture, config.ridge_px, factor)
    rig = None if rig is None else rig.scaled(scale.factor)
    config = _in_working_pixels(config, scale)
    pairs = _distinct_pairs(capture)
    pointmaps, _ = _pointmaps(capture, pairs, config, {})
    registration = register_views(capture.views, pointmaps, config.registration, pairs, rig=rig,
                                  period_px=scale.working_period_px(), redraw=_redraw(capture, config))
    pointmaps = registration.pointmaps
    seed = capture.metadata.get("seed")
    name = str(capture.metadata.get("name") or ("_".join(capture.names) + ("" if seed is None else f"_seed{seed}")))
    return RigCapture(name, [pm.depth for pm in pointmaps], [pm.focal for pm in pointmaps], registration.correspondences,
                      registration.alignment, [(view.width, view.height) for view in photos.views], tuple(capture.names),
                      contours=registration.contours)


def _refine_with_icp(capture: Capture, cameras: list[Camera], clouds: list, aligned: list[int], root: int,
                     config: FuseConfig, report: dict) -> None:
    """Open3D ICP on the aligned views' clouds (guarded); updates ``cameras`` and ``clouds`` in place."""
    icp = refine_poses([clouds[v] for v in aligned], config.icp_config, fixed=aligned.index(root))
    for k, v in enumerate(aligned):
        if icp.accepted[k]:
            cam_to_world = icp.corrections[k] @ cameras[v].cam_to_world
            cameras[v] = Camera(cameras[v].K, np.linalg.inv(cam_to_world), cameras[v].width, cameras[v].height)
            clouds[v].transform(icp.corrections[k])
    report["icp"] = {capture.views[v].name: {"accepted": icp.accepted[k], "fitness": icp.fitness[k],
                                             "rmse": icp.rmse[k], "note": icp.notes[k]} for k, v in enumerate(aligned)}


def _fused_cloud(clouds: list, cameras: list[Camera], aligned: list[int], voxel: float):
    """One Open3D cloud of the aligned views: voxel-thinned, outliers removed, normals facing the cameras (the views'
    depth-map normals, :func:`~fingersplat3d.scene.depth_normals`, averaged in each voxel)."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud()
    for v in aligned:
        cloud += clouds[v]
    if len(cloud.points) < 10:
        raise InputError("the fused point cloud is empty: no view produced usable depth")
    extent = float(np.linalg.norm(cloud.get_max_bound() - cloud.get_min_bound()))
    if voxel > 0 and extent > 0:
        cloud = cloud.voxel_down_sample(voxel * extent)
    cloud, _ = cloud.remove_statistical_outlier(nb_neighbors=20, std_ratio=3.0)
    if cloud.has_normals() and np.all(np.linalg.norm(np.asarray(cloud.normals), axis=1) > 1e-6):
        cloud.normalize_normals()  # the views' own, averaged (and so shortened) by the voxels
    else:  # none (or opposite ones met in a voxel): searched for
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.02 * extent, max_nn=30))
    _orient_outward(cloud, cameras, aligned)
    return cloud


def unseen_skin_of(cloud, views: Sequence[View], cameras: Sequence[Camera], fitted: Sequence[int], config):
    """The skin next to ``cloud`` that none of ``views[fitted]`` sees, for the splat stage to complete the model with
    (:class:`fingersplat3d.unseen_skin.UnseenSkin`); None when ``config.unseen_skin`` is off or there is none."""
    if not config.unseen_skin:
        return None
    from .unseen_skin import unseen_skin_of_cloud

    return unseen_skin_of_cloud(cloud, [cameras[v] for v in fitted], [views[v].mask for v in fitted])


def cloud_of_views(result: Reconstruction, views: Sequence[int], min_confidence: float = 0.05, voxel: float = 0.002):
    """The fused cloud of ``views`` alone, from the reconstruction's depths and cameras (what a fit
    that leaves the other views out starts from)."""
    clouds = {v: _world_cloud(result.capture.views[v], result.cameras[v], result.depths[v], result.confidences[v],
                              min_confidence) for v in views}
    return _fused_cloud(clouds, result.cameras, list(views), voxel)


def _world_cloud(view: View, camera: Camera, depth: np.ndarray, confidence: np.ndarray, min_confidence: float):
    """The view's confident depth as a coloured Open3D cloud in the world, with the depth map's own normals."""
    from .geometry import view_point_cloud

    return view_point_cloud(view.with_(camera=camera), np.where(confidence >= min_confidence, depth, np.nan))


def _metric_scale(config: FuseConfig, cameras: list[Camera], depths: list[np.ndarray], cloud, report: dict,
                  factor: float = 1.0) -> float | None:
    """Millimetres per reconstruction unit from a metric hint, or None (``factor``: working pixels per photo pixel)."""
    if config.px_per_mm:
        depth = float(np.nanmedian(depths[0]))
        return cameras[0].K[0, 0] / (config.px_per_mm * factor * depth)
    if config.finger_width_mm:
        points = np.asarray(cloud.points)
        centred = points - points.mean(0)
        _, _, axes = np.linalg.svd(centred[:: max(1, len(points) // 20000)], full_matrices=False)
        across = centred @ axes[1]  # second principal axis: across the finger
        width = float(np.percentile(across, 99.5) - np.percentile(across, 0.5))
        report["measured_width_units"] = width
        return config.finger_width_mm / width
    return None


def fuse(capture: Capture, config: FuseConfig | None = None, progress: bool = False, rig: Rig | None = None) -> Reconstruction:
    """Recover cameras and one fused finger surface from the capture's images (cameras ignored), and
    fit Gaussians to the photos on top (``config.splat``).

    ``rig``: a calibrated rig (:mod:`fingersplat3d.align.solve.rig`) whose poses and focal stay fixed; the
    capture's views are its cameras in order.

    Views that could not be registered do not raise: the result says so
    (:attr:`Reconstruction.registered`, ``report["alignment"]``), so that outputs can still be written.
    """
    config = FuseConfig() if config is None else config
    from tqdm import tqdm

    if len(capture) < MIN_VIEWS:
        raise InputError("fs3d fuse needs at least one image")
    if len({view.channels for view in capture.views}) > 1:  # the loaders read such photos alike (io.images.read_images)
        raise InputError("the views mix grayscale and colour images: one model is fitted to them all; read them with "
                         "fingersplat3d.io.images.read_images, which gives a capture one kind of channel")
    if rig is not None:
        _check_rig(capture, rig)
        refuse_focal_with_rig(config.focal_px, rig)
    copies = _copies(capture)  # on the photos: which of them are the same picture, decided once
    if rig is None and copies and len(copies) < len(capture) - 1:  # a copy beside other photos: each picture once
        return _fused_once(capture, copies, config, progress)  # (a rig's cameras are its views in order: kept)
    stages = _Stages()
    report: dict = {"version": __version__, "python": platform.python_version(), "views": capture.names,
                    "settings": asdict(config), "warnings": []}
    config = _with_exif_focal(capture, config, rig, report)
    bar = tqdm(total=5 + (config.splat is not None), desc="fs3d fuse", unit="stage", disable=not progress)

    def step(name):
        bar.set_postfix_str(name)
        return stages(name)

    try:
        with step("masks"):
            photos, capture, scale = _at_working_scale(capture, config.ridge_px, windows=rig is None)
            rig = None if rig is None else rig.scaled(scale.factor)
            config = _in_working_pixels(config, scale)
            swollen = _swollen(capture)  # said with the other warnings, after the progress bar
        bar.update()
        pairs = _distinct_pairs(capture, copies)
        with step("pointmaps"):
            pointmaps, pair_pointmaps = _pointmaps(capture, pairs, config, report)
        bar.update()
        with step("registration"):
            alignment, pointmaps = _register(capture, pairs, pointmaps, pair_pointmaps, config, report,
                                  lambda text: bar.set_postfix_str(f"registration: {text}"), rig,
                                  scale.working_period_px())
        bar.update()
        report["alignment"] = alignment_status(capture, pairs, alignment, report)
        cameras = [Camera.from_focal(alignment.focals[v], view.width, view.height, alignment.world_to_cam[v])
                   for v, view in enumerate(capture.views)]
        depths = [np.where(view.mask, alignment.depths[v], np.nan).astype(np.float32) for v, view in enumerate(capture.views)]
        confidences = [pm.confidence for pm in pointmaps]
        del pointmaps, pair_pointmaps  # their points are the depth maps' now: a phone's capture's pointmaps were 0.27 GB
        aligned = [v for v in range(len(capture)) if alignment.aligned[v]] or [alignment.root]
        with step("icp"):
            clouds = per_item(lambda v: _world_cloud(capture.views[v], cameras[v], depths[v], confidences[v],
                                                     config.min_confidence), range(len(capture)))
            if config.icp and len(aligned) >= 2:
                _refine_with_icp(capture, cameras, clouds, aligned, alignment.root, config, report)
        bar.update()
        with step("fusion"):
            cloud = _fused_cloud(clouds, cameras, aligned, config.voxel)
            mm_per_unit = _metric_scale(config, cameras, depths, cloud, report, scale.factor)
            units = "mm" if mm_per_unit is not None else "arbitrary"
            if mm_per_unit is not None:
                cloud.scale(mm_per_unit, center=np.zeros(3))
                depths = [d * mm_per_unit for d in depths]
                cameras = [_scaled_camera(c, mm_per_unit) for c in cameras]
        bar.update()
        splat, grow = None, [1.0] * len(capture)
        photo_sizes = [(view.width, view.height) for view in photos.views]
        report["working_resolution"] = scale.as_report(photo_sizes)
        if config.splat is not None:
            from .splat.stage import run_splat_stage

            geometry_scale = scale
            capture, scale, cameras, (depths, confidences), grow = _on_splat_grid(
                photos, capture, scale, config.splat_ridge_px, cameras, (depths, confidences), report)
            if scale is not geometry_scale:
                report["working_resolution"]["splat"] = scale.as_report(photo_sizes)

            device = resolve_device(config.device)
            with step("splat"):
                if device.type == "cpu":  # the numba kernels' first compile, named on the bar when it is not cached
                    from .splat.warmup import ensure_compiled

                    ensure_compiled(lambda text: bar.set_postfix_str(f"splat: {text}"))
                    bar.set_postfix_str("splat")
                unseen = unseen_skin_of(cloud, capture.views, cameras, aligned, config.splat)
                splat = run_splat_stage(capture.views, cameras, aligned, cloud, config.splat, config.clean,
                                        unseen=unseen, depths=depths, device=device, progress=progress,
                                        periods=scale.working_view_periods_px())
            cameras = splat.cameras
            report["splat"] = splat.report
            bar.update()
        mesh = None
        if config.mesh:
            from .mesh import mesh_from_cloud

            with stages("mesh"):
                mesh = mesh_from_cloud(cloud)
    finally:
        bar.close()  # before any message: an error is the last line the user sees
    for message in _ridgeless(photos, scale) + swollen:
        warn(report, message)
    backing = multi_view_backing(depths, cameras, [bool(a) for a in alignment.aligned])
    support = backed_shares(backing)
    shares = [share for share in support if share is not None]
    if len(shares) >= 2 and max(shares) < NO_PARALLAX_SHARE:
        warn(report, f"no two views see the finger from {MIN_PARALLAX_DEG:g}° or more apart (the same place, or the same "
                     "photo moved): its depth is the pointmap's guess, as from one photo; take the photos from "
                     "different angles around the finger")
    report["alignment"].update(
        backed_by_two_views={name: None if share is None else round(share, 3) for name, share in zip(capture.names, support)},
        residual_px=alignment.residual_px, residual_rel3d=alignment.residual_rel3d,
        focals_px=[float(focal) * g for focal, g in zip(alignment.focals, grow)],
        relief_scale=alignment.relief_scale, spanning_tree=[[capture.views[a].name, capture.views[b].name] for a, b in alignment.tree],
        aligned=dict(zip(capture.names, alignment.aligned)))
    cameras, (depths, confidences, splat_depths), backing = _on_photo_grid(
        photos, scale, cameras, (depths, confidences, splat.depths if splat else None), report, backing)
    report.update(stages=stages.records, units=units, scale_mm_per_unit=mm_per_unit, points=len(cloud.points))
    return Reconstruction(photos, cameras, depths, confidences, cloud, units, mm_per_unit, report, mesh,
                          splat.gaussians if splat else None, splat_depths, backing)


def _orient_outward(cloud, cameras: list[Camera], views: list[int]) -> None:
    """Flip normals that face away from every camera that saw the surface (skin faces the cameras)."""
    points, normals = np.asarray(cloud.points), np.asarray(cloud.normals)
    centres = np.stack([cameras[v].center for v in views])
    towards = centres[None] - points[:, None]  # [N, V, 3]
    cosines = np.einsum("nvk,nk->nv", towards, normals) / np.linalg.norm(towards, axis=-1)
    flip = np.abs(cosines.min(axis=1)) > np.abs(cosines.max(axis=1))
    normals[flip] *= -1
    cloud.normals = type(cloud.normals)(normals)


def _scaled_camera(camera: Camera, scale: float) -> Camera:
    pose = camera.world_to_cam.copy()
    pose[:3, 3] *= scale
    return Camera(camera.K, pose, camera.width, camera.height)


def write_reconstruction(result: Reconstruction, folder: str | Path, overwrite: bool = False) -> Path:
    """Write the reconstruction folder: fused.ply, cameras.json, depth/, mesh.ply, report.json."""
    from .atomic import atomic_dir

    with atomic_dir(Path(folder), overwrite=overwrite) as temporary:
        write_reconstruction_files(result, temporary)
    return Path(folder)


def write_reconstruction_files(result: Reconstruction, temporary: Path) -> None:
    """The files of :func:`write_reconstruction` into an existing (temporary) folder."""
    from .io.cameras import write_cameras
    from .io.reconstruction import write_fused_cloud, write_report, write_view_depth

    started = time.perf_counter()
    write_fused_cloud(temporary / "fused.ply", result.cloud)
    entries = [(view.name, result.capture.metadata.get("sources", {}).get(view.name, f"images/{view.name}.png"), camera)
               for view, camera in zip(result.capture.views, result.cameras)]
    # In mm the reconstruction is already scaled (report.json keeps the factor): cameras.json says mm, scale null.
    write_cameras(temporary / "cameras.json", entries, units=result.units,
                  scale_mm_per_unit=None if result.units == "mm" else result.scale_mm_per_unit)
    for view, depth in zip(result.capture.views, result.depths):
        write_view_depth(temporary, view.name, depth, units="mm" if result.units == "mm" else "arbitrary")
    if result.gaussians is not None:
        from .io.gaussians_ply import write_gaussians_ply

        write_gaussians_ply(temporary / "gaussians.ply", result.gaussians)
    if result.mesh is not None:
        from .mesh import write_mesh

        write_mesh(temporary / "mesh.ply", result.mesh)
    _write_overview(result, temporary / "overview.png")
    report = dict(result.report)
    report["stages"] = {**report.get("stages", {}), "write": {"seconds": round(time.perf_counter() - started, 3)}}
    write_report(temporary / "report.json", report)


def _write_overview(result: Reconstruction, path: Path) -> None:
    """``overview.png``: what the fuse found, at a glance (:func:`~fingersplat3d.viz.fuse_overview`)."""
    from .io.images import write_image
    from .viz import TILE_HEIGHT, fuse_overview

    alignment = result.report.get("alignment", {})
    backing = result.backing
    if backing is None:  # a Reconstruction made elsewhere: the fuse's own maps are not there
        placed = alignment.get("aligned", {})
        aligned = [bool(placed.get(view.name, True)) for view in result.capture.views]
        tallest = max(depth.shape[0] for depth in result.depths)
        backing = multi_view_backing(result.depths, result.cameras, aligned, stride=max(2, tallest // TILE_HEIGHT))
    picture = fuse_overview([view.image for view in result.capture.views], result.capture.names, result.cameras,
                            backing, alignment)
    write_image(path, picture.astype(np.float32) / 255.0)
