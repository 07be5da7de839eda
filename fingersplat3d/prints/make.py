"""``fs3d print``'s work: a print per input, its files and its row of ``prints.csv``.

* A reconstruction folder (``fs3d fuse -o``): its rolled-equivalent print
  (:mod:`fingersplat3d.prints.rolled`) from its depth maps, cameras and photos. The finger of each
  view is where its depth map has values. The scale, in this order: ``cameras.json`` in mm (a rig
  or synthetic cameras), ``--px-per-mm`` (the photos' pixels per mm at the finger), or the ridge
  period (9 px at 500 ppi, as for the photos' prints): first the photos' median period, then the
  print's own (measured on the flattened skin, it is not shortened toward the photos' rims, so it is
  the same whatever the finger's roll; the print is redone when the two differ by more than 3 %).
* An image file: its finger unrolled through the ``prior``'s surface, as a model's is through its own
  (:func:`unrolled_photo`), on any background the finger mask handles; with ``flat``, the photo scaled and turned
  alone (:func:`fingersplat3d.eval.contact.contact_like`).

Writes ``OUT/<name>.png`` (8-bit gray, ridges dark, white outside the skin), ``OUT/masks/<name>.png``,
``OUT/points/<name>.npy`` (rolled prints: ``[H, W, 3]`` float32 model points per print pixel, NaN
outside: minutiae found on the print carried to the model, and through ``cameras.json`` to every
photo), ``OUT/photo_xy/<name>.npy`` (photos' prints: ``[H, W, 2]`` float32, the photo pixel each print pixel
shows, NaN outside), ``OUT/pictures/<name>.png`` (the print beside its source) and ``OUT/prints.csv``. An input that
gives no print is a ``failed`` row with its reason; the others are still made. A print whose skin is smaller than
NFIQ2 scores (197 px a side: 10 mm at 500 ppi, a finger too small in its photos for a usable print) is written but
is a ``too small`` row, with the reason, when NFIQ2 was asked for.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import FS3DError, InputError
from ..eval.contact import MIN_SIDE, TARGET_PERIOD_PX, ContactImage
from .rolled import RolledEquivalent

if TYPE_CHECKING:
    from ..scene import Camera

__all__ = ["COLUMNS", "make_print", "nfiq2_region", "photo_pixels", "print_reconstruction", "print_photo",
           "unrolled_photo", "unrolled_print", "ROLLED_PPI"]

ROLLED_PPI = 500.0
PERIOD_SLACK = 0.03  # a print scaled by the ridge period is redone when its own period is off by more than this
COLUMNS = ("name", "source", "kind", "status", "reason", "ppi", "scale_from", "width_px", "height_px", "area_mm2",
           "coverage_deg", "centred_on", "nfiq2", "minutiae", "nfiq2_note", "seconds")
PICTURE_HEIGHT = 480
POINTS_PER_VIEW = 80_000  # model points per view the chart is made from (the depth map, strided)


def print_reconstruction(folder: Path, *, px_per_mm: float | None = None, ppi: float = ROLLED_PPI,
                         ridges: str = "bright", enhancer: str = "gabor") -> tuple[RolledEquivalent, str, np.ndarray]:
    """``(print, where its scale came from, the photo it owes most to)`` of a reconstruction folder."""
    from ..align.correspond.texture import as_gray
    from ..io.reconstruction_folder import ReconstructionFolder

    rec = ReconstructionFolder(folder)
    names = [name for name in rec.names if rec.has_depth(name)]
    if not names:
        raise InputError(f"{folder}: the reconstruction has no depth maps (depth/<view>.npy): nothing to unroll")
    views, photos = [], []
    for name in names:
        depth = rec.depth(name)
        if np.isfinite(depth).sum() < 64:
            continue
        gray = as_gray(rec.photo(name), name=f"view {name!r}'s photo")
        if gray.shape != depth.shape:
            raise InputError(f"view {name!r}: its photo is {gray.shape[1]}x{gray.shape[0]}, its depth map "
                             f"{depth.shape[1]}x{depth.shape[0]}")
        views.append((name, rec.cameras.cameras[name], depth, gray))
        photos.append(gray)
    if not views:
        raise InputError(f"{folder}: no view's depth map covers a finger")
    if rec.cameras.units == "mm" or rec.cameras.scale_mm_per_unit is not None:
        mm_per_unit = 1.0 if rec.cameras.units == "mm" else float(rec.cameras.scale_mm_per_unit)
        scale, scale_from = ppi / 25.4 * mm_per_unit, "cameras (mm)"
    elif px_per_mm is not None:
        per_view = [float(camera.K[0, 0]) / (float(np.nanmedian(depth)) * px_per_mm) for _, camera, depth, _ in views]
        scale, scale_from = ppi / 25.4 * float(np.median(per_view)), "--px-per-mm"
    else:
        scale, scale_from = None, "ridge period"
    result = unrolled_print(views, scale, ppi=ppi, ridges=ridges, enhancer=enhancer)
    source = photos[int(np.argmax([result.view_share[name] for name, *_ in views]))]
    return result, scale_from, source


def unrolled_print(views, px_per_unit: float | None = None, *, ppi: float = ROLLED_PPI, ridges: str = "bright",
                   enhancer: str = "gabor") -> RolledEquivalent:
    """The rolled-equivalent print of ``views``, each ``(name, camera, depth, gray photo)`` with its depth map NaN
    off the finger: the skin chart of their points unrolled at ``px_per_unit`` print pixels per model unit, or (None)
    scaled by the ridge period: first the photos' median period, then the print's own (measured on the flattened skin,
    it is not shortened toward the photos' rims, so it is the same whatever the finger's roll; the print is redone
    when the two differ by more than :data:`PERIOD_SLACK`)."""
    from ..align.correspond.texture import estimate_ridge_period, ridge_area, ridge_texture
    from ..segment.silhouette import orient_frames
    from .rolled import PrintView, default_px_per_unit, rolled_print
    from .skin_chart import finger_frame, skin_chart

    prints, periods, points = [], [], []
    for name, camera, depth, gray in views:
        mask = np.isfinite(depth)
        area = ridge_area(mask) & mask
        period = estimate_ridge_period(gray, area)
        prints.append(PrintView(name, camera, depth, ridge_texture(gray, area, period), area))
        periods.append(period)
        cloud = camera.depth_to_points(depth)[mask]
        points.append(cloud[:: max(1, len(cloud) // POINTS_PER_VIEW)])
    frames = orient_frames([view.area if view.area.sum() >= 64 else np.isfinite(view.depth) for view in prints])
    cloud = np.concatenate(points)
    chart = skin_chart(cloud, finger_frame(cloud, [view.camera for view in prints],
                                           [(frame.origin, frame.axis) for frame in frames]))
    by_period = px_per_unit is None
    scale = default_px_per_unit(prints, periods) * ppi / ROLLED_PPI if by_period else px_per_unit
    result = rolled_print(chart, prints, scale, ridges=ridges, enhancer=enhancer)
    if by_period and abs(result.period_px / (TARGET_PERIOD_PX * ppi / ROLLED_PPI) - 1) > PERIOD_SLACK:
        # The photos foreshorten the ridges toward their rims; the print does not: its own period sets the scale.
        result = rolled_print(chart, prints, scale * TARGET_PERIOD_PX * ppi / ROLLED_PPI / result.period_px,
                              ridges=ridges, enhancer=enhancer)
    return result


def print_photo(path: Path, *, ridges: str = "bright", flat: bool = False,
                enhancer: str = "gabor") -> tuple[ContactImage | RolledEquivalent, np.ndarray, np.ndarray]:
    """The print of one photo (:func:`unrolled_photo`; ``flat``: the photo scaled and turned,
    :func:`~fingersplat3d.eval.contact.contact_like`), the photo (gray), and the photo pixel ``(u, v)`` each print pixel
    shows (``[H, W, 2]`` float32, NaN off the print's skin)."""
    from ..align.correspond.texture import as_gray
    from ..eval.contact import contact_like
    from ..io.images import read_image
    from ..segment.masks import finger_mask

    image = read_image(path)
    gray = as_gray(image, name=str(path))
    mask = finger_mask(gray, name=path.name)
    if flat:
        made = contact_like(gray, mask, ridges=ridges)
        return made, gray, made.photo_pixels().astype(np.float32)
    made, camera = unrolled_photo(gray, mask, ridges=ridges, enhancer=enhancer, name=path.name)
    return made, gray, photo_pixels(made, camera).astype(np.float32)


def unrolled_photo(gray: np.ndarray, mask: np.ndarray, *, ridges: str = "bright", enhancer: str = "gabor",
                   name: str = "photo") -> tuple[RolledEquivalent, "Camera"]:
    """One photo's rolled-equivalent print: its finger unrolled through the ``prior`` pointmap's surface (the section
    swept along the silhouette, :mod:`~fingersplat3d.pointmaps.prior`) as :func:`unrolled_print` unrolls a model. A
    photo foreshortens the skin toward the finger's sides; a contact print lays it flat, so the photo's print, scaled
    and turned alone, has its minutiae nearer each other the further they lie from the pad's middle. Also the camera
    the print's points are in (the photo's, at the prior's focal): ``camera.project`` of a print pixel's point is the
    photo pixel it shows."""
    from ..pointmaps.prior import PriorBackend
    from ..scene import Camera, View

    gray = np.asarray(gray, np.float32)
    mask = np.asarray(mask, bool)
    if mask.shape != gray.shape:
        raise InputError(f"{name}: the mask {mask.shape} does not match the image {gray.shape}")
    if mask.sum() < 64:
        raise InputError(f"{name}: the finger mask is empty: there is no finger to make a print of")
    pointmap = PriorBackend().predict_views([View(name, gray, mask)])[0]
    depth = np.where(mask & pointmap.valid, pointmap.points[..., 2], np.nan).astype(np.float32)
    camera = Camera.from_focal(pointmap.focal, gray.shape[1], gray.shape[0])
    return unrolled_print([(name, camera, depth, gray)], ridges=ridges, enhancer=enhancer), camera


def photo_pixels(result: RolledEquivalent, camera: "Camera") -> np.ndarray:
    """``[H, W, 2]``: the photo pixel ``(u, v)`` each pixel of a photo's unrolled print shows (:func:`unrolled_photo`'s
    print and camera), NaN off its skin: minutiae found on the print carried to the photo, or the photo's to the print
    (a flat print's: :meth:`~fingersplat3d.eval.contact.ContactImage.photo_pixels`)."""
    points = result.points.reshape(-1, 3)
    pixels = np.full((len(points), 2), np.nan)
    seen = np.isfinite(points).all(1)
    if seen.any():
        pixels[seen] = camera.project(points[seen])[0]
    return pixels.reshape(result.points.shape[:2] + (2,))


def nfiq2_region(image: np.ndarray, centre_x: float | None = None) -> np.ndarray:
    """The part of a print NFIQ2 can score (at most 799 x 999 px of skin, white margins): a rolled print wider than
    that keeps the middle around ``centre_x`` (the pad's centre line; default the skin's middle), a longer one its tip."""
    from ..eval.contact import MARGIN, MAX_SIZE

    rows, cols = np.nonzero(image < 255)
    if rows.size == 0:
        return image
    width_cap, height_cap = MAX_SIZE[0] - 2 * MARGIN, MAX_SIZE[1] - 2 * MARGIN
    left, right, top, bottom = int(cols.min()), int(cols.max()) + 1, int(rows.min()), int(rows.max()) + 1
    if right - left > width_cap:
        middle = 0.5 * (left + right) if centre_x is None else float(centre_x)
        left = int(np.clip(round(middle - width_cap / 2), left, right - width_cap))
        right = left + width_cap
    bottom = min(bottom, top + height_cap)
    region = np.full((bottom - top + 2 * MARGIN, right - left + 2 * MARGIN), 255, np.uint8)
    region[MARGIN:-MARGIN, MARGIN:-MARGIN] = image[top:bottom, left:right]
    return region


def _scores(image: np.ndarray, nfiq2: bool, centre_x: float | None = None) -> dict:
    """NFIQ2 and the mindtct minutiae count of a print (blank when NIST's tools are not installed); a print larger
    than NFIQ2 takes is scored on its middle (:func:`nfiq2_region`), and the note says so."""
    from ..eval.fingerprint import analyse, nbis_available

    if not nfiq2 or not nbis_available():
        return {}
    region = nfiq2_region(image, centre_x)
    contact = ContactImage.of_print(region)
    found = analyse(contact)
    cut = np.count_nonzero(region < 255) < np.count_nonzero(image < 255)  # skin left out, not only white margins
    note = found.failure or (f"scored on the middle {region.shape[1]}x{region.shape[0]} px" if cut else "")
    scores = {"nfiq2": "" if found.nfiq2 is None else round(found.nfiq2, 1), "minutiae": found.count, "nfiq2_note": note}
    if not contact.fits_nfiq2:  # the region is cut to NFIQ2's largest size, so this is a print too small (or blank)
        width, height = contact.ridge_area_size
        scores.update(status="too small", reason=f"its ridge area is {width}x{height} px, smaller than NFIQ2 scores "
                                                 f"({MIN_SIDE} px a side): the finger is too small in the photos for a "
                                                 "usable print")
    return scores


def make_print(source: Path, name: str, out: Path, *, px_per_mm: float | None = None, ppi: float = ROLLED_PPI,
               ridges: str = "bright", nfiq2: bool = True, mirror: bool = False, enhancer: str = "gabor",
               flat: bool = False) -> dict:
    """One input's print written into ``out``; its ``prints.csv`` row (``status`` done, failed or too small, with the
    reason).
    ``mirror``: left-right, as an inked or scanned contact print is of a photo of the pad. ``enhancer``: of a model's
    or a photo's unrolled print (:func:`~fingersplat3d.prints.rolled.rolled_print`). ``flat``: a photo's print scaled
    and turned, not unrolled (:func:`print_photo`)."""
    from ..io.images import write_image
    from ..viz import gray8, side_by_side

    started = time.perf_counter()
    row = {"name": name, "source": str(source)}
    try:
        if source.is_dir():
            result, scale_from, photo = print_reconstruction(source, px_per_mm=px_per_mm, ppi=ppi, ridges=ridges,
                                                             enhancer=enhancer)
            image, mask, centre_x = result.image, result.mask, result.origin_px[0]
            per_mm = ppi / 25.4
            row.update(kind="rolled", ppi=ppi, scale_from=scale_from, coverage_deg=round(result.coverage_deg, 1),
                       centred_on=result.centred_on)
            points = result.points[:, ::-1] if mirror else result.points
            (out / "points").mkdir(exist_ok=True)
            np.save(out / "points" / f"{name}.npy", np.ascontiguousarray(points))
        elif source.is_file():
            made, photo, photo_xy = print_photo(source, ridges=ridges, flat=flat, enhancer=enhancer)
            per_mm = ROLLED_PPI / 25.4
            row.update(kind="photo flat" if flat else "photo", ppi=ROLLED_PPI, scale_from="ridge period")
            if flat:
                image, mask, centre_x = made.image, made.image < 255, None
                row.update(coverage_deg="", centred_on="")
            else:
                image, mask, centre_x = made.image, made.mask, made.origin_px[0]
                row.update(coverage_deg=round(made.coverage_deg, 1), centred_on=made.centred_on)
            (out / "photo_xy").mkdir(exist_ok=True)
            np.save(out / "photo_xy" / f"{name}.npy", np.ascontiguousarray(photo_xy[:, ::-1] if mirror else photo_xy))
        else:
            raise InputError(f"{source}: no such file or folder")
    except (FS3DError, OSError, ValueError) as error:
        row.update(status="failed", reason=str(error).splitlines()[0] if str(error) else type(error).__name__,
                   seconds=round(time.perf_counter() - started, 2))
        return row
    if mirror:
        image, mask = np.ascontiguousarray(image[:, ::-1]), np.ascontiguousarray(mask[:, ::-1])
        centre_x = None if centre_x is None else image.shape[1] - 1 - centre_x
    for folder in ("masks", "pictures"):
        (out / folder).mkdir(exist_ok=True)
    write_image(out / f"{name}.png", image.astype(np.float32) / 255.0)
    write_image(out / "masks" / f"{name}.png", mask.astype(np.float32))
    picture = side_by_side([gray8(photo), image], PICTURE_HEIGHT, gap=12)  # the source beside its print
    write_image(out / "pictures" / f"{name}.png", picture.astype(np.float32) / 255.0)
    row.update(status="done", reason="", width_px=image.shape[1], height_px=image.shape[0],
               area_mm2=round(float(mask.sum()) / per_mm ** 2, 1))
    row.update(_scores(image, nfiq2, centre_x), seconds=round(time.perf_counter() - started, 2))
    return row
