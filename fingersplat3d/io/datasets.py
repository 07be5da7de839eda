"""Dataset layouts turned into :class:`~fingersplat3d.scene.Capture` objects.

Loaded captures have no cameras and no depth; masks only where the layout has them. Images keep
what the file holds (grayscale stays ``H x W``) unless ``gray`` says otherwise.

* **UWA 3D/2D** raw frames, ``{subject}_{finger}_{capture}_{session}_{frame}.jpg`` as the database
  names them (``2_2_7_1_0.jpg``), or without the session, ``{subject}_{finger}_{capture}_{frame}.jpg``
  (1280x1024, 8-bit gray, a camera sometimes stored portrait; ids alphanumeric). Frames 0-2 are the three simultaneous views under plain light and become
  the views ``f0, f1, f2`` of one capture per ``(subject, finger, capture)``; frames 3-5 are the
  same cameras under structured light, skipped unless ``structured_light=True`` (then views
  ``f3, f4, f5`` follow). Frames above 5 are ignored.
* **CFPose**: ``{finger}_{pose}.{png|jpg|bmp}`` (e.g. ``1_1.bmp`` ... ``1_10.bmp``; finger ids
  alphanumeric, ``-`` allowed) become one capture per finger with views ``p1, p2, ...`` ordered
  by pose number.
* **A plain image folder** (or an explicit list of files) becomes one capture whose views are
  the file stems.

Dataset folders are searched recursively; a plain image folder is not (its ``masks/`` would be
mistaken for views). Names are sorted naturally (``img2`` before ``img10``).
"""
from __future__ import annotations

import re
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Iterable, Sequence

from ..errors import input_error
from ..scene import Capture, View
from .capture import is_capture_folder, read_capture
from .exif import exif_focal
from .images import IMAGE_SUFFIXES, UNREAD_SUFFIXES, read_images, read_mask, unread_photos, unread_photos_note

__all__ = ["UWA_VIEW_FRAMES", "UWA_STRUCTURED_FRAMES", "UWAGroup", "find_uwa_groups", "load_uwa",
           "load_cfpose", "load_image_folder", "load_any", "natural_key", "photo_folders"]

UWA_VIEW_FRAMES = (0, 1, 2)
UWA_STRUCTURED_FRAMES = (3, 4, 5)
_UWA_NAME = re.compile(r"^(?P<subject>[A-Za-z0-9]+)_(?P<finger>[A-Za-z0-9]+)_(?P<capture>[A-Za-z0-9]+)"
                       r"(?:_(?P<session>[A-Za-z0-9]+))?_(?P<frame>\d+)$")
_CFPOSE_NAME = re.compile(r"^(?P<finger>[A-Za-z0-9-]+)_(?P<pose>\d+)$")
_CFPOSE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
_MASK_SUFFIX = "_mask"


def natural_key(text: str) -> tuple:
    """Sort key that orders embedded numbers by value: ``img2`` before ``img10``."""
    return tuple((0, int(part), "") if part.isdigit() else (1, 0, part.lower()) for part in re.split(r"(\d+)", text))


def _same_id(wanted: object, found: str) -> bool:
    """``wanted`` (None = any) matches ``found``; numeric ids compare by value (``1`` == ``"001"``)."""
    if wanted is None:
        return True
    wanted = str(wanted)
    return wanted == found or (wanted.isdigit() and found.isdigit() and int(wanted) == int(found))


def photo_folders(folder: str | Path) -> list[Path]:
    """The folders directly inside ``folder`` that hold photos of their own (hidden and unreadable ones left out), in
    natural order: a user's one folder per capture, each a capture of ``fs3d batch``'s (:mod:`.jobs`)."""
    def holds_photos(inner: Path) -> bool:
        try:
            return inner.is_dir() and not inner.name.startswith(".") and bool(_image_files(inner, recursive=False)[0])
        except OSError:  # a folder that cannot be read: not one to name
            return False

    try:
        held = [inner for inner in Path(folder).iterdir() if holds_photos(inner)]
    except OSError:
        return []
    return sorted(held, key=lambda p: natural_key(p.name))


def _inner_photos_note(folder: Path, shown: int = 3) -> str:
    """``"; its folders 'a', 'b' hold photos: ..."`` when :func:`photo_folders` finds some in ``folder`` (a user
    pointing at the folder above a capture's), else ``""``: the end of a "holds no images" sentence."""
    held = sorted(inner.name for inner in photo_folders(folder))
    if not held:
        return ""
    names = ", ".join(repr(name) for name in held[:shown])
    names += f" and {len(held) - shown} more" if len(held) > shown else ""
    return (f"; its folder{'s' if len(held) > 1 else ''} {names} hold{'' if len(held) > 1 else 's'} photos: give one "
            "to fuse it, or the folder to `fs3d batch` to fuse each")


