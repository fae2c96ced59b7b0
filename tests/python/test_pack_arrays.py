"""outcore.pack: arrays packed by the real `outcore pack` (.npz inputs) and
served by the real `outcore serve` answer cast_rays as a float64 numpy brute
force over the same triangles does (geometry_id = the mesh's position,
primitive_id = the triangle's row); bad arrays are ValueErrors naming the
argument and row before anything runs; a failing binary is a PackError
carrying its message; no temporary file is left behind."""

from __future__ import annotations

import numpy as np
import pytest

import outcore
from support import Server, binary, run_outcore


def triangle_soup(rng, count: int, centre, size: float):
    """(vertices (3 count, 3) float64, triangles (count, 3) int64): triangles
    of about size/5 scattered in a cube of side `size` at `centre`."""
    corners = np.asarray(centre) + (rng.random((count, 1, 3)) - 0.5) * size
    vertices = (corners + rng.normal(scale=size / 10, size=(count, 3, 3))).reshape(-1, 3)
    return vertices, np.arange(3 * count, dtype=np.int64).reshape(count, 3)


def brute_force(rays: np.ndarray, meshes) -> dict:
    """Closest hits in float64 (Moeller-Trumbore, no epsilon) over every
    triangle of `meshes` as packed (float32 vertices), plus how clear-cut each
    answer is: the smallest barycentric margin of the hit (or of the nearest
    miss), and the gap to the second-closest hit."""
    tris, ids = [], []
    for g, (v, t) in enumerate(meshes):
        v32 = np.asarray(v, dtype=np.float32).astype(np.float64)
        tris.append(v32[np.asarray(t)])
        ids += [(g, k) for k in range(len(t))]
    tri = np.concatenate(tris)  # (T, 3, 3)
    ids = np.array(ids)
    o = rays[:, None, 0:3].astype(np.float64)
    d = rays[:, None, 3:6].astype(np.float64)
    e1, e2 = tri[None, :, 1] - tri[None, :, 0], tri[None, :, 2] - tri[None, :, 0]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = o - tri[None, :, 0]
        u = np.sum(s * p, axis=-1) * inv
        q = np.cross(s, e1)
        v = np.sum(d * q, axis=-1) * inv
        t = np.sum(e2 * q, axis=-1) * inv
    margin = np.minimum(np.minimum(u, v), 1 - u - v)
    valid = (det != 0) & (margin >= 0) & (t > 0)
    t_valid = np.where(valid, t, np.inf)
    order = np.argsort(t_valid, axis=1)
    best, second = order[:, 0], order[:, 1]
    rows = np.arange(len(rays))
    t_best, t_second = t_valid[rows, best], t_valid[rows, second]
    hit = np.isfinite(t_best)
    # Near-misses: the largest margin among triangles in front of the ray.
    near = np.where((det != 0) & (t > 0), margin, -np.inf)
    with np.errstate(invalid="ignore"):  # inf - inf where there is one hit or none
        gap_clear = t_second - t_best > 1e-4 * t_best
    return {
        "hit": hit,
        "t": t_best,
        "geometry_id": np.where(hit, ids[best, 0], outcore.INVALID_ID),
        "primitive_id": np.where(hit, ids[best, 1], outcore.INVALID_ID),
        "clear": np.where(hit, (margin[rows, best] > 1e-4) & gap_clear,
                          near.max(axis=1) < -1e-4),
    }


@pytest.fixture(scope="module")
def meshes():
    rng = np.random.default_rng(3)
    first = triangle_soup(rng, 300, (0, 0, 0), 4.0)
    # The second mesh in other dtypes: float32 vertices, uint32 indices, shuffled rows.
    v, t = triangle_soup(rng, 200, (1.5, -1, 0.5), 3.0)
    t = t[rng.permutation(len(t))]
    return [first, (v.astype(np.float32), t.astype(np.uint32))]


