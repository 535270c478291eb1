"""What callers hand the package, checked once for Shape and PrunedGrid alike: output paths
(by extension, and writable before any work) and point arrays."""
from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any, Sequence, Tuple

if TYPE_CHECKING:
    import numpy as np

from . import _sdfprune as _core

_MESH_EXTS = (".stl", ".ply", ".obj")
_SAVE_EXTS = _MESH_EXTS + (".npy", ".vdb", ".png")


def _check_ext(path: Any, allowed: Sequence[str]) -> Tuple[str, str]:
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in allowed:
        raise OSError(f'{path}: unknown output extension "{ext}" (expected {", ".join(allowed)})')
    _core.check_writable(path)
    return path, ext


def _points(points: Any) -> "np.ndarray":
    """An (N, 3) float32/float64 view of `points` (no copy for float32/float64 arrays)."""
    import numpy as np
    if isinstance(points, np.ndarray) and points.dtype in (np.float32, np.float64):
        arr = points
    else:
        try:
            arr = np.asarray(points)
        except Exception as e:
            raise ValueError(f"points must be an (N, 3) array of numbers: {e}") from None
        if arr.dtype.kind not in "fiub" or arr.dtype == np.float16:
            if arr.dtype.kind in "fiub":
                arr = arr.astype(np.float32)
            else:
                raise ValueError(f"points must be numbers (got dtype {arr.dtype})")
        if arr.dtype not in (np.float32, np.float64):
            arr = arr.astype(np.float64)
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr.reshape(1, 3)
    elif arr.ndim == 2 and arr.shape[0] == 0 and arr.shape[1] != 3:
        raise ValueError(f"points must be an (N, 3) array (got shape {arr.shape})")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"points must be an (N, 3) array (got shape {arr.shape})")
    return arr
