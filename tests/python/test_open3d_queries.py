"""Open3D's other RaycastingScene calls through `outcore serve`:
count_intersections, list_intersections, compute_closest_points,
compute_distance, compute_signed_distance and compute_occupancy, against a
numpy float64 brute force over the scene's triangles (small bricks, a
small cache); bad shapes and dtypes are ValueErrors
naming the argument; options after the arrays are keyword-only.
"""

from __future__ import annotations

import numpy as np
import pytest

import outcore
from support import Server, run_outcore


def cube(center, half):
    """A closed axis-aligned cube (12 triangles, outward)."""
    c = np.asarray(center, float)
    v = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float) * half + c
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    tris = []
    for a, b, cc, d in quads:
        tris += [(a, b, cc), (a, cc, d)]
    return v, np.array(tris)


def grid(n, size, z):
    """An open height field of 2 n^2 triangles over [0, size]^2 (a terrain)."""
    xs = np.linspace(0, size, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    h = z + 0.2 * np.sin(x) * np.cos(y)
    v = np.stack([x.ravel(), y.ravel(), h.ravel()], 1)
    tris = []
    for i in range(n):
        for j in range(n):
            a = i * (n + 1) + j
            tris += [(a, a + n + 1, a + 1), (a + 1, a + n + 1, a + n + 2)]
    return v, np.array(tris)


MESHES = [cube((0, 0, 0), 1.0), cube((4, 0.5, 0.25), 0.75), grid(16, 6.0, -3.0)]


def write_obj(path, vertices, triangles):
    with open(path, "w") as f:
        for p in vertices:
            f.write(f"v {float(p[0])!r} {float(p[1])!r} {float(p[2])!r}\n")
        for t in triangles:
            f.write(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n")


def scene_triangles():
    """(T, 3, 3) float64 vertices as float32 rounds them, geometry and primitive ids."""
    tris, geometry, primitive = [], [], []
    for g, (v, t) in enumerate(MESHES):
        tris.append(v.astype(np.float32).astype(np.float64)[t])
        geometry.append(np.full(len(t), g))
        primitive.append(np.arange(len(t)))
    return np.concatenate(tris), np.concatenate(geometry), np.concatenate(primitive)


@pytest.fixture(scope="module")
def brick_server(tmp_path_factory):
    d = tmp_path_factory.mktemp("o3d")
    paths = []
    for k, (v, t) in enumerate(MESHES):
        paths.append(d / f"mesh{k}.obj")
        write_obj(paths[-1], v, t)
    store = d / "scene.oc"
    run_outcore("pack", *paths, "-o", store, "--brick-tris", 64, "-q")
    server = Server(store, "--cache-mb", "1")
    yield server
    assert server.stop() == 0


def every_hit(tris, rays):
    """Float64 Moller-Trumbore over every triangle: (N, T) t (nan: no hit)."""
    o, d = rays[:, None, :3], rays[:, None, 3:6]
    v0, e1, e2 = tris[None, :, 0], tris[None, :, 1] - tris[None, :, 0], tris[None, :, 2] - tris[None, :, 0]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1 / det
        s = o - v0
        u = np.sum(s * p, -1) * inv
        q = np.cross(s, e1)
        v = np.sum(d * q, -1) * inv
        t = np.sum(e2 * q, -1) * inv
    hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    edge = (det != 0) & (np.minimum(np.minimum(u, v), 1 - u - v) > -1e-6) & \
        (np.minimum(np.minimum(u, v), 1 - u - v) < 1e-6)
    return np.where(hit, t, np.nan), edge.any(1)


def closest_distance(tris, points):
    """Float64 distance from each point to the nearest triangle (brute force)."""
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    out = np.empty(len(points))
    n = np.cross(b - a, c - a)
    n_len = np.linalg.norm(n, axis=1)
    for i, p in enumerate(points):
        # Inside the prism over the triangle: the plane distance.
        w = p - a
        normal = n / n_len[:, None]
        plane = np.abs(np.sum(w * normal, 1))
        proj = p - np.sum(w * normal, 1)[:, None] * normal
        c1 = np.sum(np.cross(b - a, proj - a) * n, 1)
        c2 = np.sum(np.cross(c - b, proj - b) * n, 1)
        c3 = np.sum(np.cross(a - c, proj - c) * n, 1)
        inside = (c1 >= 0) & (c2 >= 0) & (c3 >= 0)
        best = np.where(inside, plane, np.inf)
        for s0, s1 in ((a, b), (b, c), (c, a)):
            e = s1 - s0
            t = np.clip(np.sum((p - s0) * e, 1) / np.sum(e * e, 1), 0, 1)
            best = np.minimum(best, np.linalg.norm(p - (s0 + t[:, None] * e), axis=1))
        out[i] = best.min()
    return out


def random_rays(n, seed):
    rng = np.random.default_rng(seed)
    origins = rng.uniform([-3, -3, -5], [7, 5, 4], (n, 3))
    targets = rng.uniform([-1, -1, -3], [5, 2, 1], (n, 3))
    return np.concatenate([origins, targets - origins], 1).astype(np.float32)


def test_counts_and_lists_match_brute_force(brick_server):
    tris, geometry, primitive = scene_triangles()
    rays = random_rays(600, 1).reshape(20, 30, 6)
    with outcore.SceneClient(brick_server.address, timeout=60) as client:
        counts = client.count_intersections(rays)
        listed = client.list_intersections(rays)
        stats = client.last_stats
    assert counts.dtype == np.int32 and counts.shape == (20, 30)
    flat = rays.reshape(-1, 6).astype(np.float64)
    t, grazing = every_hit(tris, flat)
    expected = np.sum(~np.isnan(t), 1)
    keep = ~grazing
    assert keep.sum() > 550
    np.testing.assert_array_equal(counts.ravel()[keep], expected[keep])
    assert expected.sum() > 600  # closed cubes: two hits a ray through them
    splits = listed["ray_splits"]
    assert splits.dtype == np.uint32 and splits.shape == (601,)
    assert listed["ray_ids"].dtype == np.uint32 and listed["primitive_uvs"].shape == (splits[-1], 2)
    np.testing.assert_array_equal(np.diff(splits.astype(np.int64)), counts.ravel())
    for i in np.flatnonzero(keep)[::7]:
        lo, hi = splits[i], splits[i + 1]
        assert np.all(listed["ray_ids"][lo:hi] == i)
        order = np.argsort(t[i][~np.isnan(t[i])], kind="stable")
        hit = np.flatnonzero(~np.isnan(t[i]))[order]
        np.testing.assert_allclose(listed["t_hit"][lo:hi], t[i][hit], rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(listed["geometry_ids"][lo:hi], geometry[hit])
        np.testing.assert_array_equal(listed["primitive_ids"][lo:hi], primitive[hit])
    assert stats["brick_visits"] > len(flat)  # rays went brick by brick


def test_closest_points_and_distances_match_brute_force(brick_server):
    tris, geometry, primitive = scene_triangles()
    rng = np.random.default_rng(2)
    points = rng.uniform([-3, -3, -5], [7, 5, 4], (300, 3)).astype(np.float32)
    expected = closest_distance(tris, points.astype(np.float64))
    with outcore.SceneClient(brick_server.address, timeout=60) as client:
        closest = client.compute_closest_points(points.reshape(10, 30, 3))
        distance = client.compute_distance(points)
    assert set(closest) == {"points", "geometry_ids", "primitive_ids", "primitive_uvs", "primitive_normals"}
    assert closest["points"].shape == (10, 30, 3) and closest["primitive_ids"].shape == (10, 30)
    assert distance.dtype == np.float32 and distance.shape == (300,)
    np.testing.assert_allclose(distance, expected, rtol=1e-6, atol=1e-7)
    found = closest["points"].reshape(-1, 3).astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(found - points, axis=1), expected, rtol=1e-5, atol=1e-6)
    # The reported triangle holds the point: its own distance is the answer.
    g = closest["geometry_ids"].ravel()
    p = closest["primitive_ids"].ravel()
    index = {(gg, pp): k for k, (gg, pp) in enumerate(zip(geometry, primitive))}
    reported = tris[[index[(a, b)] for a, b in zip(g, p)]]
    own = np.array([closest_distance(reported[k:k + 1], points[k:k + 1].astype(np.float64))[0]
                    for k in range(len(points))])
    np.testing.assert_allclose(own, expected, rtol=1e-6, atol=1e-7)


def test_occupancy_and_signed_distance_inside_closed_cubes(brick_server):
    rng = np.random.default_rng(3)
    points = rng.uniform([-2, -2, -2], [6, 2, 2], (2000, 3)).astype(np.float32)
    in_a = np.all(np.abs(points) < 1, 1)
    in_b = np.all(np.abs(points - np.array([4, 0.5, 0.25], np.float32)) < 0.75, 1)
    near_face = (np.abs(np.max(np.abs(points), 1) - 1) < 1e-4) | \
        (np.abs(np.max(np.abs(points - np.array([4, 0.5, 0.25], np.float32)), 1) - 0.75) < 1e-4)
    # Points whose first ray would leave through a cube's edge or corner.
    corner = np.array([[1, 1, 1], [1, -1, 0.2], [0.2, 1, 1]], np.float32) - 0.4 * np.array([0.3, 0.8, 0.4],
                                                                                           np.float32)
    points = np.concatenate([points[~near_face], corner])
    inside = np.concatenate([(in_a | in_b)[~near_face], np.all(np.abs(corner) < 1, 1)])
    with outcore.SceneClient(brick_server.address, timeout=60) as client:
        occupancy = client.compute_occupancy(points)
        signed = client.compute_signed_distance(points, nsamples=3)
        distance = client.compute_distance(points)
    assert occupancy.dtype == np.float32
    np.testing.assert_array_equal(occupancy, inside.astype(np.float32))
    np.testing.assert_array_equal(signed, np.where(inside, -distance, distance))


def test_bad_arguments_name_what_is_wrong(server):
    with outcore.SceneClient(server.address, timeout=30) as client:
        with pytest.raises(ValueError, match="query_points"):
            client.compute_distance(np.zeros((4, 2), np.float32))
        with pytest.raises(ValueError, match="query_points"):
            client.compute_closest_points(np.array(["a", "b", "c"]))
        with pytest.raises(ValueError, match="rays"):
            client.count_intersections(np.zeros((4, 5), np.float32))
        with pytest.raises(ValueError, match="nsamples"):
            client.compute_occupancy(np.zeros((1, 3)), nsamples=2)
        with pytest.raises(ValueError, match="tnear"):
            client.test_occlusions(np.zeros((1, 6), np.float32), float("nan"))
        with pytest.raises(ValueError, match="carry their own"):
            client.test_occlusions(np.zeros((1, 8), np.float32), 0.5)
        with pytest.raises(TypeError):
            client.cast_rays(np.zeros((1, 6), np.float32), True)  # strict is keyword-only
        with pytest.raises(TypeError):
            client.count_intersections(np.zeros((1, 6), np.float32), True)


def test_occlusions_take_tnear_and_tfar_as_open3d(server):
    rays = np.zeros((3, 6), np.float32)
    rays[:, :3] = (0.2, 0.1, -10)  # at the small sphere of support.SPHERE
    rays[:, 5] = 1
    with outcore.SceneClient(server.address, timeout=30) as client:
        t = client.cast_rays(rays)["t_hit"]
        assert np.isfinite(t).all()
        assert client.test_occlusions(rays).all()
        assert not client.test_occlusions(rays, 0.0, float(t[0]) * 0.99).any()
        assert client.test_occlusions(rays, tnear=float(t[0]) * 0.99).all()
