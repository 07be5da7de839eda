"""PolyU 3D+ ground truth: per-sample MATLAB files holding a finger's height map.

The authors' own code reads the variable ``fc`` (a Frankot-Chellappa integration of photometric
normals) and flips it upside down to the image's orientation; non-finite values are background.
Files are MATLAB v5 (read by scipy) or v7.3 (HDF5, read by h5py when installed; stored
column-major, so transposed back here). When there is no ``fc``, the one 2-D numeric array of the
file is taken; when there is none or several, the error names the variables the file holds.

Heights rise toward the camera, so the depth the reconstruction is compared with is ``-height``
(up to the shift the evaluation fits anyway): a good prediction then has a positive scale.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import input_error

__all__ = ["HEIGHT_VARIABLE", "read_height_map", "depth_from_height"]

HEIGHT_VARIABLE = "fc"
_MIN_SIDE = 8


def _v5_variables(path: Path) -> dict[str, np.ndarray] | None:
    """Variables of a v5 file, or None when the file is v7.3 (HDF5)."""
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    try:
        return {k: v for k, v in loadmat(str(path)).items() if not k.startswith("__")}
    except NotImplementedError:  # "Please use HDF reader for matlab v7.3 files"
        return None
    except (MatReadError, ValueError, TypeError, OSError) as error:
        if _is_hdf5(path):  # an HDF5 file without MATLAB's header
            return None
        raise input_error(path, f"not a readable MATLAB file ({error})") from None


def _is_hdf5(path: Path) -> bool:
    """HDF5's signature at offset 0 or at a power-of-two user block (MATLAB v7.3 uses 512)."""
    signature = b"\x89HDF\r\n\x1a\n"
    with open(path, "rb") as handle:
        head = handle.read(4096 + 8)
    return any(head[offset:offset + 8] == signature for offset in (0, 512, 1024, 2048, 4096))


def _v73_variables(path: Path) -> dict[str, np.ndarray]:
    try:
        import h5py
    except ImportError:
        raise input_error(path, "is a MATLAB v7.3 (HDF5) file; reading it needs h5py (pip install h5py)") from None
    try:
        with h5py.File(path, "r") as handle:
            return {k: np.asarray(v).T for k, v in handle.items() if isinstance(v, h5py.Dataset)}
    except OSError as error:
        raise input_error(path, f"not a readable MATLAB v7.3 file ({error})") from None


def _is_map(value) -> bool:
    return (isinstance(value, np.ndarray) and value.ndim == 2 and min(value.shape) >= _MIN_SIDE
            and np.issubdtype(value.dtype, np.number))


def read_height_map(path: str | Path) -> np.ndarray:
    """The height map of one PolyU 3D+ sample, float64 ``[H, W]`` in the image's orientation,
    NaN where there is no finger (``InputError`` in one sentence when the file has no usable map)."""
    path = Path(path)
    if not path.is_file():
        raise input_error(path, "file not found")
    variables = _v5_variables(path)
    if variables is None:
        variables = _v73_variables(path)
    if HEIGHT_VARIABLE in variables and _is_map(variables[HEIGHT_VARIABLE]):
        height = variables[HEIGHT_VARIABLE]
    else:
        maps = [name for name, value in variables.items() if _is_map(value)]
        if len(maps) != 1:
            held = ", ".join(f"{k} {getattr(v, 'shape', '')}" for k, v in variables.items()) or "no variables"
            why = "no 2-D numeric array" if not maps else f"several 2-D arrays ({', '.join(maps)}) and no '{HEIGHT_VARIABLE}'"
            raise input_error(path, f"holds {why} to read as the height map; it holds: {held}")
        height = variables[maps[0]]
    height = np.flipud(np.asarray(height, dtype=np.float64)).copy()
    height[~np.isfinite(height)] = np.nan
    if not np.isfinite(height).any():
        raise input_error(path, "the height map has no finite value")
    return height


def depth_from_height(height: np.ndarray) -> np.ndarray:
    """Depth up to a shift: heights rise toward the camera (see the module docstring)."""
    return -height
