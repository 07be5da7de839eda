"""``fs3d eval match``: the paper's matching experiment (mindtct minutiae, or pyfing's LEADER's; bozorth3 scores) as a
command.

Samples are photos named so that the finger and the capture can be read from the name (by
default the UWA 3D/2D naming ``{subject}_{finger}_{capture}_{session}_{frame}``: finger =
subject_finger, capture = capture_session, view = frame). Two protocols:

* **real**: every two photos of *different captures* seen by the same camera (view label);
  genuine when the finger is the same, impostor otherwise.
* **synthesized** (with reconstruction folders from ``fs3d fuse``): the model of one capture is
  rendered at angles about the rig axis (0 = its middle camera) and each render compared with the
  real photos of the gallery view (the middle camera's label) of every *other* capture: genuine
  for the same finger, impostor for other fingers. Scores by angle give the paper's
  angle-difference table.

* **rolled** (with ``rolled`` reconstruction folders; no Gaussians needed): the rolled-equivalent
  print of each model (:mod:`fingersplat3d.prints`) against the rolled prints of the other captures'
  models (genuine for the same finger), and, as **rolled vs photos**, against the real photos of the
  gallery view of every other capture (the rolled print at five scales about the photos' ridge period, each pair at
  its best, as the gallery below: two kinds of print need not read the same period).

* **gallery** (with ``gallery`` contact prints, each named by its finger with ``gallery_naming``): every probe
  print — photos, renders, rolled prints — against every gallery print, genuine for the same finger; one protocol
  per probe kind (``photos vs gallery``, ...). A photo carries no scale, so its print is scaled to a ridge period
  of 9 px; each gallery print is compared at five scales about the same period, each pair at its best
  (``gallery_about_period``; a finger's ridges 0.40-0.55 mm apart are 8-11 px at 500 ppi, bozorth3 tolerates a scale
  little off, and two kinds of print of one finger need not read the same period), and rolled prints of models in mm
  are brought to that period.
  ``mirror``: ``yes``, the probes are mirrored left-right first (an inked or scanned contact print is the
  mirror image of a photo of the pad; a rolled print of ``fs3d synth`` or IMPOSE is not); ``no``, as they are;
  ``auto`` (the default), each kind of probe compared both ways and the gallery's way round read from the scores
  (:mod:`fingersplat3d.eval.handedness`: the way whose probes find the stronger best matches), said in the summary.

Every photo and render becomes a contact-like print (:mod:`fingersplat3d.eval.contact`); compared with flat-laid prints
(the gallery's, the rolled prints), a photo's finger is unrolled first through the surface its silhouette gives
(:func:`fingersplat3d.prints.make.unrolled_photo`; ``flat``: not). All go through NIST's tools
(:mod:`fingersplat3d.eval.fingerprint`). Error rates:
:func:`fingersplat3d.eval.verification.error_rates`. Writes ``scores.csv``, ``prints.csv`` (per
print: minutiae, NFIQ2, failure), ``prints/`` (the prints as PNG), ``summary.md`` and ``det.png``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..errors import FS3DError, InputError
from ..eval.handedness import gallery_handedness, median_best
from .tables import write_rows

__all__ = ["UWA_NAMING", "GALLERY_NAMING", "MIRROR_CHOICES", "Sample", "read_gallery", "parse_samples", "real_pairs",
           "run_match_evaluation", "DEFAULT_ANGLES"]

UWA_NAMING = r"^(?P<subject>\d+)_(?P<hand>\d+)_(?P<capture>\d+)_(?P<session>\d+)_(?P<view>\d+)$"
"""UWA 3D/2D: finger = subject + finger number, capture = capture + session, view = frame."""
DEFAULT_ANGLES = (-30.0, -15.0, 0.0, 15.0, 30.0)
GALLERY_NAMING = r"^(?P<finger>.+)$"
"""A contact print's file stem is its finger, as the probes' naming reads it (e.g. ``1_1.png`` for UWA's ``1_1_*``)."""
MIRROR_CHOICES = ("auto", "yes", "no")
"""How the probes are turned for the gallery: read from the scores (:mod:`~fingersplat3d.eval.handedness`), mirrored
left-right, or as they are."""
PROBE_KINDS = {"real": "photos", "synthesized": "renders", "rolled": "rolled prints"}


@dataclass(frozen=True)
class Sample:
    """One photo and who it is of."""

    path: str
    finger: str
    capture: str  # unique across fingers: finger/capture
    view: str

    @property
    def name(self) -> str:
        return Path(self.path).stem


def _identity(stem: str, pattern: re.Pattern) -> tuple[str, str, str] | None:
    match = pattern.match(stem)
    if match is None:
        return None
    groups = match.groupdict()
    if "finger" in groups:
        finger = groups["finger"]
    else:
        finger = f"{groups['subject']}_{groups['hand']}"
    capture = groups["capture"] + (f"_{groups['session']}" if groups.get("session") else "")
    return finger, f"{finger}/{capture}", groups.get("view") or ""


def compile_naming(naming: str) -> re.Pattern:
    """A naming regex with the groups it needs (``finger`` or ``subject`` + ``hand``, and ``capture``)."""
    try:
        pattern = re.compile(naming)
    except re.error as error:
        raise InputError(f"--naming {naming!r} is not a regular expression: {error}") from None
    groups = set(pattern.groupindex)
    if "capture" not in groups or not ("finger" in groups or {"subject", "hand"} <= groups):
        raise InputError(f"--naming {naming!r} needs the named groups 'capture' and 'finger' "
                         "(or 'subject' and 'hand'); 'view' and 'session' are optional")
    return pattern


def parse_samples(paths: list[Path], naming: str = UWA_NAMING, views: set[str] | None = None
                  ) -> tuple[list[Sample], list[Path]]:
    """Samples from image files (names parsed by ``naming``) and the files whose name did not parse."""
    pattern = compile_naming(naming)
    samples, unparsed = [], []
    for path in paths:
        identity = _identity(path.stem, pattern)
        if identity is None:
            unparsed.append(path)
        elif views is None or identity[2] in views:
            samples.append(Sample(str(path), *identity))
    return samples, unparsed


def real_pairs(samples: list[Sample]) -> list[tuple[int, int, bool]]:
    """``(i, j, genuine)`` for every two samples of different captures and the same view."""
    pairs = []
    for i in range(len(samples)):
        for j in range(i + 1, len(samples)):
            a, b = samples[i], samples[j]
            if a.capture != b.capture and a.view == b.view:
                pairs.append((i, j, a.finger == b.finger))
    return pairs


@dataclass(frozen=True)
class _Print:
    name: str
    fingerprint: object | None  # Fingerprint, None when no print could be made
    failure: str
    image: np.ndarray | None = field(default=None, repr=False, compare=False)  # the print (uint8), when one was made


def _print_of(name: str, image: np.ndarray, mask: np.ndarray | None, folder: Path, ridges: str,
              unrolled: bool = False, extractor: str = "mindtct") -> _Print:
    """A photo's or render's print, scaled and turned (:func:`~fingersplat3d.eval.fingerprint.fingerprint_of`) or
    ``unrolled`` (:func:`~fingersplat3d.prints.make.unrolled_photo`), written to ``folder``, with its minutiae."""
    from ..eval.fingerprint import analyse, fingerprint_of

    if not unrolled:
        contact, fingerprint, failure = fingerprint_of(image, mask, ridges=ridges, name=name, extractor=extractor)
        printed = None if contact is None else contact.image
    else:
        from ..align.correspond.texture import as_gray
        from ..eval.contact import ContactImage
        from ..prints.make import unrolled_photo
        from ..segment.masks import finger_mask

        try:
            gray = as_gray(image, name=name)
            printed = unrolled_photo(gray, finger_mask(gray, name=name) if mask is None else mask, ridges=ridges,
                                     name=name)[0].image
        except FS3DError as error:
            return _Print(name, None, str(error))
        fingerprint = analyse(ContactImage.of_print(printed), extractor=extractor)
        failure = fingerprint.failure
    if printed is not None:
        cv2.imwrite(str(folder / f"{name.replace('/', '__')}.png"), printed)
    return _Print(name, fingerprint, failure, printed)


def _reconstruction_identity(folder: Path, pattern: re.Pattern):
    from ..io.cameras import read_cameras

    cameras = read_cameras(folder / "cameras.json")
    identities = [_identity(Path(image).stem, pattern) for image in cameras.images.values()]
    if not identities or any(i is None for i in identities):
        raise InputError(f"{folder / 'cameras.json'}: its photos' names do not follow the naming pattern, so the "
                         "finger and capture it shows are unknown")
    return cameras, identities


def _synthesized(folder: Path, angles: tuple[float, ...], pattern: re.Pattern, prints: Path, ridges: str,
                 extractor: str = "mindtct"):
    """Prints of a reconstruction rendered at ``angles``: ``(finger, capture, gallery view, [(angle, print)])``."""
    from ..device import resolve_device
    from ..io.gaussians_ply import read_gaussians_ply
    from ..splat.camera_path import cameras_at_angles, middle_camera
    from ..splat.novel import render_views

    if not (folder / "gaussians.ply").is_file():
        raise InputError(f"{folder}: no gaussians.ply (a reconstruction folder from 'fs3d fuse' without --no-splat)")
    cameras, identities = _reconstruction_identity(folder, pattern)
    finger, capture = identities[0][0], identities[0][1]
    inputs = list(cameras.cameras.values())
    try:
        reference = middle_camera(inputs)
        placed = cameras_at_angles(inputs, angles)
    except ValueError as error:
        raise InputError(f"{folder}: cannot place novel views: {error}") from None
    gallery_view = identities[reference][2]
    model = read_gaussians_ply(folder / "gaussians.ply").to(resolve_device("auto"))
    results = []
    for angle, view in zip(angles, render_views(model, [(f"{a:+.0f}", c) for a, c in zip(angles, placed)])):
        name = f"{folder.name}@{angle:+.0f}deg"
        results.append((angle, _print_of(name, view.image, view.alpha >= 0.5, prints, ridges, extractor=extractor)))
    return finger, capture, gallery_view, results


def _rolled(folder: Path, pattern: re.Pattern, prints: Path, ridges: str, enhancer: str = "gabor",
            extractor: str = "mindtct"):
    """The rolled-equivalent print of a reconstruction: ``(finger, capture, gallery view, print)``."""
    from ..eval.contact import ContactImage
    from ..eval.fingerprint import analyse
    from ..prints.make import print_reconstruction
    from ..splat.camera_path import middle_camera

    cameras, identities = _reconstruction_identity(folder, pattern)
    finger, capture = identities[0][0], identities[0][1]
    name = f"{folder.name}@rolled"
    try:
        gallery_view = identities[middle_camera(list(cameras.cameras.values()))][2]
    except ValueError:
        gallery_view = identities[0][2]
    try:
        result, _, _ = print_reconstruction(folder, ridges=ridges, enhancer=enhancer)
    except FS3DError as error:
        return finger, capture, gallery_view, _Print(name, None, str(error))
    cv2.imwrite(str(prints / f"{name}.png"), result.image)
    fingerprint = analyse(ContactImage.of_print(result.image, result.period_px), extractor=extractor)
    return finger, capture, gallery_view, _Print(name, fingerprint, fingerprint.failure, result.image)


def read_gallery(paths: list[Path], naming: str = GALLERY_NAMING) -> list[tuple[str, Path]]:
    """``(finger, file)`` of every contact print under ``paths``; a name the pattern does not read is an error."""
    from ..io.images import find_files

    try:
        pattern = re.compile(naming)
    except re.error as error:
        raise InputError(f"--gallery-naming {naming!r} is not a regular expression: {error}") from None
    if "finger" not in pattern.groupindex:
        raise InputError(f"--gallery-naming {naming!r} needs the named group 'finger'")
    gallery = []
    for path in find_files(paths):
        match = pattern.match(path.stem)
        if match is None:
            raise InputError(f"{path.name}: the gallery naming {naming!r} does not read a finger from it")
        gallery.append((match.group("finger"), path))
    if not gallery:
        raise InputError("the gallery holds no image files")
    return gallery


@dataclass(frozen=True)
class _GalleryPrint:
    """A contact print of the gallery, analysed at each scale it is compared at (one: as it is)."""

    name: str
    fingerprints: tuple  # Fingerprint at each scale that has minutiae
    scales: tuple[float, ...]  # the factor each was resized by
    failure: str

    @property
    def fingerprint(self):
        """The print at the probes' own ridge period (the middle scale), for prints.csv; None without minutiae."""
        return self.fingerprints[len(self.fingerprints) // 2] if self.fingerprints else None


def _gallery_print(finger: str, path: Path, extractor: str = "mindtct", about_period: bool = True):
    """A contact print (8-bit gray, ridges dark) analysed at scales about the probes' ridge period
    (:func:`~fingersplat3d.eval.contact.prints_about_period`), or as it is: ``(finger, _GalleryPrint)``."""
    from ..eval.contact import ContactImage, prints_about_period
    from ..eval.fingerprint import analyse
    from ..io.images import read_image

    name = f"gallery/{path.stem}"
    try:
        gray = read_image(path, gray=True)
    except FS3DError as error:
        return finger, _GalleryPrint(name, (), (), str(error))
    image = np.rint(np.clip(gray, 0, 1) * 255).astype(np.uint8)
    contacts = prints_about_period(image) if about_period else [ContactImage.of_print(image)]
    analysed = [(analyse(c, nfiq2=False, extractor=extractor), c.ppi_scale) for c in contacts]
    usable = [(f, scale) for f, scale in analysed if f.count]
    failure = "" if usable else (analysed[0][0].failure or f"{extractor} found no minutiae")
    return finger, _GalleryPrint(name, tuple(f for f, _ in usable), tuple(scale for _, scale in usable), failure)


def _at_period(probe: _Print, extractor: str = "mindtct") -> _Print:
    """A rolled print brought to the photos' ridge period for the gallery (a model's print in mm keeps its finger's
    own spacing); the print itself where it already is, or has no print."""
    from ..eval.contact import print_at_period
    from ..eval.fingerprint import analyse

    if probe.fingerprint is None or probe.image is None:
        return probe
    scaled = print_at_period(probe.image)
    if scaled.ppi_scale == 1.0:
        return probe
    fingerprint = analyse(scaled, nfiq2=False, extractor=extractor)
    return _Print(probe.name, fingerprint if fingerprint.count else None, fingerprint.failure, scaled.image)


def _mirrored(probe: _Print, extractor: str = "mindtct"):
    """The probe's print mirrored left-right and analysed again (None when it has no print)."""
    from ..eval.contact import ContactImage
    from ..eval.fingerprint import analyse

    if probe.image is None:
        return None
    return analyse(ContactImage.of_print(probe.image[:, ::-1].copy()), nfiq2=False, extractor=extractor)


def _gallery_scores(probes: list[_Print], contact: list, mirrored: bool,
                    extractor: str) -> tuple[np.ndarray, np.ndarray]:
    """``[probes, gallery]`` bozorth3 scores of the probes (mirrored left-right first, or as they are) against the
    gallery's prints, each pair's best over the scales a gallery print was analysed at, and that scale; NaN where
    either has no minutiae to compare."""
    from ..eval.fingerprint import match_score

    scores, scales = np.full((len(probes), len(contact)), np.nan), np.full((len(probes), len(contact)), np.nan)
    for i, probe in enumerate(probes):
        template = _mirrored(probe, extractor) if mirrored else probe.fingerprint
        if template is None:
            continue
        for j, (_, entry) in enumerate(contact):
            if entry.fingerprints:
                each = [match_score(template, f) for f in entry.fingerprints]
                best = int(np.argmax(each))
                scores[i, j], scales[i, j] = each[best], entry.scales[best]
    return scores, scales


def _about_period(probe: _Print, extractor: str = "mindtct") -> tuple:
    """A rolled print's fingerprints at the scales about the photos' ridge period
    (:func:`~fingersplat3d.eval.contact.prints_about_period`), those with minutiae: a print pressed flat and a photo
    unrolled through a guessed section need not read the same period (the real dev captures' rolled prints against
    their photos: 45.9 % EER at one scale, 35.9 % at the best of five)."""
    from ..eval.contact import prints_about_period
    from ..eval.fingerprint import analyse

    analysed = [analyse(c, nfiq2=False, extractor=extractor) for c in prints_about_period(probe.image)]
    return tuple(f for f in analysed if f.count) or (probe.fingerprint,)


def _finite(value: float | None) -> float | None:
    return None if value is None or not np.isfinite(value) else float(value)


def run_match_evaluation(samples: list[Sample], out: Path, *, reconstructions: list[Path] = (),
                         angles: tuple[float, ...] = DEFAULT_ANGLES, naming: str = UWA_NAMING, ridges: str = "bright",
                         progress: bool = True, rolled: list[Path] = (), gallery: list[tuple[str, Path]] = (),
                         mirror: str = "auto", enhancer: str = "gabor", flat: bool = False,
                         extractor: str = "mindtct", gallery_about_period: bool = True) -> dict:
    """Both protocols; writes the files named in the module docstring and returns the summary (``enhancer``: of the
    rolled prints, :func:`~fingersplat3d.prints.rolled.rolled_print`; ``extractor``: every print's minutiae,
    :data:`~fingersplat3d.eval.fingerprint.MINUTIAE_EXTRACTORS`). Photos compared with photos or renders (one
    camera's foreshortening on both sides) are scaled and turned; compared with flat-laid prints (the gallery's contact
    prints, the rolled prints), they are unrolled first (:func:`~fingersplat3d.prints.make.unrolled_photo`), unless
    ``flat``. ``gallery_about_period``: each gallery print, and each rolled print compared with photos, compared at five
    scales about the photos' ridge period, each pair at its best
    (:func:`~fingersplat3d.eval.contact.prints_about_period`), and rolled prints in mm brought to that period, as photos
    carry no scale; else every print as it is."""
    from tqdm import tqdm

    from ..eval.fingerprint import match_score
    from ..io.images import read_image

    if mirror not in MIRROR_CHOICES:
        raise ValueError(f"mirror must be one of {MIRROR_CHOICES}, got {mirror!r}")
    pattern = compile_naming(naming)
    prints = out / "prints"
    prints.mkdir(parents=True, exist_ok=True)
    unroll = bool(gallery or rolled) and not flat
    real, laid = [], []  # each photo's print; and its print for comparisons with flat-laid prints
    for sample in tqdm(samples, desc="prints (photos)", unit="image", disable=not progress):
        try:
            image = read_image(sample.path)
        except FS3DError as error:
            real.append(_Print(sample.name, None, str(error)))
            laid.append(real[-1])
            continue
        real.append(_print_of(sample.name, image, None, prints, ridges, extractor=extractor))
        laid.append(_print_of(f"{sample.name}@unrolled", image, None, prints, ridges, unrolled=True, extractor=extractor)
                    if unroll and real[-1].fingerprint is not None else real[-1])
    synthesized = [_synthesized(folder, tuple(angles), pattern, prints, ridges, extractor)
                   for folder in tqdm(reconstructions, desc="prints (renders)", unit="model", disable=not progress)]
    unrolled = [_rolled(folder, pattern, prints, ridges, enhancer, extractor)
                for folder in tqdm(rolled, desc="prints (rolled)", unit="model", disable=not progress)]
    rows = []
    for i, j, genuine in real_pairs(samples):
        a, b = real[i].fingerprint, real[j].fingerprint
        if a is not None and b is not None:
            rows.append({"protocol": "real", "probe": samples[i].name, "gallery": samples[j].name,
                         "genuine": int(genuine), "angle_deg": "", "score": match_score(a, b)})
    for finger, capture, view, renders in synthesized:
        for k, sample in enumerate(samples):
            if sample.capture == capture or sample.view != view or real[k].fingerprint is None:
                continue
            for angle, render in renders:
                if render.fingerprint is not None:
                    rows.append({"protocol": "synthesized", "probe": render.name, "gallery": sample.name,
                                 "genuine": int(sample.finger == finger), "angle_deg": angle,
                                 "score": match_score(render.fingerprint, real[k].fingerprint)})
    for i, (finger_a, capture_a, _, print_a) in enumerate(unrolled):
        if print_a.fingerprint is None:
            continue
        about = _about_period(print_a, extractor) if gallery_about_period else (print_a.fingerprint,)
        for finger_b, capture_b, _, print_b in unrolled[i + 1:]:
            if capture_b != capture_a and print_b.fingerprint is not None:
                rows.append({"protocol": "rolled", "probe": print_a.name, "gallery": print_b.name,
                             "genuine": int(finger_a == finger_b), "angle_deg": "",
                             "score": match_score(print_a.fingerprint, print_b.fingerprint)})
        for k, sample in enumerate(samples):
            if sample.capture != capture_a and sample.view == unrolled[i][2] and laid[k].fingerprint is not None:
                rows.append({"protocol": "rolled vs photos", "probe": print_a.name, "gallery": sample.name,
                             "genuine": int(sample.finger == finger_a), "angle_deg": "",
                             "score": max(match_score(f, laid[k].fingerprint) for f in about)})
    contact = [_gallery_print(finger, path, extractor, gallery_about_period)
               for finger, path in tqdm(gallery, desc="prints (gallery)", unit="print", disable=not progress)]
    probes = ([("real", sample.finger, p) for sample, p in zip(samples, laid)]
              + [("synthesized", finger, p) for finger, _, _, renders in synthesized for _, p in renders]
              + [("rolled", finger, _at_period(p, extractor) if contact and gallery_about_period else p)
                 for finger, _, _, p in unrolled])
    handedness = {}
    for kind in PROBE_KINDS:
        kind_probes = [(finger, probe) for k, finger, probe in probes if k == kind and probe.fingerprint is not None]
        if not contact or not kind_probes:
            continue
        ways = (False, True) if mirror == "auto" else (mirror == "yes",)
        compared = {way: _gallery_scores([p for _, p in kind_probes], contact, way, extractor) for way in ways}
        scores = {way: table for way, (table, _) in compared.items()}
        best = {way: median_best(table) for way, table in scores.items()}
        flip = gallery_handedness(scores[False], scores[True]).mirrored if mirror == "auto" else mirror == "yes"
        handedness[f"{PROBE_KINDS[kind]} vs gallery"] = {
            "mirrored": flip, "chosen": "read from the scores" if mirror == "auto" else "given",
            "median_best_as_is": _finite(best.get(False)), "median_best_mirrored": _finite(best.get(True))}
        for (finger, probe), row, row_scales in zip(kind_probes, *compared[flip]):
            for (gallery_finger, entry), score, scale in zip(contact, row, row_scales):
                if np.isfinite(score):
                    rows.append({"protocol": f"{PROBE_KINDS[kind]} vs gallery", "probe": probe.name,
                                 "gallery": entry.name, "genuine": int(gallery_finger == finger), "angle_deg": "",
                                 "score": int(score), "mirrored": int(flip), "gallery_scale": round(float(scale), 3)})
    all_prints = (real + [p for p, q in zip(laid, real) if p is not q] + [p for *_, renders in synthesized for _, p in renders]
                  + [p for *_, p in unrolled]
                  + [p for _, p in contact])
    write_rows(out / "prints.csv", ("name", "minutiae", "nfiq2", "failure"),
               [{"name": p.name, "minutiae": p.fingerprint.count if p.fingerprint else "",
                 "nfiq2": "" if p.fingerprint is None or p.fingerprint.nfiq2 is None else p.fingerprint.nfiq2,
                 "failure": p.failure} for p in all_prints])
    write_rows(out / "scores.csv", ("protocol", "probe", "gallery", "genuine", "angle_deg", "score", "mirrored",
                                    "gallery_scale"), [{"mirrored": "", "gallery_scale": ""} | row for row in rows])
    summary = summarise(rows, all_prints) | {"minutiae": extractor, "handedness": handedness}
    (out / "summary.md").write_text(summary_markdown(summary))
    curves = {}
    from ..eval.verification import det_curve

    for protocol, rates in summary["protocols"].items():
        if rates.get("eer") is not None:
            genuine, impostor = _split(rows, protocol)
            _, fmr, fnmr = det_curve(genuine, impostor)
            curves[f"{protocol} (EER {rates['eer']:.1%})"] = (fmr, fnmr)
    if curves:
        from .plots import det_picture

        det_picture(out / "det.png", curves, f"bozorth3 on {extractor} minutiae")
    return summary


def _split(rows: list[dict], protocol: str, angle: float | None = None) -> tuple[list[int], list[int]]:
    chosen = [r for r in rows if r["protocol"] == protocol and (angle is None or r["angle_deg"] == angle)]
    return [r["score"] for r in chosen if r["genuine"]], [r["score"] for r in chosen if not r["genuine"]]


def summarise(rows: list[dict], prints: list[_Print]) -> dict:
    from ..eval.verification import error_rates

    protocols = {}
    for protocol in ("real", "synthesized", "rolled", "rolled vs photos", *(f"{kind} vs gallery" for kind in PROBE_KINDS.values())):
        genuine, impostor = _split(rows, protocol)
        if genuine and impostor:
            protocols[protocol] = error_rates(genuine, impostor)
        elif genuine or impostor:
            protocols[protocol] = {"genuine": len(genuine), "impostor": len(impostor), "eer": None}
    angles = []
    for angle in sorted({r["angle_deg"] for r in rows if r["protocol"] == "synthesized"}):
        genuine, impostor = _split(rows, "synthesized", angle)
        entry = {"angle_deg": angle, "genuine": len(genuine), "impostor": len(impostor),
                 "genuine_mean": float(np.mean(genuine)) if genuine else None,
                 "genuine_median": float(np.median(genuine)) if genuine else None,
                 "impostor_mean": float(np.mean(impostor)) if impostor else None}
        if genuine and impostor:
            from ..eval.verification import equal_error_rate

            entry["eer"] = equal_error_rate(genuine, impostor)
        angles.append(entry)
    failed = [(p.name, p.failure) for p in prints if p.fingerprint is None]
    nfiq2 = [p.fingerprint.nfiq2 for p in prints if p.fingerprint is not None and p.fingerprint.nfiq2 is not None]
    return {"protocols": protocols, "angles": angles, "prints": len(prints), "failed": failed,
            "nfiq2_failed": sum(1 for p in prints if p.fingerprint is not None and p.fingerprint.nfiq2 is None),
            "nfiq2_mean": float(np.mean(nfiq2)) if nfiq2 else None}


def _percent(value) -> str:
    return "—" if value is None else f"{100 * value:.1f} %"


def handedness_sentence(protocol: str, way: dict) -> str:
    """One sentence on which way round the probes of ``protocol`` were compared with the gallery, and why."""
    turned = "mirrored left-right" if way["mirrored"] else "as they are"
    figures = [f"{label} {way[key]:.0f}" for label, key in (("as they are", "median_best_as_is"),
                                                           ("mirrored", "median_best_mirrored"))
               if way.get(key) is not None]
    why = ("the gallery's way round read from the scores" if way["chosen"] == "read from the scores"
           else "as --mirror or --no-mirror fixes it")
    return (f"{protocol}: the probes compared {turned} ({why}; their best matches' median score "
            f"{', '.join(figures)}).")


def summary_markdown(summary: dict) -> str:
    lines = [f"# Matching ({summary.get('minutiae', 'mindtct')} + bozorth3)", "",
             f"{summary['prints']} prints; {len(summary['failed'])} could not be made, NFIQ2 failed on "
             f"{summary['nfiq2_failed']}; mean NFIQ2 {summary['nfiq2_mean']:.1f}." if summary["nfiq2_mean"] is not None
             else f"{summary['prints']} prints; {len(summary['failed'])} could not be made.", ""]
    if summary["protocols"]:
        lines += ["| protocol | genuine | impostor | EER | FNMR @ FMR 1 % | FNMR @ FMR 0.01 % | FMR_zero | FMR floor (1/impostors) |",
                  "|---|---|---|---|---|---|---|---|"]
        for name, r in summary["protocols"].items():
            lines.append(f"| {name} | {r['genuine']} | {r['impostor']} | {_percent(r.get('eer'))} | "
                         f"{_percent(r.get('fnmr_at_fmr_1pct'))} | {_percent(r.get('fnmr_at_fmr_0.01pct'))} | "
                         f"{_percent(r.get('fmr_zero'))} | {_percent(r.get('fmr_resolution'))} |")
        lines += ["", "FNMR at an FMR below the floor cannot be told from FMR_zero with this many impostor scores."]
    for protocol, way in summary.get("handedness", {}).items():
        lines += ["", handedness_sentence(protocol, way)]
    if summary["angles"]:
        lines += ["", "Synthesized views against real photos of the finger's other captures, by the render's angle "
                  "from the gallery camera:", "",
                  "| angle ° | genuine | mean genuine score | median genuine | mean impostor score | EER |",
                  "|---|---|---|---|---|---|"]
        for a in summary["angles"]:
            def number(v):
                return "—" if v is None else f"{v:.1f}"
            lines.append(f"| {a['angle_deg']:+.0f} | {a['genuine']} | {number(a['genuine_mean'])} | "
                         f"{number(a['genuine_median'])} | {number(a['impostor_mean'])} | {_percent(a.get('eer'))} |")
    if summary["failed"]:
        lines += ["", "No print:", ""] + [f"- {name}: {why}" for name, why in summary["failed"]]
    return "\n".join(lines) + "\n"
