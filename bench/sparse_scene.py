"""The sparse benchmark scene: 27 copies of the Igea scan (the largest scanned
model in tests/data/models after the bunny, 268,686 triangles) on a 3x3x3
grid whose step is 4x the scan's largest extent, so that most of the scene's
box is empty: 7.25 M triangles, of which about 15 % of bench/make_rays.py's
camera rays hit something (13 % of its incoherent rays). It stands for the
scenes where most rays touch nothing: what a ray that misses costs matters.

The copies are written once as a binary little-endian PLY (shared vertices,
one triangle list per copy, copy-major: copy c's triangle k is primitive
c * 268,686 + k, k in the scan's own triangle order) into the bench's work
directory; the scan's triangles are read back from a store of it, so the
triangles are the ones Outcore packs from tests/data/models/igea.ply.
"""
import json
import os

import numpy as np

from common import ROOT, prepare_store, read_store_triangles

MODEL = os.path.join(ROOT, "tests", "data", "models", "igea.ply")
GRID = 3  # copies along each axis
STEP = 4.0  # grid step over the scan's largest extent: ~15 % of camera rays hit


def write_sparse_scene(outcore, work):
    """Writes work/sparse.ply and its layout, work/sparse.layout.json (the
    first copy's box, the grid step and size), unless they are there;
    returns the PLY's path."""
    path = os.path.join(work, "sparse.ply")
    layout_path = os.path.join(work, "sparse.layout.json")
    if os.path.exists(path) and os.path.exists(layout_path):
        return path
    store, _ = prepare_store(outcore, work, "igea", [MODEL])
    tris, ids = read_store_triangles(store)
    tris = tris[np.argsort(ids[:, 1], kind="stable")].reshape(-1, 3).astype(np.float64)
    vertices, faces = np.unique(tris, axis=0, return_inverse=True)
    faces = faces.reshape(-1, 3).astype(np.int32)
    step = STEP * float((vertices.max(0) - vertices.min(0)).max())
    offsets = [np.array([i, j, k], np.float64) * step
               for i in range(GRID) for j in range(GRID) for k in range(GRID)]
    all_vertices = np.concatenate([vertices + o for o in offsets]).astype("<f4")
    face_rows = np.empty(len(offsets) * len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    face_rows["n"] = 3
    face_rows["v"] = np.concatenate([faces + c * len(vertices) for c in range(len(offsets))])
    header = (f"ply\nformat binary_little_endian 1.0\ncomment outcore bench: {len(offsets)} copies of igea.ply\n"
              f"element vertex {len(all_vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(face_rows)}\nproperty list uchar int vertex_indices\nend_header\n")
    temporary = path + ".tmp"
    with open(temporary, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(all_vertices.tobytes())
        f.write(face_rows.tobytes())
    os.replace(temporary, path)
    copy = all_vertices[:len(vertices)].astype(np.float64)
    with open(layout_path, "w") as f:
        json.dump({"copy_min": copy.min(0).tolist(), "copy_max": copy.max(0).tolist(), "step": step,
                   "grid": GRID}, f)
    return path


def sparse_layout(work):
    """The layout write_sparse_scene wrote: (first copy's min, max, step, grid)."""
    with open(os.path.join(work, "sparse.layout.json")) as f:
        layout = json.load(f)
    return np.array(layout["copy_min"]), np.array(layout["copy_max"]), layout["step"], layout["grid"]
