"""outcore.pack: a scene store from numpy arrays, by the real `outcore pack`.

Each mesh is checked here (so a mistake is a ValueError naming the argument
and the row, before anything runs), written as an .npz input (`vertices`
(V, 3) float32, `triangles` (T, 3) uint32; docs/INPUTS.md, ".npz") into a
temporary directory beside the store, and the binary packs them all, in
order: geometry_id k is the k-th mesh, primitive_id a triangle's row. The
temporary files go whatever happens. The binary is found as
outcore._binary.find_outcore_binary says (binary=, $OUTCORE_BINARY, PATH).

Thread-safety: pack() may run in several threads at once (separate
temporary directories), but two packs to one path race as two `outcore
pack` processes do (the store is committed atomically; one wins).
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ._binary import find_outcore_binary

__all__ = ["pack", "PackError"]

# The largest vertex coordinate a store may hold (core/geometry/coordinate_limits.h).
LARGEST_VERTEX_COMPONENT = 2.0**39
_MAX_TRIANGLES = 0xFFFFFFFF - 1  # primitive ids are 32-bit (one value means "miss")


class PackError(RuntimeError):
    """`outcore pack` failed: ``returncode``, ``stderr`` (its message) and
    ``command`` (the argument list) say how."""

    def __init__(self, command: list[str], returncode: int, stderr: str):
        self.command = command
        self.returncode = returncode
        self.stderr = stderr
        super().__init__(f"outcore pack exited {returncode}: {stderr.strip() or '(no message)'}")


def pack(vertices, triangles, path=None, *, force: bool = False, binary=None, extra_args=()) -> Path:
    """Packs meshes given as arrays into the scene store `path` and returns
    its Path.

    pack(vertices, triangles, path): one mesh, geometry_id 0. vertices (V, 3)
    real numbers (converted to float32, as every input is), triangles (T, 3)
    integer vertex indices (0-based).
    pack([(vertices0, triangles0), (vertices1, triangles1), ...], path):
    several meshes, geometry_id = position in the list.

    force: replace an existing store at `path` (`pack --force`; anything else
    there is refused, never deleted). binary: the `outcore` executable
    (default: $OUTCORE_BINARY, else `outcore` on the PATH). extra_args: more
    `outcore pack` options, e.g. ("--brick-tris", 4096).

    Raises ValueError naming the argument (and the row) for arrays of the
    wrong shape or dtype, non-finite or too large coordinates (beyond
    +-2^39) and indices out of range; FileNotFoundError without a binary;
    PackError with the binary's message when it fails.
    """
    if path is None:
        meshes, path, names = _mesh_list(vertices), triangles, None
    else:
        meshes, names = [(vertices, triangles)], ("vertices", "triangles")
    if path is None or not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"path must be a file system path for the store, got {path!r}")
    checked = [
        _checked_mesh(v, t, names or (f"meshes[{k}] vertices", f"meshes[{k}] triangles"))
        for k, (v, t) in enumerate(meshes)
    ]
    exe = find_outcore_binary(binary)
    store = Path(path)
    # Beside the store: on its disk (the packer's own temporary files go there
    # too), not in a /tmp that may be memory.
    parent = store.resolve().parent
    with tempfile.TemporaryDirectory(prefix=".outcore-pack-", dir=parent) as scratch:
        inputs = []
        for k, (v, t) in enumerate(checked):
            npz = Path(scratch) / f"geometry{k}.npz"
            np.savez(npz, vertices=v, triangles=t)
            inputs.append(str(npz))
        command = [str(exe), "pack", *inputs, "-o", str(store), "-q"]
        command += ["--force"] if force else []
        command += [str(a) for a in extra_args]
        result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise PackError(command, result.returncode, result.stderr)
    return store


def _mesh_list(meshes) -> list:
    if isinstance(meshes, np.ndarray) or not isinstance(meshes, (list, tuple)):
        raise ValueError(
            "with two arguments, pack(meshes, path) needs meshes as a list of (vertices, triangles) "
            f"pairs; for one mesh call pack(vertices, triangles, path) (got {type(meshes).__name__})"
        )
    if not meshes:
        raise ValueError("meshes is empty: a scene needs at least one (vertices, triangles) pair")
    for k, mesh in enumerate(meshes):
        if not isinstance(mesh, (list, tuple)) or len(mesh) != 2:
            raise ValueError(f"meshes[{k}] must be a (vertices, triangles) pair")
    return list(meshes)


def _as_array(value, name: str) -> np.ndarray:
    try:
        return np.asarray(value)
    except (TypeError, ValueError) as e:  # ragged lists and the like
        raise ValueError(f"{name} must be an array of shape (N, 3): {e}") from None


def _checked_mesh(vertices, triangles, names: tuple[str, str]) -> tuple[np.ndarray, np.ndarray]:
    """(float32 vertices, uint32 triangles), C-contiguous, checked as the
    .npz reader checks them (same limits, named rows)."""
    v_name, t_name = names
    v = _as_array(vertices, v_name)
    if v.dtype.kind not in "fiu" or v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"{v_name} must be a (V, 3) array of real numbers, got shape {v.shape} dtype {v.dtype}")
    with np.errstate(over="ignore", invalid="ignore"):
        v32 = np.ascontiguousarray(v, dtype="<f4")
    bad = ~np.isfinite(v32)
    if bad.any():
        row, axis = np.argwhere(bad)[0]
        raise ValueError(
            f"{v_name}: row {row}: coordinate {'xyz'[axis]} is not finite in float32 ({float(v[row, axis])!r})"
        )
    far = np.abs(v32) > LARGEST_VERTEX_COMPONENT
    if far.any():
        row, axis = np.argwhere(far)[0]
        raise ValueError(
            f"{v_name}: row {row}: coordinate {'xyz'[axis]} = {float(v[row, axis])!r} is beyond +-5.5e11 (2^39), "
            "the largest the float ray/triangle tests handle"
        )
    if v.shape[0] > 0xFFFFFFFF:
        raise ValueError(f"{v_name} has {v.shape[0]} rows; at most 4294967295 vertices can be indexed")
    t = _as_array(triangles, t_name)
    if t.dtype.kind not in "iu" or t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(
            f"{t_name} must be a (T, 3) array of integer vertex indices, got shape {t.shape} dtype {t.dtype}"
        )
    if t.shape[0] > _MAX_TRIANGLES:
        raise ValueError(f"{t_name} has {t.shape[0]} rows; an input may hold at most {_MAX_TRIANGLES}")
    if t.size:
        out_of_range = (t < 0) | (t >= v.shape[0])
        if out_of_range.any():
            row, corner = np.argwhere(out_of_range)[0]
            raise ValueError(
                f"{t_name}: row {row}: vertex index {t[row, corner]} out of range ({v.shape[0]} vertices)"
            )
    return v32, np.ascontiguousarray(t, dtype="<u4")