def _image_files(folder_or_files: str | Path | Iterable[str | Path], recursive: bool) -> tuple[list[Path], Path]:
    """Image files of a folder (or the given files) and the path to name in errors."""
    if isinstance(folder_or_files, (str, Path)):
        folder = Path(folder_or_files)
        if not folder.exists():
            raise input_error(folder, "folder not found")
        if not folder.is_dir():
            return [folder], folder
        walker = folder.rglob("*") if recursive else folder.iterdir()
        files = [path for path in walker if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES
                 and not any(part.startswith(".") for part in path.relative_to(folder).parts)]
        return sorted(files, key=lambda path: natural_key(str(path))), folder
    files = [Path(path) for path in folder_or_files]
    if not files:
        raise input_error(None, "no image files were given")
    for path in files:
        if not path.is_file():
            raise input_error(path, "file not found")
    return files, files[0].parent


# -------------------------------------------------------------------------------------------- UWA

@dataclass(frozen=True, eq=False)
class UWAGroup:
    """The frames of one UWA capture: ``frames[n]`` is the file of frame ``n``."""

    subject: str
    finger: str
    capture: str
    session: str | None
    frames: dict[int, Path]

    @property
    def label(self) -> str:
        return f"subject {self.subject}, finger {self.finger}, capture {self.capture}" + (
            f", session {self.session}" if self.session is not None else "")

    @property
    def stem(self) -> str:
        """The shared part of the frame names (``2_2_7_1`` for ``2_2_7_1_0.jpg``)."""
        return "_".join(part for part in (self.subject, self.finger, self.capture, self.session) if part is not None)


def find_uwa_groups(folder_or_files: str | Path | Iterable[str | Path], subject: object = None,
                    finger: object = None, capture: object = None) -> list[UWAGroup]:
    """Group UWA frame files by ``(subject, finger, capture)``, filtered; reads no pixels.

    Files not named like UWA frames are ignored; if none is, or the filter leaves nothing, that
    is an ``InputError``. Two files for the same frame are an error too.
    """
    files, where = _image_files(folder_or_files, recursive=True)
    groups: dict[tuple[str, str, str, str | None], dict[int, Path]] = {}
    matched = 0
    for path in files:
        match = _UWA_NAME.match(path.stem)
        if not match:
            continue
        matched += 1
        if not (_same_id(subject, match["subject"]) and _same_id(finger, match["finger"])
                and _same_id(capture, match["capture"])):
            continue
        frames = groups.setdefault((match["subject"], match["finger"], match["capture"], match["session"]), {})
        frame = int(match["frame"])
        if frame in frames:
            raise input_error(path, f"frame {frame} of this UWA capture is also in {frames[frame]}")
        frames[frame] = path
    if not matched:
        raise input_error(where, "no files named like UWA frames ({subject}_{finger}_{capture}_{frame}.jpg)")
    if not groups:
        raise input_error(where, f"no UWA frames match subject={subject}, finger={finger}, capture={capture}")
    ordered = sorted(groups, key=lambda key: tuple(natural_key(part or "") for part in key))
    return [UWAGroup(*key, frames=groups[key]) for key in ordered]


def load_uwa(folder_or_files: str | Path | Iterable[str | Path], subject: object = None, finger: object = None,
             capture: object = None, structured_light: bool = False, *, gray: bool | None = None) -> list[Capture]:
    """Load UWA 3D/2D raw frames as one 3-view capture per ``(subject, finger, capture)``.

    Views are ``f0, f1, f2`` (plus ``f3, f4, f5`` with ``structured_light``); a group missing one
    of them is an ``InputError`` naming the group and the missing file. Metadata: ``dataset``
    ``"uwa"``, ``subject``, ``finger``, ``capture`` (strings), ``sources`` (view -> path) and
    ``lighting`` (view -> ``"plain"`` | ``"structured"``).
    """
    wanted = UWA_VIEW_FRAMES + (UWA_STRUCTURED_FRAMES if structured_light else ())
    folder = isinstance(folder_or_files, (str, Path)) and Path(folder_or_files).is_dir()
    # a folder is a dataset, its captures whole; files named one by one are fused as given (load_any)
    hint = " (a folder is read as a dataset; to fuse only the frames there, give them as files)" if folder else ""
    captures = []
    for group in find_uwa_groups(folder_or_files, subject, finger, capture):
        for frame in wanted:
            if frame not in group.frames:
                some = next(iter(group.frames.values()))
                expected = some.with_name(f"{group.stem}_{frame}{some.suffix}")
                raise input_error(expected, f"UWA {group.label} is missing frame {frame}{hint}")
        paths = [group.frames[frame] for frame in wanted]
        images = read_images(paths, gray)
        names = [f"f{frame}" for frame in wanted]
        metadata = _uwa_metadata(group, wanted)
        captures.append(Capture(tuple(View(name, image) for name, image in zip(names, images)), metadata))
    return captures


