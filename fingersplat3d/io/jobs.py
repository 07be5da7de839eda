"""The captures of a dataset as jobs: a name and the files to load, found without reading a pixel.

What a dataset run (``fs3d batch``, ``fs3d rig calibrate``) hands to its workers: large inputs
travel by path, and each worker loads its own capture (:func:`load_job`). Layouts:

* a UWA raw folder (``{subject}_{finger}_{capture}[_{session}]_{frame}.jpg``): one job per capture,
  frames 0-2; a capture missing one of them is listed with the reason, so the run records it;
* a CFPose folder (``{finger}_{pose}.bmp``): one job per finger, every pose;
* a folder of capture folders (each with ``manifest.json`` or ``images/``): one job per folder;
* a folder of photo folders (no photos of its own, each folder inside with photos of its own, as a user lays out
  one folder per capture): one job per such folder;
* a CSV file with a header ``name,paths`` (paths separated by ``;``, relative to the CSV): one
  job per row;
* a single capture folder, image folder or list of image files: one job.

``select`` filters them: ``subject=2``, ``finger=1``, ``capture=7``, ``name=2_2_7_1`` (each may
repeat as a comma-separated list: ``subject=1,subject=2``) and ``count=N`` (the first N after the
filters).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from ..errors import InputError, input_error
from ..scene import Capture
from .capture import is_capture_folder
from .datasets import (UWA_VIEW_FRAMES, _cfpose_fingers, _image_files, _kind_of, find_uwa_groups, load_any,
                       natural_key, photo_folders)
from .images import unread_photos_note

__all__ = ["CaptureJob", "list_jobs", "load_job", "parse_select"]

SELECT_KEYS = ("subject", "finger", "capture", "name", "count")


@dataclass(frozen=True)
class CaptureJob:
    """One capture of a dataset: its name (the output folder's), its files and its ids."""

    name: str
    files: tuple[str, ...]
    ids: dict = field(default_factory=dict)  # subject / finger / capture where the layout has them
    problem: str = ""  # non-empty: the capture cannot be loaded, and why (a missing frame)


def parse_select(text: str | None) -> dict[str, list[str]]:
    """``"subject=1,finger=2,count=5"`` -> ``{"subject": ["1"], "finger": ["2"], "count": ["5"]}``; a bad term is an ``InputError``."""
    selection: dict[str, list[str]] = {}
    for term in filter(None, (part.strip() for part in (text or "").split(","))):
        key, sep, value = term.partition("=")
        if not sep or key not in SELECT_KEYS or not value:
            raise InputError(f"--select: {term!r} is not KEY=VALUE with KEY one of {', '.join(SELECT_KEYS)}")
        if key == "count" and (not value.isdigit() or int(value) < 1):
            raise InputError(f"--select: count must be a positive whole number, got {value!r}")
        selection.setdefault(key, []).append(value)
    return selection


def _same(wanted: str, found: str) -> bool:
    return wanted == found or (wanted.isdigit() and found.isdigit() and int(wanted) == int(found))


def _selected(jobs: list[CaptureJob], selection: dict[str, list[str]]) -> list[CaptureJob]:
    for key in ("subject", "finger", "capture"):
        if key in selection:
            jobs = [job for job in jobs if key in job.ids and any(_same(w, str(job.ids[key])) for w in selection[key])]
    if "name" in selection:
        jobs = [job for job in jobs if job.name in selection["name"]]
    if "count" in selection:
        jobs = jobs[:int(selection["count"][-1])]
    return jobs


def _uwa_jobs(folder: Path | list[Path]) -> list[CaptureJob]:
    jobs = []
    for group in find_uwa_groups(folder):
        missing = [frame for frame in UWA_VIEW_FRAMES if frame not in group.frames]
        ids = {"subject": group.subject, "finger": group.finger, "capture": group.capture}
        files = tuple(str(group.frames[frame]) for frame in UWA_VIEW_FRAMES if frame in group.frames)
        problem = f"UWA {group.label} is missing frame(s) {', '.join(map(str, missing))}" if missing else ""
        jobs.append(CaptureJob(group.stem, files, ids, problem))
    return jobs


def _csv_jobs(path: Path) -> list[CaptureJob]:
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = list(csv.DictReader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise input_error(path, f"cannot be read as CSV ({error})") from None
    if not rows or not {"name", "paths"} <= set(rows[0]):
        raise input_error(path, 'a capture list needs a header "name,paths" and at least one row')
    jobs, seen = [], set()
    for number, row in enumerate(rows, start=2):
        name, paths = (row.get("name") or "").strip(), [p.strip() for p in (row.get("paths") or "").split(";") if p.strip()]
        if not name or not paths:
            raise input_error(path, f"line {number}: a row needs a name and at least one path")
        if name in seen:
            raise input_error(path, f"line {number}: the name {name!r} appears twice")
        seen.add(name)
        jobs.append(CaptureJob(name, tuple(str((path.parent / p) if not Path(p).is_absolute() else Path(p)) for p in paths)))
    return jobs


def list_jobs(paths: Sequence[str | Path], select: str | None = None) -> list[CaptureJob]:
    """The captures ``paths`` hold, as jobs (see the module docstring), filtered by ``select``; none left is an ``InputError``."""
    selection = parse_select(select)
    items = [Path(p) for p in paths]
    if not items:
        raise InputError("no dataset was given")
    for item in items:
        if not item.exists():
            raise input_error(item, "not found")
    if len(items) == 1 and items[0].is_file() and items[0].suffix.lower() == ".csv":
        jobs = _csv_jobs(items[0])
    elif len(items) == 1 and items[0].is_dir() and not is_capture_folder(items[0]):
        folder = items[0]
        subfolders = sorted((p for p in folder.iterdir() if is_capture_folder(p)), key=lambda p: natural_key(p.name))
        if subfolders:
            jobs = [CaptureJob(p.name, (str(p),)) for p in subfolders]
        else:
            files, _ = _image_files(folder, recursive=True)
            if not files:  # said now, not as the one capture of a run that then fails it
                raise input_error(folder, "holds no images and no capture folders" + unread_photos_note(folder))
            kind = _kind_of(files)
            if kind == "uwa":
                jobs = _uwa_jobs(folder)
            elif kind == "cfpose":
                fingers = _cfpose_fingers(folder, None)
                jobs = [CaptureJob(f"finger_{finger}", tuple(str(fingers[finger][pose]) for pose in sorted(fingers[finger])),
                                   {"finger": finger}) for finger in sorted(fingers, key=natural_key)]
            else:
                inner = [] if _image_files(folder, recursive=False)[0] else photo_folders(folder)
                jobs = [CaptureJob(p.name, (str(p),)) for p in inner] or [CaptureJob(folder.name, (str(folder),))]
    else:
        files = [item for item in items if item.is_file()]
        jobs = _uwa_jobs(files) if files and len(files) == len(items) and _kind_of(files) == "uwa" else \
            [CaptureJob(items[0].stem if len(items) == 1 else items[0].parent.name or "capture", tuple(map(str, items)))]
    chosen = _selected(jobs, selection)
    if not chosen:
        raise InputError(f"{items[0]}: no capture matches --select {select!r}" if select else f"{items[0]}: holds no capture")
    return chosen


def load_job(job: CaptureJob) -> Capture:
    """The job's capture (one), named after the job; a job with a problem is an ``InputError`` saying it."""
    if job.problem:
        raise InputError(job.problem)
    captures = load_any(job.files[0] if len(job.files) == 1 else list(job.files))
    if len(captures) != 1:
        raise InputError(f"{job.name}: its files hold {len(captures)} captures, not one")
    capture = captures[0]
    return Capture(capture.views, {**capture.metadata, "name": job.name})
