"""Freed memory handed back to the operating system between the heavy steps of a fuse.

glibc's allocator keeps what a process frees for its own reuse: after an allocation larger than its mmap threshold is
freed, it raises the threshold to that size, so the next arrays of up to 32 MB come from its heap, and their pages stay
with the process once freed. A fuse allocates and frees images, maps and torch temporaries of every size, and on
camera-sized photos the pages held so were a fifth of the geometry's resident memory when the splat fit began (a
phone-like 12-megapixel capture: 3.0 GB, 2.4 GB with them handed back). :func:`release_free_memory` asks for them back
(``malloc_trim``), a few milliseconds between the fuse's stages: that capture's `fast` fuse peaked at 4.23 GB instead of
4.94 GB, in the same time (docs/measurements.md, stop 90). Handed back after every step of the splat fit as well, the
peak stayed (the fit's own step holds it) and the fit took a quarter longer. Where the C library has no
``malloc_trim`` (macOS, musl) it does nothing.
"""
from __future__ import annotations

import ctypes
import ctypes.util
from functools import lru_cache

__all__ = ["release_free_memory"]


@lru_cache(maxsize=1)
def _trim():
    """glibc's ``malloc_trim``, or None where the C library has none."""
    try:
        library = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = library.malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


def release_free_memory() -> bool:
    """Hand the C heap's free pages back to the operating system; whether any were (False where it cannot)."""
    trim = _trim()
    return bool(trim(0)) if trim is not None else False