def _uwa_metadata(group: UWAGroup, frames: Sequence[int]) -> dict:
    """A UWA capture's metadata; its views are ``f<frame>`` for ``frames``, in that order."""
    names = [f"f{frame}" for frame in frames]
    return {"dataset": "uwa", "subject": group.subject, "finger": group.finger, "capture": group.capture,
            "session": group.session, "name": group.stem,
            "sources": {name: str(group.frames[frame]) for name, frame in zip(names, frames)},
            "lighting": {name: "plain" if frame in UWA_VIEW_FRAMES else "structured" for name, frame in zip(names, frames)}}


# ----------------------------------------------------------------------------------------- CFPose

def _cfpose_fingers(folder_or_files: str | Path | Iterable[str | Path], finger: object) -> dict[str, dict[int, Path]]:
    files, where = _image_files(folder_or_files, recursive=True)
    fingers: dict[str, dict[int, Path]] = {}
    matched = 0
    for path in files:
        match = _CFPOSE_NAME.match(path.stem)
        if not match or path.suffix.lower() not in _CFPOSE_SUFFIXES:
            continue
        matched += 1
        if not _same_id(finger, match["finger"]):
            continue
        poses = fingers.setdefault(match["finger"], {})
        pose = int(match["pose"])
        if pose in poses:
            raise input_error(path, f"pose {pose} of CFPose finger {match['finger']} is also in {poses[pose]}")
        poses[pose] = path
    if not matched:
        raise input_error(where, "no files named like CFPose images ({finger}_{pose}.png|jpg|bmp)")
    if not fingers:
        raise input_error(where, f"no CFPose images of finger {finger}")
    return fingers


def load_cfpose(folder: str | Path | Iterable[str | Path], finger: object = None, *,
                gray: bool | None = None) -> list[Capture]:
    """Load CFPose images as one capture per finger, views ``p<pose>`` in pose order.

    Any number of poses is accepted (CFPose has 10). Metadata: ``dataset`` ``"cfpose"``,
    ``finger``, ``poses`` (list of ints) and ``sources`` (view -> path).
    """
    captures = []
    fingers = _cfpose_fingers(folder, finger)
    for finger_id in sorted(fingers, key=natural_key):
        poses = sorted(fingers[finger_id])
        images = read_images([fingers[finger_id][pose] for pose in poses], gray=gray)
        views = tuple(View(f"p{pose}", image) for pose, image in zip(poses, images))
        metadata = {"dataset": "cfpose", "finger": finger_id, "poses": poses,
                    "sources": {f"p{pose}": str(fingers[finger_id][pose]) for pose in poses}}
        captures.append(Capture(views, metadata))
    return captures


# ------------------------------------------------------------------------------------ image folder

def _find_mask(image: Path) -> Path | None:
    for candidate in (image.parent / "masks" / f"{image.stem}.png", image.parent / f"{image.stem}{_MASK_SUFFIX}.png"):
        if candidate.is_file():
            return candidate
    return None


def load_image_folder(folder_or_files: str | Path | Iterable[str | Path], gray: bool | None = None,
                      min_views: int = 1) -> Capture:
    """One capture from a folder of images (natural name order) or a list of files (given order).

    Views are named by file stem; ``<stem>_mask.png`` files in the folder are masks, not views,
    and a mask is found as ``masks/<stem>.png`` or ``<stem>_mask.png`` next to its image. Views may
    differ in size; fewer than ``min_views`` images is an ``InputError``.
    Metadata: ``dataset`` ``"images"``, ``sources`` (view -> path) and ``exif_focal`` (view -> the focal its EXIF
    records in its pixels, ``focal_px`` or None, and ``how``: :func:`~fingersplat3d.io.exif.exif_focal`).
    """
    explicit = not isinstance(folder_or_files, (str, Path)) or Path(folder_or_files).is_file()
    files, where = _image_files(folder_or_files, recursive=False)
    if explicit:
        for path in files:
            if path.suffix.lower() in UNREAD_SUFFIXES:
                raise input_error(path, unread_photos([UNREAD_SUFFIXES[path.suffix.lower()]]))
            if path.suffix.lower() not in IMAGE_SUFFIXES:
                raise input_error(path, f"not an image file (expected one of {', '.join(IMAGE_SUFFIXES)})")
    else:
        files = [path for path in files if not path.stem.endswith(_MASK_SUFFIX)]
    if len(files) < max(1, min_views):
        raise input_error(where, f"found {len(files)} image(s) but at least {max(1, min_views)} are needed")
    seen: dict[str, Path] = {}
    for path in files:
        if path.stem in seen:
            raise input_error(path, f"has the same name as {seen[path.stem]}; view names must be unique")
        seen[path.stem] = path
    images = read_images(files, gray)
    views = []
    for path, image in zip(files, images):
        mask_path = _find_mask(path)
        mask = None
        if mask_path is not None:
            mask = read_mask(mask_path, shape=image.shape[:2])
            if not mask.any():
                raise input_error(mask_path, "mask is empty (no pixel set)")
        views.append(View(path.stem, image, mask=mask))
    focals = {path.stem: asdict(exif_focal(path, (image.shape[1], image.shape[0]))) for path, image in zip(files, images)}
    return Capture(tuple(views), {"dataset": "images", "sources": {path.stem: str(path) for path in files},
                                  "exif_focal": focals})


