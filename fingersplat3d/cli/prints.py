"""``fs3d print``: rolled-equivalent prints of reconstructions, contact-like prints of photos."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import EXIT_INCOMPLETE
from ..prints.learned import ENHANCERS
from .common import refuse_missing
from .types import PX_PER_MM, number

__all__ = ["add", "run"]

NAME = "print"
HELP = "fingerprints a matcher can use: the rolled-equivalent print of a 3D model, contact-like prints of photos"


def add(commands) -> None:
    """``fs3d print``: its arguments."""
    prints = commands.add_parser(
        NAME, help=HELP,
        description="For each reconstruction folder (fs3d fuse -o), the rolled-equivalent print of its model: the finger's "
                    "surface unrolled by arc length, textured from the photos that see it most squarely, ridges dark, "
                    "tip up, ~500 ppi; for each image file, its finger unrolled the same way through the surface "
                    "its silhouette gives (--flat: the photo scaled and turned). Writes OUT/<name>.png, "
                    "OUT/masks/, OUT/points/ (per print pixel its 3D point on the model), OUT/photo_xy/ (per print pixel of a "
                    "photo's print the photo pixel it shows), OUT/pictures/ (each print beside "
                    "its source) and OUT/prints.csv. Exit status 4 when some inputs gave no print, or a print too small for "
                    "NFIQ2 (listed in prints.csv).")
    prints.add_argument("inputs", nargs="+", type=Path, help="reconstruction folders and/or image files")
    prints.add_argument("-o", "--output", type=Path, required=True, help="folder for the prints")
    prints.add_argument("--px-per-mm", type=PX_PER_MM,
                        help="the photos' pixels per mm at the finger, to scale a reconstruction made in arbitrary units "
                             "(default: the model's own scale when in mm, else the ridge period: 9 px at 500 ppi)")
    prints.add_argument("--ppi", type=number(float, 100.0, 2000.0), default=500.0, help="print resolution (default 500)")
    prints.add_argument("--ridges", choices=("bright", "dark"), default="bright",
                        help="how ridge crests look in the photos: bright (contactless rigs, the default) or dark")
    prints.add_argument("--mirror", action="store_true",
                        help="mirror the prints left-right, as an inked or scanned contact print is of a photo of the pad "
                             "(default: a photo's handedness, as fs3d synth's true rolled prints)")
    prints.add_argument("--flat", action="store_true",
                        help="a photo's print is the photo scaled to 500 ppi and turned tip up, not unrolled (its skin "
                             "foreshortened toward the finger's sides, as the photo shows it)")
    prints.add_argument("--enhance", choices=ENHANCERS, default="gabor",
                        help="ridge enhancement of a model's or photo's unrolled print: gabor (the default, built in), or pyfing's learned "
                             "snfen or classical gbfen (pip install 'fingersplat3d[learned]'; measured in docs/prints.md)")
    prints.add_argument("--no-nfiq2", action="store_true", help="skip NFIQ2 and the minutiae count")
    prints.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    prints.set_defaults(run=run)


def _names(inputs: list[Path]) -> list[str]:
    """One distinct file name per input: its folder or file stem, numbered when two would clash."""
    names, seen = [], {}
    for path in inputs:
        base = (path.name if path.is_dir() else path.stem) or "print"
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}_{seen[base]}")
    return names


def run(args: argparse.Namespace) -> int:
    refuse_missing(args.inputs)  # a wrong path is bad input; an input that is there but gives no print is a row
    from tqdm import tqdm

    from ..atomic import atomic_dir, check_free
    from ..experiments.tables import write_rows
    from ..prints.make import COLUMNS, make_print

    check_free(args.output, args.overwrite)
    rows = []
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        pairs = list(zip(args.inputs, _names(args.inputs)))
        for source, name in tqdm(pairs, desc="fs3d print", unit="print", disable=None):
            rows.append(make_print(source, name, folder, px_per_mm=args.px_per_mm, ppi=args.ppi, ridges=args.ridges,
                                   nfiq2=not args.no_nfiq2, mirror=args.mirror, enhancer=args.enhance,
                                   flat=args.flat))
        write_rows(folder / "prints.csv", COLUMNS, rows)
    failed = [row for row in rows if row["status"] == "failed"]
    small = [row for row in rows if row["status"] == "too small"]
    for row in rows:
        if row["status"] != "failed":
            centre = "the pad's mirror line" if row.get("centred_on") == "mirror line" else "the cameras' direction"
            extra = f", {row['coverage_deg']:.0f} degrees of roll centred on {centre}" if row["kind"] in ("rolled", "photo") else ""
            score = f", NFIQ2 {row['nfiq2']}" if row.get("nfiq2") not in (None, "") else ""
            print(f"{row['name']}: {row['kind']} print {row['width_px']}x{row['height_px']} px{extra}{score}")
    print(f"wrote {args.output}")
    for row in failed + small:
        what = "" if row["status"] == "failed" else "print too small: "
        print(f"fs3d print: {row['name']}: {what}{row['reason']}", file=sys.stderr)
    counts = [f"{len(failed)} of {len(rows)} inputs gave no print"] if failed else []
    counts += [f"{len(small)} print(s) too small for NFIQ2"] if small else []
    if counts:
        print(f"fs3d print: {', '.join(counts)} (see {args.output / 'prints.csv'})", file=sys.stderr)
        return EXIT_INCOMPLETE
    return 0
