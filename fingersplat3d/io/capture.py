"""Capture folders: a :class:`~fingersplat3d.scene.Capture` on disk, and back.

Layout (docs/conventions.md)::

    images/<view>.png    8- or 16-bit, grayscale or RGB, as the view holds it
    masks/<view>.png     optional; 0 outside, 255 inside; never empty
    depth/<view>.npy     optional; float32 H x W camera-frame z (mm), NaN = none; nothing else here
    cameras.json         when every view has a camera (schema in :mod:`.cameras`)
    minutiae.json        optional ground truth (schema in :mod:`.minutiae`)
    mesh.ply             optional ground-truth surface (binary PLY)
    rolled_print.png     optional ground-truth rolled print (8-bit gray, 500 ppi; minutiae.json says how it maps)
    manifest.json        {"format": "fingersplat3d-capture", "version": 1,
                          "created_by": "fingersplat3d <version>", "views": [names in order],
                          "files": {"images": {view: path}, "masks": {...}, "depth": {...},
                                    "cameras": "cameras.json", "minutiae": ..., "mesh": ...},
                          "metadata": {...}, ...extra keys}

Paths in ``files`` are relative to the folder; ``masks``/``depth`` list only the views that have
one and ``cameras``/``minutiae``/``mesh`` appear only when written. ``manifest.json`` is optional
on reading: without it the views are the images in ``images/`` in natural name order (``v2``
before ``v10``), and masks, depth and cameras are found by the names above.

The whole folder is written under a temporary sibling name and renamed into place, so a failed
write leaves nothing behind.
"""
from __future__ import annotations

import json
import re
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Mapping

import numpy as np

from ..atomic import atomic_dir
from ..errors import InputError, InputNote, input_error
from ..scene import Capture, View
from ..synth.rolled import ROLLED_PRINT_FILE
from .cameras import read_cameras, write_cameras
from .depth import read_depth, write_depth
from .images import IMAGE_SUFFIXES, read_images, read_mask, unread_photos_note, write_image, write_mask
from .jsonio import read_json, to_jsonable
from .minutiae import write_minutiae
from .ply import write_mesh_ply

__all__ = ["CAPTURE_FORMAT", "CAPTURE_VERSION", "CaptureFiles", "capture_files", "is_capture_folder",
           "read_capture", "write_capture"]

CAPTURE_FORMAT = "fingersplat3d-capture"
CAPTURE_VERSION = 1
MANIFEST, CAMERAS, MINUTIAE, MESH = "manifest.json", "cameras.json", "minutiae.json", "mesh.ply"
ROLLED_PRINT = ROLLED_PRINT_FILE
_RESERVED_KEYS = ("format", "version", "created_by", "views", "files", "metadata")
_BAD_NAME = re.compile(r'[/\\:*?"<>|\x00-\x1f]')


@dataclass(frozen=True, eq=False)
class CaptureFiles:
    """Where the parts of a capture folder are; only files that exist are listed."""

    folder: Path
    views: tuple[str, ...]  # view names in order
    images: dict[str, Path]  # every view has one
    masks: dict[str, Path] = field(default_factory=dict)
    depth: dict[str, Path] = field(default_factory=dict)
    cameras: Path | None = None
    minutiae: Path | None = None
    mesh: Path | None = None
    manifest: Path | None = None
    metadata: dict[str, Any] = field(default_factory=dict)  # the manifest's "metadata"


def _natural_key(text: str) -> tuple:
    return tuple((0, int(part), "") if part.isdigit() else (1, 0, part) for part in re.split(r"(\d+)", text))


def _foreign(data: Any) -> bool:
    """A JSON ``manifest.json`` that another tool wrote (a dataset's own, say): not a capture manifest."""
    return not isinstance(data, dict) or "format" not in data or (
        isinstance(data["format"], str) and not data["format"].startswith("fingersplat3d"))


def _own_manifest(folder: Path) -> dict[str, Any] | None:
    """The capture manifest of ``folder``, or None where there is none or it is another tool's (noted)."""
    path = folder / MANIFEST
    if not path.is_file():
        return None
    data = read_json(path)
    if _foreign(data):
        what = f'"format" {data["format"]!r}' if isinstance(data, dict) and "format" in data else "no \"format\""
        warnings.warn(f"{path}: not a fingersplat3d capture manifest ({what}); ignored, the views are read from "
                      f"images/", InputNote, stacklevel=3)
        return None
    return data