@pytest.fixture(scope="module")
def packed(meshes, tmp_path_factory):
    path = tmp_path_factory.mktemp("arrays") / "scene.oc"
    # Small bricks: the answers must not depend on how triangles were split.
    returned = outcore.pack(meshes, path, binary=binary(), extra_args=("--brick-tris", 64))
    assert returned == path
    return path


@pytest.fixture(scope="module")
def client(packed):
    server = Server(packed)
    with outcore.SceneClient(server.address, timeout=60) as c:
        yield c
    assert server.stop() == 0, "".join(server.lines)


def random_rays(rng, n: int, centre, radius: float) -> np.ndarray:
    unit = rng.normal(size=(n, 3))
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    origins = np.asarray(centre) + radius * unit
    targets = np.asarray(centre) + (rng.random((n, 3)) - 0.5) * radius
    return np.concatenate([origins, targets - origins], axis=1).astype(np.float32)


def test_packed_arrays_answer_cast_rays_as_a_float64_brute_force(client, meshes, packed):
    info = client.scene_info()
    assert [i["triangle_count"] for i in info["inputs"]] == [300, 200]
    assert info["brick_count"] > 1
    rays = random_rays(np.random.default_rng(11), 3000, (0.5, -0.3, 0.2), 6.0)
    ans = client.cast_rays(rays)
    ref = brute_force(rays, meshes)
    clear = ref["clear"]
    assert clear.sum() > 2500 and ref["hit"][clear].sum() > 1000 and (~ref["hit"][clear]).sum() > 300
    assert np.array_equal(ans["geometry_ids"][clear], ref["geometry_id"][clear])
    assert np.array_equal(ans["primitive_ids"][clear], ref["primitive_id"][clear])
    hit = clear & ref["hit"]
    np.testing.assert_allclose(ans["t_hit"][hit], ref["t"][hit], rtol=1e-5)
    assert np.all(np.isinf(ans["t_hit"][clear & ~ref["hit"]]))


def test_one_mesh_is_geometry_0_with_its_rows_as_primitive_ids_and_degenerates_counted(tmp_path):
    # Rows: a unit square at z = 0 (two triangles), a degenerate triangle, and
    # a triangle at z = 1 over x in [2, 3].
    vertices = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 1], [3, 0, 1], [2, 1, 1]]
    triangles = [[0, 1, 2], [0, 2, 3], [1, 1, 2], [4, 5, 6]]
    path = outcore.pack(vertices, triangles, tmp_path / "one.oc", binary=binary())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.oc"]  # no temporary files left
    server = Server(path)
    try:
        with outcore.SceneClient(server.address, timeout=60) as c:
            info = c.scene_info()
            assert len(info["inputs"]) == 1
            assert info["inputs"][0]["triangle_count"] == 4
            assert info["inputs"][0]["degenerate_count"] == 1
            rays = np.array([[0.75, 0.25, 5, 0, 0, -1], [0.25, 0.75, 5, 0, 0, -1], [2.25, 0.25, 5, 0, 0, -1],
                             [9, 9, 5, 0, 0, -1]], np.float32)
            ans = c.cast_rays(rays)
    finally:
        assert server.stop() == 0
    assert ans["geometry_ids"].tolist() == [0, 0, 0, outcore.INVALID_ID]
    assert ans["primitive_ids"].tolist() == [0, 1, 3, outcore.INVALID_ID]
    np.testing.assert_allclose(ans["t_hit"][:3], [5.0, 5.0, 4.0], rtol=1e-6)


def test_the_binary_comes_from_outcore_binary_when_not_given(tmp_path, monkeypatch):
    monkeypatch.setenv("OUTCORE_BINARY", str(binary()))
    path = outcore.pack([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], tmp_path / "env.oc")
    assert "triangles" in run_outcore("info", path).stdout
    monkeypatch.setenv("OUTCORE_BINARY", str(tmp_path / "missing"))
    with pytest.raises(FileNotFoundError, match="OUTCORE_BINARY"):
        outcore.pack([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], tmp_path / "never.oc")
    with pytest.raises(FileNotFoundError, match="binary argument"):
        outcore.pack([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], tmp_path / "never.oc",
                     binary=tmp_path / "nowhere")
    assert not (tmp_path / "never.oc").exists()


