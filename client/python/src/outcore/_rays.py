"""Ray batches as the wire wants them: (N, 6) or (N, 8) little-endian float32;
points as (N, 3).

Thread-safety: pure functions.
"""

from __future__ import annotations

import math

import numpy as np

RAY_COLUMNS = (6, 8)
_WIRE_DTYPE = np.dtype("<f4")


def as_wire_rays(rays) -> tuple[np.ndarray, tuple[int, ...]]:
    """Returns (flat, batch_shape): `flat` is C-contiguous (N, 6|8) '<f4', a
    view of `rays` when it already is one; `batch_shape` is rays.shape[:-1],
    the shape the per-ray results are given back in (Open3D's convention).

    Raises ValueError naming the problem for anything that is not a real
    numeric array of shape (..., 6) or (..., 8).
    """
    arr = _real_numbers(rays, "rays", "(..., 6) or (..., 8)")
    if arr.ndim < 2 or arr.shape[-1] not in RAY_COLUMNS:
        raise ValueError(
            "rays must have shape (N, 6) [ox oy oz dx dy dz] or (N, 8) [... tnear tfar] "
            f"(leading batch dims allowed), got shape {arr.shape}"
        )
    flat = np.ascontiguousarray(arr, dtype=_WIRE_DTYPE).reshape(-1, arr.shape[-1])
    return flat, tuple(arr.shape[:-1])


def as_wire_points(points, name: str = "query_points") -> tuple[np.ndarray, tuple[int, ...]]:
    """Returns (flat, batch_shape) for points: `flat` C-contiguous (N, 3)
    '<f4'; `batch_shape` is points.shape[:-1]. ValueError naming `name` for
    anything that is not a real numeric array of shape (..., 3)."""
    arr = _real_numbers(points, name, "(..., 3)")
    if arr.ndim < 1 or arr.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got shape {arr.shape}")
    flat = np.ascontiguousarray(arr, dtype=_WIRE_DTYPE).reshape(-1, 3)
    return flat, tuple(arr.shape[:-1])


def _real_numbers(values, name: str, shape: str) -> np.ndarray:
    try:
        arr = np.asarray(values)
    except (TypeError, ValueError) as e:  # ragged lists and the like
        raise ValueError(f"{name} must be an array of numbers of shape {shape}: {e}") from None
    # Integers convert exactly enough; bool, complex, strings and objects do not.
    if arr.dtype.kind not in "fiu":
        raise ValueError(f"{name} must have a real numeric dtype (float32 preferred), got dtype {arr.dtype}")
    return arr


def rays_with_segment(rays, tnear, tfar) -> tuple[np.ndarray, tuple[int, ...]]:
    """Wire rays with tnear/tfar (test_occlusions' arguments) as columns 7-8."""
    flat, batch_shape = as_wire_rays(rays)
    for name, value in (("tnear", tnear), ("tfar", tfar)):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or \
                math.isnan(value):
            raise ValueError(f"{name} must be a number, got {value!r}")
    if tnear == 0.0 and tfar == math.inf:
        return flat, batch_shape
    if flat.shape[1] == 8:
        raise ValueError("rays of shape (..., 8) carry their own tnear and tfar; "
                         "give tnear/tfar either there or as arguments, not both")
    full = np.empty((flat.shape[0], 8), dtype="<f4")
    full[:, :6] = flat
    full[:, 6] = tnear
    full[:, 7] = tfar
    return full, batch_shape