def is_capture_folder(path: str | Path) -> bool:
    """True for a folder that holds an ``images/`` folder or a capture ``manifest.json`` (not another tool's)."""
    path = Path(path)
    if not path.is_dir():
        return False
    if (path / "images").is_dir():
        return True
    if not (path / MANIFEST).is_file():
        return False
    try:
        return not _foreign(json.loads((path / MANIFEST).read_text(encoding="utf-8")))
    except (OSError, ValueError):
        return True  # ours but unreadable: reading it says why


# ----------------------------------------------------------------------------------------- writing

def _check_writable(capture: Capture, folder: Path, image_bits: int) -> None:
    """Refuse, before anything is written, what :func:`read_capture` would reject."""
    if image_bits not in (8, 16):
        raise ValueError(f"image_bits must be 8 or 16, got {image_bits}")
    if not capture.views:
        raise input_error(folder, "refusing to write a capture with no views")
    for view in capture.views:
        name = view.name
        if not name or name in (".", "..") or name.startswith(".") or _BAD_NAME.search(name):
            raise input_error(folder, f"view name {name!r} cannot be used as a file name")
        if not np.all(np.isfinite(view.image)):
            raise input_error(folder, f"view {name!r} has NaN or Inf in its image")
        if view.mask is not None and not view.mask.any():
            raise input_error(folder, f"view {name!r} has an empty mask (no pixel set)")
        if view.depth is not None and (np.isinf(view.depth).any() or (view.depth < 0).any()):
            raise input_error(folder, f"view {name!r} has Inf or negative values in its depth map")
    lowered = [view.name.lower() for view in capture.views]
    if len(set(lowered)) != len(lowered):
        raise input_error(folder, f"view names {capture.names} clash on case-insensitive file systems")


def _write_mesh(path: Path, mesh: Any) -> None:
    if isinstance(mesh, (str, Path)):
        if not Path(mesh).is_file():
            raise input_error(mesh, "mesh file not found")
        shutil.copyfile(mesh, path)
        return
    import open3d as o3d  # heavy; only needed when a mesh is written

    if not isinstance(mesh, o3d.geometry.TriangleMesh):
        raise TypeError(f"mesh must be an open3d.geometry.TriangleMesh or a PLY path, got {type(mesh).__name__}")
    if len(mesh.vertices) == 0:
        raise ValueError(f"{path}: refusing to write an empty mesh")
    normals = np.asarray(mesh.vertex_normals) if mesh.has_vertex_normals() else None
    colors = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else None
    write_mesh_ply(path, np.asarray(mesh.vertices), np.asarray(mesh.triangles), normals, colors)


