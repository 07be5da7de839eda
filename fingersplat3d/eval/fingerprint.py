"""NIST's fingerprint tools on a contact-like print: mindtct minutiae, NFIQ2 quality, bozorth3 scores.

The implementation is NIST's NBIS and NFIQ2 as packaged by ``nbis-py`` (pinned 0.1.3: newer
``nbis-python`` releases need a newer glibc than common Linux machines have). Prints come from
:func:`fingersplat3d.eval.contact.contact_like` (8-bit gray, ridges dark, ~500 ppi).

* :func:`analyse`: minutiae (in the *photo's* pixels, through the print's affine map; mindtct's, or pyfing's
  LEADER's with ``extractor="leader"``) and the NFIQ2 score. A print NFIQ2 cannot score (too small, no ridge
  flow) is a :class:`Fingerprint` with ``nfiq2`` None and the reason in ``failure``; its minutiae are still
  extracted when the extractor can.
* :func:`fingerprint_of`: a photo or render (and its finger mask, found when not given) made a
  print and analysed; a photo with no finger is a failure reason, not an exception.
* :func:`match_score`: the bozorth3 score of two fingerprints (0 when either has no minutiae).
  bozorth3 scores are not normalised: above ~40 is the classic "probably the same finger".
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import cv2
import numpy as np

from ..errors import FS3DError, InputError
from .contact import ContactImage, contact_like
from .learned_minutiae import MINUTIAE_EXTRACTORS

__all__ = ["Fingerprint", "MINUTIAE_EXTRACTORS", "analyse", "fingerprint_of", "match_score", "nbis_available"]


@dataclass(frozen=True, eq=False)
class Fingerprint:
    """What NIST's tools found in one print."""

    minutiae: np.ndarray  # [N, 4]: x, y (photo pixels), angle (degrees, photo frame), reliability in [0, 1]
    kinds: tuple[str, ...]  # "ending" | "bifurcation" per minutia
    nfiq2: float | None  # 0-100; None when NFIQ2 could not score the print
    failure: str = ""  # why nfiq2 (or the minutiae) are missing; "" when all went well
    template: Any = field(default=None, repr=False)  # nbis Minutiae, for bozorth3

    @property
    def count(self) -> int:
        return len(self.minutiae)


def nbis_available() -> bool:
    """Whether ``nbis-py`` can be imported."""
    try:
        import nbis  # noqa: F401
    except ImportError:
        return False
    return True


@lru_cache(maxsize=2)
def _extractor(nfiq2: bool):
    import nbis

    settings = nbis.NbisExtractorSettings(min_quality=0.0, get_center=False, check_fingerprint=False,
                                          compute_nfiq2=nfiq2, ppi=500.0)
    return nbis.new_nbis_extractor(settings)


def _reason(error: Exception) -> str:
    text = str(error).strip() or type(error).__name__
    return f"{type(error).__name__}: {text}" if type(error).__name__ not in text else text


def analyse(contact: ContactImage, nfiq2: bool = True, extractor: str = "mindtct") -> Fingerprint:
    """Minutiae and NFIQ2 of a print (see the module docstring); ``extractor``: mindtct's minutiae, or pyfing's LEADER
    (:mod:`.learned_minutiae`, matched by bozorth3 through an ISO record: :mod:`.iso_minutiae`)."""
    import nbis

    if extractor not in MINUTIAE_EXTRACTORS:
        raise InputError(f"unknown minutiae extractor {extractor!r}; choose from {', '.join(MINUTIAE_EXTRACTORS)}")
    ok, png = cv2.imencode(".png", contact.image)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise RuntimeError("could not encode the print as PNG")
    data = png.tobytes()
    failure, score, template = "", None, None
    if nfiq2 and not contact.fits_nfiq2:
        failure = "NFIQ2: the print's ridge area is outside 197-799 x 197-999 px"
    elif nfiq2:
        try:
            template = _extractor(True).extract_minutiae(data)
            score = float(template.quality().score)
        except nbis.NbisError as error:
            failure, template = f"NFIQ2: {_reason(error)}", None
    if extractor == "leader":
        return _leader_fingerprint(contact, score, failure)
    if template is None:
        try:
            template = _extractor(False).extract_minutiae(data)
        except nbis.NbisError as error:
            reason = f"mindtct: {_reason(error)}"
            return Fingerprint(np.zeros((0, 4)), (), None, f"{failure}; {reason}" if failure else reason)
    found = template.get()
    xy = np.array([[m.x(), m.y()] for m in found], np.float64).reshape(-1, 2)
    angles = np.array([float(m.angle()) for m in found], np.float64)
    reliability = np.array([float(m.reliability()) for m in found], np.float64)
    kinds = tuple("bifurcation" if "BIF" in str(m.kind()).upper() else "ending" for m in found)
    return _in_photo(contact, xy, angles, reliability, kinds, score, failure, template)


