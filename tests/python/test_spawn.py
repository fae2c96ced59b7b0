"""outcore.spawn_origins: bitwise equal to `outcore trace --spawn-out` (the
C++ helper, core/ray/spawn_origin.h) on the same rays, for both sides, and
secondary rays from its origins never re-hit their own triangle."""

import subprocess

import numpy as np
import pytest

import outcore
from support import binary, make_rays


@pytest.fixture
def client(server):
    with outcore.SceneClient(server.address, timeout=60) as c:
        yield c


@pytest.mark.parametrize("side", ["front", "back"])
def test_spawn_origins_equal_the_cli_bitwise(client, store, bounds, tmp_path, side):
    rays = make_rays(bounds, 4000, seed=5, columns=8)
    result = client.cast_rays(rays)
    rays_path, hits_path, spawn_path = tmp_path / "r.npy", tmp_path / "h.npy", tmp_path / "s.npy"
    np.save(rays_path, rays)
    subprocess.run([str(binary()), "trace", str(store), "--rays", str(rays_path), "-o", str(hits_path),
                    "--spawn-out", str(spawn_path), "--spawn-side", side], check=True, capture_output=True)
    expected = np.load(spawn_path)
    got = outcore.spawn_origins(rays, result, side=side)
    assert got.shape == (len(rays), 3) and got.dtype == np.float32
    hit = np.isfinite(result["t_hit"])
    assert hit.any() and (~hit).any()
    assert np.all(np.isnan(got[~hit])) and np.all(np.isnan(expected[~hit]))
    assert np.array_equal(got[hit].view(np.uint32), expected[hit].view(np.uint32))


def test_reflected_rays_from_front_origins_never_hit_their_own_triangle(client, bounds):
    rays = make_rays(bounds, 4000, seed=9, columns=6)
    first = client.cast_rays(rays)
    hit = np.isfinite(first["t_hit"])
    origins = outcore.spawn_origins(rays, first)[hit]
    d = rays[hit, 3:6]
    n = first["primitive_normals"][hit]
    reflected = d - 2.0 * np.sum(d * n, axis=1, keepdims=True) * n
    second = client.cast_rays(np.concatenate([origins, reflected], axis=1).astype(np.float32))
    same = ((second["geometry_ids"] == first["geometry_ids"][hit]) &
            (second["primitive_ids"] == first["primitive_ids"][hit]))
    assert not same.any()


def test_bad_side_and_mismatched_result_are_value_errors(client, bounds):
    rays = make_rays(bounds, 10, seed=1, columns=6)
    result = client.cast_rays(rays)
    with pytest.raises(ValueError, match="side"):
        outcore.spawn_origins(rays, result, side="up")
    with pytest.raises(ValueError, match="10 hits for 9 rays"):
        outcore.spawn_origins(rays[:9], result)
