"""Images and masks on disk: 8- or 16-bit PNG/JPEG/TIFF/BMP/WebP, and the HEIC/HEIF photos phones save (through
pillow-heif: OpenCV's build has no HEVC decoder), grayscale or RGB.

Images are read as float32 in [0, 1]; grayscale stays ``H x W``, colour becomes ``H x W x 3``
in RGB order. Masks are ``H x W`` bool (any non-zero pixel is inside).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError, input_error
from ..atomic import atomic_path

__all__ = ["HEIF_SUFFIXES", "IMAGE_SUFFIXES", "UNREAD_SUFFIXES", "unread_photos", "unread_photos_note", "find_files",
           "read_image", "read_images", "write_image", "read_mask", "write_mask"]

HEIF_SUFFIXES = (".heic", ".heif")
"""The photos an iPhone (and many Android phones) save by default: HEVC in a HEIF box, decoded by pillow-heif
(libheif), upright as the phone showed them, their EXIF (the focal, :mod:`.exif`) read alike."""
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp") + HEIF_SUFFIXES
UNREAD_SUFFIXES = {".avif": "AVIF", ".dng": "raw DNG", ".cr2": "raw", ".nef": "raw", ".arw": "raw", ".gif": "GIF"}
"""Photo formats a phone or camera may write that are not read here (neither OpenCV's build nor pillow-heif decodes
them, or, GIF, a palette of 256 colours): named in the error, with what to do, by every command that reads a photo
(:func:`read_image` as well as the capture loaders: ``fs3d print`` had read a GIF that ``fs3d fuse`` refused)."""
NEAR_GRAY = 2.0 / 255.0
"""A colour image whose three channels lie within this of each other at every pixel is a gray one stored in colour (a
gray photo saved as RGB, then re-encoded lossily: WebP moved 0.1 % of a real frame's pixels by one level): read as
gray."""


def unread_photos(kinds) -> str:
    """``"HEIC photos are not read: ..."``: what to do with photos of the formats ``kinds`` (names from
    :data:`UNREAD_SUFFIXES`)."""
    return f"{' and '.join(sorted(set(kinds)))} photos are not read: save them as JPEG or PNG first (keeping their EXIF)"


def unread_photos_note(folder: Path) -> str:
    """``"; its HEIC photos are not read: ..."`` when ``folder`` holds photos of a format in :data:`UNREAD_SUFFIXES`,
    else ``""``: the end of a "holds no images" sentence."""
    kinds = [UNREAD_SUFFIXES[p.suffix.lower()] for p in Path(folder).iterdir()
             if p.is_file() and p.suffix.lower() in UNREAD_SUFFIXES] if Path(folder).is_dir() else []
    return f"; its {unread_photos(kinds)}" if kinds else ""


def find_files(paths: list[Path], suffixes: tuple[str, ...] = IMAGE_SUFFIXES) -> list[Path]:
    """Files with one of ``suffixes`` (case-insensitive): those given, and those under given folders
    (recursively, sorted). A path that does not exist is an ``InputError``."""
    found = []
    for path in map(Path, paths):
        if path.is_dir():
            found += sorted(p for p in path.rglob("*") if p.suffix.lower() in suffixes)
        elif path.suffix.lower() in suffixes:
            found.append(path)
        elif not path.exists():
            raise InputError(f"{path}: not found")
    return found


def _read_raw(path: Path, upright: bool = False) -> np.ndarray:
    """The file's pixels as stored (any depth); ``upright``: turned as its EXIF orientation says, as a viewer shows
    it (phone photos are stored sideways with a tag), the alpha channel dropped."""
    if not path.is_file():
        raise input_error(path, "file not found")
    if path.suffix.lower() in UNREAD_SUFFIXES:
        raise input_error(path, unread_photos([UNREAD_SUFFIXES[path.suffix.lower()]]))
    if path.stat().st_size == 0:
        raise input_error(path, "file is empty")
    if path.suffix.lower() in HEIF_SUFFIXES:
        return _read_heif(path)
    data = path.read_bytes()
    # Checked before decoding: OpenCV would fill the missing rows grey and print libjpeg's complaint above the error.
    if path.suffix.lower() in (".jpg", ".jpeg") and _jpeg_truncated(data):
        raise input_error(path, "truncated JPEG: the file ends inside its image data (an interrupted copy or download?)")
    raw = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR if upright else cv2.IMREAD_UNCHANGED)
    if raw is None or raw.size == 0:
        raise input_error(path, "not a readable image (corrupt or unsupported format)")
    return raw


def _read_heif(path: Path) -> np.ndarray:
    """A HEIC/HEIF photo's main image as OpenCV would give it (uint8, BGR or one channel, no alpha), upright: libheif
    applies the file's own turn and mirror (a phone's portrait shot is stored sideways), as every viewer does. HDR
    photos (10 or 12 bits) come down to 8, as a viewer shows them."""
    try:
        import pillow_heif
    except ImportError:  # a dependency, but an environment may lack it: say what to do, not "not an image"
        raise input_error(path, "HEIC photos need the pillow-heif package (pip install pillow-heif), or save them as "
                                "JPEG or PNG first (keeping their EXIF)") from None
    try:
        pixels = np.asarray(pillow_heif.open_heif(path, convert_hdr_to_8bit=True))
    except Exception as error:  # noqa: BLE001 - libheif's errors vary by release; any of them is an unreadable file
        why = str(error).strip() or type(error).__name__
        raise input_error(path, f"not a readable HEIC/HEIF image ({why})") from None
    if pixels.ndim == 3 and pixels.shape[2] >= 3:
        return np.ascontiguousarray(pixels[..., 2::-1])  # RGB(A) -> BGR, the alpha dropped
    return np.ascontiguousarray(pixels[..., 0] if pixels.ndim == 3 else pixels)  # grey (with alpha)


def _jpeg_truncated(data: bytes) -> bool:
    """True when a JPEG's image data is not closed by an end-of-image marker: the file stops inside it. OpenCV then
    fills the missing rows grey and says so only on stderr. The marker segments are walked from the start to the main
    image's first scan (an EXIF thumbnail inside APP1 is skipped whole), and an end-of-image marker must follow it
    (inside scan data 0xFF is always escaped, so only a marker reads 0xFFD9; data a camera appends after the image, a
    second picture included, comes after its end marker). Anything the walk cannot read is left to the decoder."""
    if data[:2] != b"\xff\xd8":
        return False
    i = 2
    while i + 4 <= len(data):
        if data[i] != 0xFF:
            return False
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte before a marker
            i += 1
        elif marker == 0xDA:  # start of scan: entropy-coded data follows
            return data.find(b"\xff\xd9", i) < 0
        elif marker == 0x01 or 0xD0 <= marker <= 0xD8:  # markers without a length
            i += 2
        else:
            i += 2 + int.from_bytes(data[i + 2:i + 4], "big")
    return False


def read_image(path: str | Path, gray: bool | None = None) -> np.ndarray:
    """Read an image as float32 in [0, 1], upright as its EXIF orientation says (as every viewer shows a phone photo).

    ``gray=None`` keeps what the file holds (colour images whose three channels are equal, within
    :data:`NEAR_GRAY`, come back grayscale); ``True`` converts to one channel; ``False`` always returns RGB.
    """
    path = Path(path)
    raw = _read_raw(path, upright=True)
    if raw.dtype == np.uint8:
        image = raw.astype(np.float32) / 255.0
    elif raw.dtype == np.uint16:
        image = raw.astype(np.float32) / 65535.0
    elif raw.dtype in (np.float32, np.float64):
        image = raw.astype(np.float32)
        if not np.all(np.isfinite(image)):
            raise input_error(path, "image contains NaN or Inf")
        image = np.clip(image, 0.0, 1.0)
    else:
        raise input_error(path, f"unsupported pixel type {raw.dtype}")
    if image.ndim == 3:
        if image.shape[2] == 4:
            image = image[..., :3]
        image = image[..., ::-1] if image.shape[2] == 3 else image[..., 0]
    if image.ndim == 3 and gray is None:
        spread = _channel_spread(image)
        if spread == 0.0:  # the same values to the bit as the file's one channel
            image = image[..., 0]
        elif spread <= NEAR_GRAY + 1e-7:
            gray = True
    if gray is True and image.ndim == 3:
        image = image @ np.array([0.299, 0.587, 0.114], np.float32)
    if gray is False and image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    return np.ascontiguousarray(image, dtype=np.float32)


def read_images(paths, gray: bool | None = None) -> list[np.ndarray]:
    """The photos of one capture (:func:`read_image` each), in one kind of channel: one model is fitted to them all, so
    when some are grayscale and some colour (a gray camera beside a phone, photos converted apart), every one is read
    as grayscale, the one channel they all have. Sizes and orientations may differ."""
    paths = [Path(path) for path in paths]
    images = [read_image(path, gray=gray) for path in paths]
    if len({image.ndim for image in images}) > 1:
        images = [image if image.ndim == 2 else read_image(path, gray=True) for path, image in zip(paths, images)]
    return images


def _channel_spread(image: np.ndarray) -> float:
    """The largest difference between a colour image's channels at any pixel, up to just past :data:`NEAR_GRAY`
    (a band of rows at a time, stopping at the first band of colour: a 12-megapixel photo's spread map would be another
    48 MB)."""
    spread = 0.0
    for start in range(0, image.shape[0], 256):
        band = image[start:start + 256]
        spread = max(spread, float(np.max(band.max(axis=2) - band.min(axis=2))))
        if spread > NEAR_GRAY + 1e-7:
            break
    return spread


def write_image(path: str | Path, image: np.ndarray, bits: int = 8) -> Path:
    """Write a float image in [0, 1] (``H x W`` or ``H x W x 3`` RGB) as 8- or 16-bit, atomically."""
    path = Path(path)
    image = np.asarray(image, np.float32)
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, got {bits}")
    if not np.all(np.isfinite(image)):
        raise ValueError(f"{path}: refusing to write an image with NaN or Inf")
    scale = 255.0 if bits == 8 else 65535.0
    data = np.round(np.clip(image, 0.0, 1.0) * scale).astype(np.uint8 if bits == 8 else np.uint16)
    if data.ndim == 3:
        data = np.ascontiguousarray(data[..., ::-1])
    with atomic_path(path) as temporary:
        if not cv2.imwrite(str(temporary), data):
            raise OSError(f"{path}: could not write image")
    return path


def read_mask(path: str | Path, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a mask as ``H x W`` bool; ``shape`` (H, W) is checked when given."""
    path = Path(path)
    raw = _read_raw(path)
    if raw.ndim == 3:
        raw = raw.max(axis=2)
    mask = raw > 0
    if shape is not None and mask.shape != tuple(shape):
        raise input_error(path, f"mask is {mask.shape[1]}x{mask.shape[0]} but its image is {shape[1]}x{shape[0]}")
    return mask


def write_mask(path: str | Path, mask: np.ndarray) -> Path:
    """Write a bool mask as an 8-bit PNG (0 / 255), atomically."""
    return write_image(path, np.asarray(mask, bool).astype(np.float32), bits=8)
