"""``fs3d eval match``: mindtct + bozorth3 matching of photos and synthesized views."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..atomic import atomic_dir, check_free
from ..errors import EXIT_INCOMPLETE, InputError
from ..eval.learned_minutiae import MINUTIAE_EXTRACTORS
from ..prints.learned import ENHANCERS
from .common import finished, nbis_needed
from .types import angle_list

__all__ = ["add", "run"]

NAME = "match"
HELP = "mindtct + bozorth3 matching of photos and synthesized views: EER, FMR, DET"


def add(actions) -> None:
    from ..experiments.match import DEFAULT_ANGLES, GALLERY_NAMING, UWA_NAMING

    match = actions.add_parser(
        NAME, help=HELP,
        description="Make a contact-like print (8-bit gray, ridges dark, ~500 ppi, tip up) of every photo, find its "
                    "minutiae (mindtct) and NFIQ2, and score every two photos of different captures seen by the same "
                    "camera with bozorth3: genuine when the finger is the same (read from the file names), impostor "
                    "otherwise. With --reconstructions, each model is rendered at --angles about its rig axis and "
                    "compared with the real photos of the finger's other captures (and of other fingers). With --rolled, the "
                    "rolled-equivalent print of each model is compared with the other models' and with the photos. With "
                    "--gallery, every photo, render and rolled print is also compared with the contact prints given. Writes "
                    "scores.csv, prints.csv, prints/, summary.md (EER, FNMR at FMR 1 % and 0.01 %, FMR_zero, "
                    "scores by angle) and det.png.")
    match.add_argument("inputs", nargs="+", type=Path, help="photos, or folders of photos")
    match.add_argument("--reconstructions", nargs="+", type=Path, default=[], metavar="REC",
                       help="reconstruction folders from 'fs3d fuse' (with their Gaussians) to synthesize views from")
    match.add_argument("--rolled", nargs="+", type=Path, default=[], metavar="REC",
                       help="reconstruction folders from 'fs3d fuse' whose rolled-equivalent prints (fs3d print) are "
                            "compared with each other and with the photos of the other captures")
    match.add_argument("--gallery", nargs="+", type=Path, default=[], metavar="PRINT",
                       help="contact prints (files or folders; 8-bit gray, ridges dark) that every photo, render and "
                            "rolled print is compared with: contactless against contact")
    match.add_argument("--gallery-naming", default=GALLERY_NAMING,
                       help="regular expression on the gallery's file stems with the named group 'finger', matching the "
                            "probes' finger (default: the whole stem, e.g. 1_1.png for UWA's 1_1_*)")
    match.add_argument("--gallery-as-is", action="store_true",
                       help="compare the gallery's prints, and the rolled prints with photos, at their own scale "
                            "only; by default each is compared at five scales about the photos' ridge period (9 px), "
                            "each pair at its best, since photos carry no scale")
    handedness = match.add_mutually_exclusive_group()
    handedness.add_argument("--mirror", dest="mirror", action="store_const", const="yes", default="auto",
                            help="mirror the probes left-right before comparing them with the gallery (an inked, "
                                 "scanned or live-scan contact print is the mirror image of a photo of the pad). "
                                 "Default: each kind of probe compared both ways, the way whose probes find the "
                                 "stronger best matches kept and said in summary.md")
    handedness.add_argument("--no-mirror", dest="mirror", action="store_const", const="no",
                            help="compare the probes with the gallery as they are (a rolled print made from a model "
                                 "or a texture, as fs3d synth's, has a photo's handedness)")
    match.add_argument("--naming", default=UWA_NAMING,
                       help="regular expression on file stems with named groups 'capture' and 'finger' (or "
                            "'subject' and 'hand'), optional 'view' and 'session'; default: the UWA 3D/2D naming "
                            "subject_finger_capture_session_frame")
    match.add_argument("--views", help="comma-separated view labels to use (e.g. 0,1,2: UWA's plain-light frames)")
    match.add_argument("--angles", type=angle_list, default=DEFAULT_ANGLES,
                       help="render angles in degrees about the rig axis, comma-separated, as --angles=-30,0,30 (default "
                            f"{','.join(f'{a:g}' for a in DEFAULT_ANGLES)})")
    match.add_argument("--enhance", choices=ENHANCERS, default="gabor",
                       help="ridge enhancement of the rolled prints (as fs3d print --enhance)")
    match.add_argument("--minutiae", choices=MINUTIAE_EXTRACTORS, default="mindtct",
                       help="the minutiae bozorth3 compares: NIST's mindtct (the default) or pyfing's learned LEADER "
                            "(pip install '.[learned]'; measured against mindtct in docs/measurements.md)")
    match.add_argument("--flat", action="store_true",
                       help="photos compared with flat-laid prints (--gallery, --rolled) scaled and turned alone, not "
                            "unrolled first (as fs3d print --flat; photos compared with photos or renders always are)")
    match.add_argument("--ridges", choices=("bright", "dark"), default="bright",
                       help="how ridge crests look in the photos (default bright: contactless rigs' plain light)")
    match.add_argument("-o", "--output", type=Path, required=True, help="folder for the results")
    match.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    match.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..experiments.match import handedness_sentence, parse_samples, read_gallery, run_match_evaluation
    from ..io.images import find_files

    nbis_needed("fs3d eval match")
    check_free(args.output, args.overwrite)
    views = {v.strip() for v in args.views.split(",") if v.strip()} if args.views else None
    samples, unparsed = parse_samples(find_files(args.inputs), args.naming, views)
    for path in unparsed:
        print(f"fs3d eval match: {path.name} does not follow the naming pattern; skipped", file=sys.stderr)
    gallery = read_gallery(args.gallery, args.gallery_naming) if args.gallery else []
    if not samples or (len({s.capture for s in samples}) < 2 and not gallery):
        raise InputError(f"{len(samples)} photos from {len({s.capture for s in samples})} capture(s): matching needs "
                         "photos of at least two captures (or of one, with --gallery), named so that the finger and capture can be read")
    for folder in [*args.reconstructions, *args.rolled]:
        if not (folder / "cameras.json").is_file():
            raise InputError(f"{folder}: not a reconstruction folder (no cameras.json; make one with 'fs3d fuse')")
    with atomic_dir(args.output, overwrite=args.overwrite) as folder:
        summary = run_match_evaluation(samples, folder, reconstructions=args.reconstructions, angles=args.angles,
                                       naming=args.naming, ridges=args.ridges, rolled=args.rolled,
                                       gallery=gallery, mirror=args.mirror, enhancer=args.enhance,
                                       flat=args.flat, extractor=args.minutiae,
                                       gallery_about_period=not args.gallery_as_is)
    for protocol, rates in summary["protocols"].items():
        eer = "no EER (genuine or impostor pairs missing)" if rates.get("eer") is None else f"EER {rates['eer']:.1%}"
        print(f"{protocol}: {rates['genuine']} genuine, {rates['impostor']} impostor comparisons; {eer}")
    for protocol, way in summary["handedness"].items():
        print(handedness_sentence(protocol, way))
    print(f"wrote {args.output}")
    if not summary["protocols"]:
        print("fs3d eval match: no two prints could be compared (see summary.md)", file=sys.stderr)
        return EXIT_INCOMPLETE
    return finished("fs3d eval match", len(summary["failed"]), summary["prints"], "photos or renders gave no print",
                     args.output)