def test_a_failing_pack_raises_pack_error_with_the_binarys_message_and_force_replaces(tmp_path):
    v, t = [[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]
    path = outcore.pack(v, t, tmp_path / "s.oc", binary=binary())
    with pytest.raises(outcore.PackError) as failed:
        outcore.pack(v, t, path, binary=binary())
    assert failed.value.returncode != 0
    assert "--force" in failed.value.stderr and "--force" in str(failed.value)
    with pytest.raises(outcore.PackError, match="brick-tris"):
        outcore.pack(v, t, tmp_path / "t.oc", binary=binary(), extra_args=("--brick-tris", 0))
    outcore.pack([[0, 0, 0], [2, 0, 0], [0, 2, 0]], t, path, binary=binary(), force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.oc"]  # temporary files gone, also on failure


V3 = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]
T2 = [[0, 1, 2], [1, 3, 2]]


@pytest.mark.parametrize(
    "vertices, triangles, message",
    [
        ([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]], r"vertices must be a \(V, 3\)"),
        (np.zeros((4, 3), dtype=bool), T2, "vertices must be"),
        (np.array([["a", "b", "c"]] * 4), T2, "vertices must be"),
        (np.zeros((4, 3), dtype=complex), T2, "vertices must be"),
        (V3[:3] + [[0, np.nan, 0]], T2, "vertices: row 3: coordinate y is not finite"),
        (V3[:3] + [[np.inf, 0, 0]], T2, "vertices: row 3: coordinate x is not finite"),
        ([[1e39, 0, 0]] + V3[1:], T2, "vertices: row 0: coordinate x is not finite in float32"),
        ([[0, 0, -1e12]] + V3[1:], T2, r"vertices: row 0: coordinate z = -1000000000000.0 is beyond"),
        (V3, [[0, 1]], r"triangles must be a \(T, 3\)"),
        (V3, [[0.0, 1.0, 2.0]], "triangles must be"),
        (V3, np.ones((1, 3), dtype=bool), "triangles must be"),
        (V3, [[0, 1, 2], [1, 4, 2]], r"triangles: row 1: vertex index 4 out of range \(4 vertices\)"),
        (V3, [[0, -1, 2]], "triangles: row 0: vertex index -1 out of range"),
        ([[[0, 0, 0]], [[1, 0]]], T2, "vertices must be an array"),
    ],
)
def test_bad_arrays_are_value_errors_naming_the_argument_and_row(tmp_path, vertices, triangles, message):
    with pytest.raises(ValueError, match=message):
        outcore.pack(vertices, triangles, tmp_path / "bad.oc", binary=binary())
    assert not any(tmp_path.iterdir())


def test_bad_mesh_lists_and_paths_are_value_errors_naming_them(tmp_path):
    good = (V3, T2)
    with pytest.raises(ValueError, match=r"meshes\[1\] triangles: row 0: vertex index 7"):
        outcore.pack([good, (V3, [[0, 1, 7]])], tmp_path / "x.oc", binary=binary())
    with pytest.raises(ValueError, match=r"meshes\[0\] must be a \(vertices, triangles\) pair"):
        outcore.pack([V3], tmp_path / "x.oc", binary=binary())
    with pytest.raises(ValueError, match="meshes is empty"):
        outcore.pack([], tmp_path / "x.oc", binary=binary())
    with pytest.raises(ValueError, match=r"pack\(vertices, triangles, path\)"):
        outcore.pack(np.array(V3), tmp_path / "x.oc", binary=binary())
    with pytest.raises(ValueError, match="path"):
        outcore.pack(V3, T2, 42, binary=binary())
    assert not any(tmp_path.iterdir())
