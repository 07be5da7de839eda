"""Minutiae as an ISO/IEC 19794-2:2005 finger minutiae record, the bytes ``nbis-py`` reads for bozorth3.

``nbis-py`` matches only templates it made (mindtct's) or read from this record
(``NbisExtractor.load_iso_19794_2_2005``), so minutiae found by another extractor (pyfing's LEADER,
:mod:`.learned_minutiae`) reach bozorth3 through it. The layout is the one ``nbis-py`` 0.1.3 writes
(``Minutiae.to_iso_19794_2_2005``), byte for byte (tested): a 24-byte record header (``FMR\\0``, `` 20\\0``,
the record's length, the capture device, the image's width and height, resolution and view count left 0), a
2-byte finger view header whose second byte is the minutiae count, then 6 bytes per minutia: its kind (2 bits:
1 ending, 2 bifurcation) over x (14 bits), y (16 bits), its direction in 256ths of a turn (counter-clockwise from
+x with y up, mindtct's convention) and its quality (0-100). Pure ``struct``.
"""
from __future__ import annotations

import struct
from typing import Sequence

import numpy as np

__all__ = ["MAX_MINUTIAE", "iso_minutiae_record"]

MAX_MINUTIAE = 255
"""The record counts its minutiae in one byte; the best by quality are kept (bozorth3 reads 150 at most anyway)."""
_KIND = {"ending": 1, "bifurcation": 2}


def iso_minutiae_record(width: int, height: int, xy: np.ndarray, angles_deg: np.ndarray, kinds: Sequence[str],
                        quality: np.ndarray) -> bytes:
    """The record of minutiae at pixel ``xy`` [N, 2] (x right, y down, inside ``width`` x ``height``), directions
    ``angles_deg`` [N] (counter-clockwise from +x, y up), ``kinds`` ("ending" | "bifurcation") and ``quality`` [N]
    (0-100); more than :data:`MAX_MINUTIAE` keep the best by quality."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    angles = np.asarray(angles_deg, np.float64).reshape(-1)
    quality = np.asarray(quality, np.float64).reshape(-1)
    if not len(xy) == len(angles) == len(kinds) == len(quality):
        raise ValueError("xy, angles_deg, kinds and quality must describe the same minutiae")
    if not 0 < width < 2 ** 14 or not 0 < height < 2 ** 14:
        raise ValueError(f"a record's image must be 1-16383 px a side, got {width} x {height}")
    if len(xy) and not (np.isfinite(xy).all() and np.isfinite(angles).all() and np.isfinite(quality).all()):
        raise ValueError("minutiae must be finite")
    keep = np.sort(np.argsort(-quality, kind="stable")[:MAX_MINUTIAE])  # the best, in their given order
    columns = np.clip(np.rint(xy[keep, 0]), 0, width - 1).astype(int)
    rows = np.clip(np.rint(xy[keep, 1]), 0, height - 1).astype(int)
    steps = np.rint(angles[keep] % 360.0 / (360.0 / 256.0)).astype(int) % 256
    scores = np.clip(np.rint(quality[keep]), 0, 100).astype(int)
    body = b"".join(struct.pack(">HHBB", _KIND[kinds[k]] << 14 | c, r, s, q)
                    for k, c, r, s, q in zip(keep, columns, rows, steps, scores))
    header = b"FMR\x00" + b" 20\x00" + struct.pack(">IHHHHHBBBB", 26 + len(body), 0, width, height, 0, 0, 0, 0, 0,
                                                    len(keep))
    return header + body
