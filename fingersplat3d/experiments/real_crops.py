"""Real captures cropped so that no fingertip is in the frame: the rig check of crops, against the whole captures.

Datasets publish crops cut straight across the finger, and another group's renders are cut at both ends; the shape
work's target is that such views register as well as whole fingers. The real dev captures show the whole fingertip,
so :func:`crop_without_tip` cuts each photo at run time (nothing is written next to the data): symmetric about the
image centre, so that the principal point stays where the fit assumes it (a crop off centre would move it, and its
turns with it, by up to 9 degrees at these sizes), with the tip-side edge :data:`CUT_SHARE` of the finger's width past
the fingertip (the whole cap outside the frame); the far edge then cuts the finger too, as far from the centre.

Each crop is scored by :func:`~fingersplat3d.eval.rig_consistency.deviation_against` the whole captures' rig mean: the
same cameras, so the crop's turns should be the rig's. Pure numpy (the finger found by
:func:`~fingersplat3d.segment.masks.finger_mask`).
"""
from __future__ import annotations

import numpy as np

__all__ = ["CUT_SHARE", "FILL_ACROSS", "crop_without_tip", "crop_filling", "tipless_window", "filling_window",
           "centred_filling_window", "crop_table"]

CUT_SHARE = 0.3
"""The tip-side edge of the crop lies this share of the finger's width past the fingertip, along the finger."""
FILL_ACROSS = 0.8
"""A crop that the finger fills keeps this share of the finger's width across it (:func:`crop_filling`)."""
_MIN_HALF = 0.2  # the crop keeps at least this share of the finger's width on either side of the centre


def crop_without_tip(view, share: float = CUT_SHARE):
    """``view`` cropped about its image centre along the image axis nearest the finger's, the fingertip and ``share``
    of the finger's width behind it outside the frame (:func:`tipless_window`); None when the finger is not found or
    its tip lies too near or past the centre for that."""
    return _cropped(view, lambda mask: tipless_window(mask, share))


def _cropped(view, window):
    """``view`` cut to ``window(mask)`` of its finger mask (rows and columns, or None: no crop); None too when the
    finger is not found."""
    from ..errors import InputError
    from ..scene import View
    from ..segment.masks import finger_mask

    try:
        mask = finger_mask(view.image, name=view.name)
    except InputError:
        return None
    keep = window(mask)
    return None if keep is None else View(view.name, view.image[keep])


def _along_columns(mask: np.ndarray) -> tuple[np.ndarray, bool, int, float, float]:
    """``(along, horizontal, sign, tip, width)``: the finger ``mask`` with the finger running along its columns (the
    mask itself where it runs nearer the image's columns than its rows, ``horizontal``; else its transpose), ``+1``
    where its tip lies toward the high columns and ``-1`` toward the low, the tip's column, and the finger's width
    (:func:`~fingersplat3d.segment.silhouette.widest_disc`)."""
    from ..segment.silhouette import silhouette_frame, widest_disc

    frame = silhouette_frame(mask)
    horizontal = bool(abs(frame.axis[0]) >= abs(frame.axis[1]))
    along = mask if horizontal else mask.T
    sign = 1 if (frame.axis[0] if horizontal else frame.axis[1]) > 0 else -1
    seen = np.nonzero(along.any(axis=0))[0]
    return along, horizontal, sign, float(seen.max() if sign > 0 else seen.min()), widest_disc(mask)


def tipless_window(mask: np.ndarray, share: float = CUT_SHARE) -> tuple[slice, slice] | None:
    """The rows and columns of a crop of the finger ``mask`` (``[H, W]`` bool) about the image centre along the image
    axis nearest the finger's, the fingertip and ``share`` of the finger's width behind it outside the window (at least
    :data:`_MIN_HALF` of the width kept each side of the centre, the tip still half that share outside); None when its
    tip lies too near or past the centre for that."""
    along, horizontal, sign, tip, width = _along_columns(mask)
    size = along.shape[1]
    centre = (size - 1) / 2.0
    toward_high = sign > 0
    cut = tip - share * width if toward_high else tip + share * width
    half = max(abs(cut - centre), _MIN_HALF * width)
    edge = centre + half if toward_high else centre - half  # the crop's tip-side edge
    if width <= 0 or (cut > centre) != toward_high or abs(tip - edge) < 0.5 * share * width or not (
            0 <= centre - half and centre + half <= size - 1):
        return None
    first, last = int(np.ceil(centre - half)), int(np.floor(centre + half)) + 1
    return (slice(None), slice(first, last)) if horizontal else (slice(first, last), slice(None))