# ------------------------------------------------------------------------------------------ dispatch

def _kind_of(files: Sequence[Path]) -> str:
    stems = [path.stem for path in files]
    if stems and all(_UWA_NAME.match(stem) for stem in stems):
        return "uwa"
    if stems and all(_CFPOSE_NAME.match(stem) and path.suffix.lower() in _CFPOSE_SUFFIXES
                     for stem, path in zip(stems, files)):
        return "cfpose"
    return "images"


def _files_as_given(files: list[Path], gray: bool | None) -> Capture:
    """Image files the user named: one capture of exactly those files, in the order given.

    A dataset's naming never groups or completes them (that is for folders); it only names the
    views and fills the metadata when every file is a frame of one UWA capture (views ``f<frame>``)
    or a pose of one CFPose finger (views ``p<pose>``).
    """
    capture = load_image_folder(files, gray=gray)
    uwa = [_UWA_NAME.match(path.stem) for path in files]
    cfpose = [_CFPOSE_NAME.match(path.stem) for path in files]
    if all(uwa) and len({(m["subject"], m["finger"], m["capture"], m["session"]) for m in uwa}) == 1 \
            and len({int(m["frame"]) for m in uwa}) == len(files):
        frames = [int(m["frame"]) for m in uwa]
        names = [f"f{frame}" for frame in frames]
        first = uwa[0]
        group = UWAGroup(first["subject"], first["finger"], first["capture"], first["session"], dict(zip(frames, files)))
        metadata = _uwa_metadata(group, frames)
    elif all(cfpose) and len({m["finger"] for m in cfpose}) == 1 and len({int(m["pose"]) for m in cfpose}) == len(files):
        names = [f"p{int(m['pose'])}" for m in cfpose]
        metadata = {"dataset": "cfpose", "finger": cfpose[0]["finger"], "poses": [int(m["pose"]) for m in cfpose],
                    "sources": {name: str(path) for name, path in zip(names, files)}}
    else:
        return capture
    metadata["exif_focal"] = {name: capture.metadata["exif_focal"][view.name] for view, name in zip(capture.views, names)}
    return Capture(tuple(replace(view, name=name) for view, name in zip(capture.views, names)), metadata)


def load_any(paths: str | Path | Iterable[str | Path], *, gray: bool | None = None) -> list[Capture]:
    """Load whatever ``paths`` is, always as a list of captures.

    * a capture folder (``manifest.json`` or ``images/``) -> :func:`read_capture`;
    * a folder whose images are *all* named like UWA frames -> :func:`load_uwa`;
    * ... all named like CFPose images -> :func:`load_cfpose`;
    * any other folder of images -> :func:`load_image_folder`;
    * a list of image files -> one capture of exactly those files in the given order (a dataset's
      naming only names their views, never groups or completes them);
    * a list of folders -> each one loaded as above, results concatenated.

    Only the folder's own files decide (no recursion); mask files are not counted.
    """
    if isinstance(paths, (str, Path)):
        path = Path(paths)
        if not path.exists():
            raise input_error(path, "not found")
        if is_capture_folder(path):
            return [read_capture(path, gray=gray)]
        if path.is_dir():
            files, _ = _image_files(path, recursive=False)
            files = [file for file in files if not file.stem.endswith(_MASK_SUFFIX)]
            if not files:
                raise input_error(path, "holds no images and is not a capture folder" + unread_photos_note(path)
                                  + _inner_photos_note(path))
        else:
            files = [path]
    else:
        items = [Path(item) for item in paths]
        if not items:
            raise input_error(None, "no input paths were given")
        folders = [item for item in items if item.is_dir()]
        if folders and len(folders) == len(items):
            return [capture for folder in folders for capture in load_any(folder, gray=gray)]
        if folders:
            raise input_error(folders[0], "is a folder; give either folders or image files, not both")
        return [_files_as_given(items, gray)]
    kind = _kind_of(files)
    if kind == "uwa":
        return load_uwa(path, gray=gray)
    if kind == "cfpose":
        return load_cfpose(path, gray=gray)
    return [load_image_folder(path, gray=gray)]