def _leader_fingerprint(contact: ContactImage, score: float | None, failure: str) -> Fingerprint:
    """LEADER's minutiae of the print, with a bozorth3 template read from their ISO record."""
    from .iso_minutiae import iso_minutiae_record
    from .learned_minutiae import leader_minutiae

    xy, angles, kinds, quality = leader_minutiae(contact.image)
    if not len(xy):
        reason = "LEADER found no minutiae"
        return Fingerprint(np.zeros((0, 4)), (), score, f"{failure}; {reason}" if failure else reason)
    height, width = contact.image.shape
    record = iso_minutiae_record(width, height, xy, angles, kinds, 100.0 * quality)
    template = _extractor(False).load_iso_19794_2_2005(record)
    return _in_photo(contact, xy, angles, quality, kinds, score, failure, template)


def _in_photo(contact: ContactImage, xy: np.ndarray, angles: np.ndarray, reliability: np.ndarray,
              kinds: tuple[str, ...], score: float | None, failure: str, template) -> Fingerprint:
    """A :class:`Fingerprint` of minutiae found on the print (its pixels, NBIS's directions), in the photo's frame."""
    if not len(xy):
        return Fingerprint(np.zeros((0, 4)), (), score, failure, template)
    minutiae = np.column_stack([contact.to_photo(xy), _photo_angles(contact, angles), reliability])
    return Fingerprint(minutiae, kinds, score, failure, template)


def fingerprint_of(image: np.ndarray, mask: np.ndarray | None = None, *, ridges: str = "bright",
                   period_px: float | None = None, nfiq2: bool = True, name: str = "image", extractor: str = "mindtct"
                   ) -> tuple[ContactImage | None, Fingerprint | None, str]:
    """``(print, fingerprint, failure)`` of a photo or render; ``mask`` None: the finger mask is found.
    When no print can be made (no finger), print and fingerprint are None and ``failure`` says why."""
    from ..segment.masks import finger_mask

    try:
        contact = contact_like(image, finger_mask(image, name=name) if mask is None else mask, ridges=ridges,
                               period_px=period_px)
    except FS3DError as error:
        return None, None, str(error)
    fingerprint = analyse(contact, nfiq2=nfiq2, extractor=extractor)
    return contact, fingerprint, fingerprint.failure


def _photo_angles(contact: ContactImage, degrees: np.ndarray) -> np.ndarray:
    """Minutia directions on the print (degrees, counter-clockwise from +x, y up as NBIS gives them)
    -> the same directions in the photo's pixel frame (degrees, x right, y down, clockwise)."""
    if degrees.size == 0:
        return degrees
    radians = np.deg2rad(degrees)
    direction = np.stack([np.cos(radians), -np.sin(radians)], 1)  # print pixel frame (y down)
    back = direction @ np.linalg.inv(contact.affine[:, :2]).T
    return np.rad2deg(np.arctan2(back[:, 1], back[:, 0])) % 360.0


def match_score(a: Fingerprint, b: Fingerprint) -> int:
    """bozorth3's score of two fingerprints (0 when either has no minutiae)."""
    if a.template is None or b.template is None or not a.count or not b.count:
        return 0
    return int(a.template.compare(b.template))