def filling_window(mask: np.ndarray, across: float, past_tip: float = 0.3, length: float = 1.6) -> tuple[slice, slice]:
    """The rows and columns of a tight crop of the finger ``mask`` (``[H, W]`` bool) that it fills across its width: a
    window ``across`` times the finger's width (:func:`~fingersplat3d.segment.silhouette.widest_disc`) about the pad's
    middle across the finger (under 1: both flanks cut by the frame), from ``past_tip`` widths beyond the fingertip to
    ``length`` widths behind it (the base cut), clipped to the image. A dataset's or a phone's close-up crop."""
    along_first, horizontal, sign, tip, width = _along_columns(mask)
    start, stop = sorted((int(tip + sign * past_tip * width), int(tip - sign * length * width)))
    start, stop = max(start, 0), min(stop, along_first.shape[1])
    rows = np.nonzero(along_first[:, start:stop].any(axis=1))[0]
    middle = 0.5 * (rows.min() + rows.max())
    first, last = max(int(middle - across * width / 2), 0), min(int(middle + across * width / 2), along_first.shape[0])
    window = (slice(first, last), slice(start, stop))
    return window if horizontal else window[::-1]


def crop_filling(view, across: float = FILL_ACROSS, past_tip: float = CUT_SHARE, on_finger: bool = False):
    """``view`` cropped about its image centre so that the finger fills it across its width
    (:func:`centred_filling_window`): a tight crop with both flanks cut and the tip in view, the principal point
    kept; ``on_finger``: about the finger's pad instead (:func:`filling_window`), as a dataset crops, the principal
    point moved with the crop. None when the finger is not found or the window does not fit in the photo."""
    return _cropped(view, lambda mask: filling_window(mask, across, past_tip) if on_finger
                    else centred_filling_window(mask, across, past_tip))


def centred_filling_window(mask: np.ndarray, across: float = FILL_ACROSS,
                           past_tip: float = CUT_SHARE) -> tuple[slice, slice] | None:
    """The rows and columns of a crop of the finger ``mask`` symmetric about the image centre (the principal point
    stays where the fit assumes it): ``across`` times the finger's width across it, and along it from ``past_tip``
    widths beyond the fingertip to as far on the other side of the centre (the base cut). None where the tip lies
    on the far side of the centre, or the window does not fit in the image."""
    along_first, horizontal, sign, tip, width = _along_columns(mask)
    rows, columns = along_first.shape
    centre_c, centre_r = (columns - 1) / 2.0, (rows - 1) / 2.0
    half_c, half_r = sign * (tip - centre_c) + past_tip * width, across * width / 2.0
    if width <= 0 or sign * (tip - centre_c) <= 0 or centre_c - half_c < 0 or centre_c + half_c > columns - 1 \
            or centre_r - half_r < 0:
        return None
    window = (slice(int(np.ceil(centre_r - half_r)), int(np.floor(centre_r + half_r)) + 1),
              slice(int(np.ceil(centre_c - half_c)), int(np.floor(centre_c + half_c)) + 1))
    return window if horizontal else window[::-1]


def crop_table(records: list[dict], deviations: dict) -> str:
    """The markdown table of the cropped captures: registered views, crop size, each pair's deviation from the whole
    captures' rig mean, the focal, whether the photos held it and the largest sensitivity; then the medians."""
    lines = ["| capture | views registered | crop px | rig deviation 0-1 / 0-2 / 1-2 ° | focal px | focal held | "
             "sensitivity max ° | warned |", "|---|---|---|---|---|---|---|---|"]
    for r in records:
        values = [deviations.get(p, {}).get(r["capture"]) for p in ("01", "02", "12")]
        deviation = " / ".join("–" if v is None else f"{v:.2f}" for v in values)
        sensitivity = [v for v in r.get("turn_sensitivity_deg", {}).values() if v is not None]
        held = r.get("focal_probe", {}).get("held")
        size = " ".join(f"{w}×{h}" for w, h in r["sizes"][:1])
        lines.append(f"| {r['capture']} | {r['registered']}/{len(r['sizes'])} | {size} | {deviation} | {r['focal']:.0f} | "
                     f"{'–' if held is None else 'yes' if held else 'no'} | "
                     f"{max(sensitivity) if sensitivity else float('nan'):.2f} | {'yes' if r.get('warned_turns') else 'no'} |")
    whole = [r for r in records if r["registered"] == len(r["sizes"])]
    medians = " / ".join(f"{np.median(list(deviations[p].values())):.2f}" if deviations.get(p) else "–"
                         for p in ("01", "02", "12"))
    largest = max((v for p in deviations.values() for v in p.values()), default=float("nan"))
    lines.append(f"| **median** | {len(whole)}/{len(records)} captures whole | | **{medians}** (max {largest:.2f}) | | | | |")
    return "\n".join(lines)