def write_capture(capture: Capture, folder: str | Path, *, minutiae: dict | None = None, mesh: Any = None,
                  overwrite: bool = False, image_bits: int = 8, extra_manifest: Mapping[str, Any] | None = None,
                  rolled_print: np.ndarray | None = None) -> Path:
    """Write ``capture`` as a capture folder (layout above), atomically; return the folder.

    ``minutiae`` is a dict for ``minutiae.json``; ``mesh`` an ``open3d.geometry.TriangleMesh`` (or
    the path of a PLY to copy); ``rolled_print`` an 8-bit gray image (``rolled_print.png``);
    ``image_bits`` is 8 or 16 for every image; ``extra_manifest`` adds
    top-level manifest keys (the reserved ones cannot be replaced). ``cameras.json`` is written
    when every view has a camera, with ``units`` / ``scale_mm_per_unit`` from ``capture.metadata``
    (default ``"mm"`` / null). An existing non-empty folder is an error unless ``overwrite``.
    """
    from .. import __version__

    folder = Path(folder)
    _check_writable(capture, folder, image_bits)
    extra = dict(extra_manifest or {})
    clashes = sorted(set(extra) & set(_RESERVED_KEYS))
    if clashes:
        raise ValueError(f"extra_manifest cannot replace the reserved keys {clashes}")
    metadata = to_jsonable({k: v for k, v in capture.metadata.items() if k != "sources"})  # files are new
    extra = to_jsonable(extra, "extra_manifest")
    files: dict[str, Any] = {"images": {}, "masks": {}, "depth": {}}
    with atomic_dir(folder, overwrite=overwrite) as temporary:
        for view in capture.views:
            files["images"][view.name] = f"images/{view.name}.png"
            write_image(temporary / files["images"][view.name], view.image, bits=image_bits)
            if view.mask is not None:
                files["masks"][view.name] = f"masks/{view.name}.png"
                write_mask(temporary / files["masks"][view.name], view.mask)
            if view.depth is not None:
                files["depth"][view.name] = f"depth/{view.name}.npy"
                write_depth(temporary / files["depth"][view.name], view.depth)
        if capture.has_cameras:
            write_cameras(temporary / CAMERAS, [(view.name, files["images"][view.name], view.camera)
                                                for view in capture.views],
                          units=capture.metadata.get("units", "mm"),
                          scale_mm_per_unit=capture.metadata.get("scale_mm_per_unit"))
            files["cameras"] = CAMERAS
        if minutiae is not None:
            write_minutiae(temporary / MINUTIAE, minutiae)
            files["minutiae"] = MINUTIAE
        if mesh is not None:
            _write_mesh(temporary / MESH, mesh)
            files["mesh"] = MESH
        if rolled_print is not None:
            write_image(temporary / ROLLED_PRINT, np.asarray(rolled_print, np.float32) / 255.0, bits=8)
            files["rolled_print"] = ROLLED_PRINT
        manifest = {"format": CAPTURE_FORMAT, "version": CAPTURE_VERSION, "created_by": f"fingersplat3d {__version__}",
                    "views": capture.names, "files": files, "metadata": metadata, **extra}
        (temporary / MANIFEST).write_text(json.dumps(manifest, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return folder


# ----------------------------------------------------------------------------------------- reading

def _relative(folder: Path, manifest: Path, value: Any, where: str) -> Path:
    """A path from the manifest, which must stay inside the capture folder."""
    if not isinstance(value, str) or not value:
        raise input_error(manifest, f"{where} must be a relative path string, got {value!r}")
    relative = PurePosixPath(value.replace("\\", "/"))
    if relative.is_absolute() or ".." in relative.parts:
        raise input_error(manifest, f"{where} points outside the capture folder ({value!r})")
    return folder / relative


def _parse_manifest(folder: Path, path: Path, data: dict[str, Any]) -> tuple[list[str], dict[str, Any], dict[str, Any]]:
    """Views, ``files`` and ``metadata`` of a validated manifest (``data``, read from ``path``)."""
    if data.get("format") != CAPTURE_FORMAT:
        raise input_error(path, f'not a capture manifest ("format" is {data.get("format")!r}, '
                                f'expected {CAPTURE_FORMAT!r})')
    version = data.get("version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise input_error(path, f'"version" must be a positive integer, got {version!r}')
    if version > CAPTURE_VERSION:
        raise input_error(path, f"capture format version {version} is newer than this reader "
                                f"(version {CAPTURE_VERSION}); update fingersplat3d")
    views = data.get("views")
    if not isinstance(views, list) or not views or not all(isinstance(name, str) and name for name in views):
        raise input_error(path, '"views" must be a non-empty list of view names')
    if len(set(views)) != len(views):
        raise input_error(path, f'"views" lists a name twice ({views})')
    files = data.get("files", {})
    metadata = data.get("metadata", {})
    if not isinstance(files, dict):
        raise input_error(path, '"files" must be an object')
    if not isinstance(metadata, dict):
        raise input_error(path, '"metadata" must be an object')
    resolved: dict[str, Any] = {}
    for kind in ("images", "masks", "depth"):
        listing = files.get(kind, {})
        if not isinstance(listing, dict):
            raise input_error(path, f'"files.{kind}" must map view names to paths')
        unknown = [name for name in listing if name not in views]
        if unknown:
            raise input_error(path, f'"files.{kind}" names view {unknown[0]!r}, which is not in "views"')
        resolved[kind] = {name: _relative(folder, path, value, f'"files.{kind}"[{name!r}]')
                          for name, value in listing.items()}
    for kind in ("cameras", "minutiae", "mesh"):
        value = files.get(kind)
        resolved[kind] = None if value is None else _relative(folder, path, value, f'"files.{kind}"')
    return views, resolved, metadata


def _find_image(images_dir: Path, name: str) -> Path | None:
    for suffix in IMAGE_SUFFIXES:
        for candidate in (images_dir / f"{name}{suffix}", images_dir / f"{name}{suffix.upper()}"):
            if candidate.is_file():
                return candidate
    return None


def _listed(path: Path | None, manifest: Path | None, what: str) -> Path | None:
    """A path the manifest lists must exist."""
    if path is not None and not path.is_file():
        raise input_error(path, f"{what} listed in {manifest.name if manifest else MANIFEST} is missing")
    return path


def capture_files(folder: str | Path) -> CaptureFiles:
    """Locate (and check the presence of) every part of a capture folder; reads no pixels."""
    folder = Path(folder)
    if not folder.exists():
        raise input_error(folder, "capture folder not found")
    if not folder.is_dir():
        raise input_error(folder, "not a folder (a capture folder with images/ is expected)")
    images_dir = folder / "images"
    manifest = folder / MANIFEST
    data = _own_manifest(folder)
    if data is not None:
        views, listed, metadata = _parse_manifest(folder, manifest, data)
        if not images_dir.is_dir() and not listed["images"]:
            raise input_error(folder, "capture folder has no images/ folder")
    else:
        manifest, listed, metadata = None, {kind: {} for kind in ("images", "masks", "depth")}, {}
        if not images_dir.is_dir():
            raise input_error(folder, "capture folder has no images/ folder (and no manifest.json)")
        stems: dict[str, Path] = {}
        for path in sorted(images_dir.iterdir()):
            if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES and not path.name.startswith("."):
                if path.stem in stems:
                    raise input_error(path, f"two images for view {path.stem!r} ({stems[path.stem].name} and {path.name})")
                stems[path.stem] = path
        if not stems:
            raise input_error(images_dir, f"holds no images ({', '.join(IMAGE_SUFFIXES)})" + unread_photos_note(images_dir))
        views = sorted(stems, key=_natural_key)
        listed.update(cameras=None, minutiae=None, mesh=None)
    images, masks, depth = {}, {}, {}
    for name in views:
        image = listed["images"].get(name) or _find_image(images_dir, name)
        if image is None or not image.is_file():
            raise input_error(image or images_dir / f"{name}.png", f"image of view {name!r} is missing")
        images[name] = image
        mask = _listed(listed["masks"].get(name), manifest, f"mask of view {name!r}") or folder / "masks" / f"{name}.png"
        if mask.is_file():
            masks[name] = mask
        depth_path = _listed(listed["depth"].get(name), manifest, f"depth map of view {name!r}") \
            or folder / "depth" / f"{name}.npy"
        if depth_path.is_file():
            depth[name] = depth_path
    optional = {}
    for kind, default in (("cameras", CAMERAS), ("minutiae", MINUTIAE), ("mesh", MESH)):
        path = _listed(listed[kind], manifest, kind) or folder / default
        optional[kind] = path if path.is_file() else None
    return CaptureFiles(folder, tuple(views), images, masks, depth, manifest=manifest, metadata=dict(metadata),
                        **optional)


def read_capture(folder: str | Path, *, load_depth: bool = True, gray: bool | None = None) -> Capture:
    """Read a capture folder into a :class:`Capture` (every file checked; see the module doc).

    Images are float32 in [0, 1] (``gray`` as in :func:`~.images.read_images`, one kind of channel for all); masks are
    checked against their image's size and must not be empty; depth maps must match their image and hold no Inf or
    negative values (NaN is fine). With ``cameras.json`` its views must be exactly the
    capture's views with matching image sizes, and ``metadata["units"]`` (and
    ``"scale_mm_per_unit"`` when known) are taken from it. ``minutiae.json`` and ``mesh.ply`` are
    not loaded: :func:`capture_files` gives their paths.
    """
    files = capture_files(folder)
    cameras = read_cameras(files.cameras) if files.cameras is not None else None
    if cameras is not None:
        for name in cameras.names:
            if name not in files.images:
                raise input_error(files.cameras, f"view {name!r} has no image in the capture folder")
        for name in files.views:
            if name not in cameras.cameras:
                raise input_error(files.cameras, f"has no camera for view {name!r}")
    views = []
    images = read_images([files.images[name] for name in files.views], gray=gray)
    for name, image in zip(files.views, images):
        height, width = image.shape[:2]
        mask = None
        if name in files.masks:
            mask = read_mask(files.masks[name], shape=(height, width))
            if not mask.any():
                raise input_error(files.masks[name], "mask is empty (no pixel set)")
        depth = read_depth(files.depth[name], shape=(height, width)) if load_depth and name in files.depth else None
        camera = cameras.cameras[name] if cameras is not None else None
        if camera is not None and camera.size != (width, height):
            raise input_error(files.cameras, f"view {name!r} is {camera.width}x{camera.height} but its image "
                                             f"{files.images[name].name} is {width}x{height}")
        try:
            views.append(View(name, image, mask=mask, camera=camera, depth=depth))
        except ValueError as error:  # should not happen after the checks above
            raise InputError(f"{files.folder}: view {name!r} is inconsistent ({error})") from None
    metadata = dict(files.metadata)
    # where each photo is: a reconstruction's cameras.json names it, for tools that read the photos again
    metadata["sources"] = {view.name: str(files.images[view.name].resolve()) for view in views}
    if cameras is not None:
        metadata["units"] = cameras.units
        if cameras.scale_mm_per_unit is not None:
            metadata["scale_mm_per_unit"] = cameras.scale_mm_per_unit
    return Capture(tuple(views), metadata)
