"""The dynamic layer over gRPC (`outcore serve`, Python SceneClient): meshes
added at run time, instances placed, moved, deformed and removed, each change
a new version; hits report the instance's geometry id (after the packed
inputs'), the mesh's primitive ids and exact t; a query names an old version
and gets its answers; the bytes, stream and shared-memory paths agree; bad
input is an error naming what was wrong, and changes nothing.
"""

from __future__ import annotations

import grpc
import numpy as np
import pytest

import outcore
from outcore.v1 import scene_query_pb2 as pb
from support import Server

# A closed unit cube: 8 vertices, 12 triangles.
CUBE_VERTICES = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                         dtype=np.float32)
CUBE_TRIANGLES = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                           [2, 3, 7], [2, 7, 6], [1, 2, 6], [1, 6, 5], [0, 4, 7], [0, 7, 3]], dtype=np.uint32)
FAR = 1000.0  # far from the packed scene, so only dynamic geometry is hit there


def placed_at(x, y=0.0, z=0.0, scale=1.0) -> np.ndarray:
    t = np.zeros((3, 4))
    t[:, :3] = np.eye(3) * scale
    t[:, 3] = (x, y, z)
    return t


def rays_up_at(x, n=64, seed=0) -> np.ndarray:
    """Rays along +z from z = -10 at points of the unit square at (x, 0)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.05, 0.95, (n, 2))
    rays = np.zeros((n, 6), np.float32)
    rays[:, 0] = x + xy[:, 0]
    rays[:, 1] = xy[:, 1]
    rays[:, 2] = -10
    rays[:, 5] = 1
    return rays


@pytest.fixture()
def dynamic_server(store):
    """A server of its own: the dynamic layer is per server."""
    server = Server(store, "--max-message-mb", 1)
    yield server
    assert server.stop() == 0


def test_instances_are_hit_with_their_ids_and_move_with_each_version(dynamic_server):
    with outcore.SceneClient(dynamic_server.address, timeout=60) as client:
        first_id = len(client.scene_info()["inputs"])
        mesh = client.add_mesh(CUBE_VERTICES, CUBE_TRIANGLES)
        assert mesh == 0 and client.last_dynamic_version == 1
        a = client.add_instance(mesh, placed_at(FAR))
        b = client.add_instance(mesh, placed_at(FAR + 5, scale=2))
        assert (a, b) == (first_id, first_id + 1), "dynamic ids continue after the packed inputs'"
        v_placed = client.last_dynamic_version
        assert v_placed == 3
        rays = np.concatenate([rays_up_at(FAR), rays_up_at(FAR + 5)])
        ans = client.cast_rays(rays)
        assert client.last_dynamic_version == v_placed
        assert np.array_equal(ans["geometry_ids"], np.repeat([a, b], 64))
        assert np.allclose(ans["t_hit"], 10.0, rtol=1e-6, atol=0)
        assert set(ans["primitive_ids"].tolist()) <= {0, 1}  # the bottom face
        assert np.allclose(ans["primitive_normals"], [0, 0, -1])
        assert client.test_occlusions(rays).all()

        v_moved = client.update_transforms([a], placed_at(FAR, z=3)[None])
        assert v_moved == v_placed + 1
        moved = client.cast_rays(rays)
        assert np.allclose(moved["t_hit"][:64], 13.0, rtol=1e-6, atol=0)
        assert moved["t_hit"][64:].tobytes() == ans["t_hit"][64:].tobytes()
        # The version before the move is still answered as it was.
        old = client.cast_rays(rays, dynamic_version=v_placed)
        assert client.last_dynamic_version == v_placed
        assert old["t_hit"].tobytes() == ans["t_hit"].tobytes()

        # Deform the mesh: every instance of it changes.
        v_deformed = client.update_vertices(mesh, CUBE_VERTICES * np.float32(0.5) + np.float32(0.25))
        deformed = client.cast_rays(rays)
        inner = ((rays[:64, 0] - FAR > 0.3) & (rays[:64, 0] - FAR < 0.7) & (rays[:64, 1] > 0.3)
                 & (rays[:64, 1] < 0.7))
        assert inner.sum() > 5
        assert np.allclose(deformed["t_hit"][:64][inner], 13.25, rtol=1e-6, atol=0)
        assert v_deformed == v_moved + 1

        stats = client.stats()
        assert stats["dynamic_version"] == v_deformed and stats["dynamic_meshes"] == 1
        assert stats["dynamic_instances"] == 2 and stats["dynamic_triangles"] == 24
        assert stats["dynamic_mesh_refits"] + stats["dynamic_mesh_rebuilds"] == 1
        assert stats["dynamic_top_refits"] + stats["dynamic_top_rebuilds"] >= 3
        v_removed = client.remove(a)
        gone = client.cast_rays(rays)
        assert v_removed == v_deformed + 1
        assert np.all(gone["primitive_ids"][:64] == outcore.INVALID_ID)
        # b's mesh was deformed too: its rays hit it where they did after that.
        assert gone["geometry_ids"][64:].tobytes() == deformed["geometry_ids"][64:].tobytes()
        assert np.any(gone["geometry_ids"][64:] == b)


def test_the_bytes_stream_and_shared_paths_agree_and_a_stream_sees_one_version(dynamic_server):
    with outcore.SceneClient(dynamic_server.address, timeout=60) as client:
        mesh = client.add_mesh(CUBE_VERTICES, CUBE_TRIANGLES)
        ids = [client.add_instance(mesh, placed_at(FAR + 3 * k)) for k in range(8)]
        rays = np.concatenate([rays_up_at(FAR + 3 * (k % 8), 8, seed=k) for k in range(5000)])  # 40,000 rays
        shared = client.cast_rays(rays)
        assert client.last_call_shared
        assert np.array_equal(np.unique(shared["geometry_ids"]), ids)
    with outcore.SceneClient(dynamic_server.address, timeout=60, shared_memory=False) as bytes_client:
        streamed = bytes_client.cast_rays(rays)  # > 1 MiB messages: streamed in chunks
    with outcore.SceneClient(dynamic_server.address, timeout=60, chunk_rays=3000) as chunked:
        chunks = chunked.cast_rays(rays)
    for key in ("t_hit", "geometry_ids", "primitive_ids", "primitive_uvs", "primitive_normals"):
        assert shared[key].tobytes() == streamed[key].tobytes() == chunks[key].tobytes(), key


def test_bad_input_is_a_named_error_and_changes_nothing(dynamic_server):
    with outcore.SceneClient(dynamic_server.address, timeout=60) as client:
        mesh = client.add_mesh(CUBE_VERTICES, CUBE_TRIANGLES)
        geometry = client.add_instance(mesh, placed_at(FAR))
        version = client.last_dynamic_version
        rays = rays_up_at(FAR)
        before = client.cast_rays(rays)

        def refused(code, words, call, *args, **kwargs):
            with pytest.raises(outcore.OutcoreError) as error:
                call(*args, **kwargs)
            assert error.value.code == code, error.value
            assert words in error.value.details, error.value.details

        nan = placed_at(FAR)
        nan[1, 1] = np.nan
        refused("INVALID_ARGUMENT", "element [1][1] is not finite", client.update_transforms, [geometry], nan[None])
        flat = placed_at(FAR)
        flat[2, 2] = 0
        refused("INVALID_ARGUMENT", "singular", client.add_instance, mesh, flat)
        refused("NOT_FOUND", "no such dynamic instance", client.update_transforms, [geometry + 7], placed_at(0)[None])
        refused("NOT_FOUND", "no mesh 9", client.add_instance, 9, placed_at(0))
        refused("INVALID_ARGUMENT", "topology is fixed", client.update_vertices, mesh, CUBE_VERTICES[:7])
        bad = CUBE_TRIANGLES.copy()
        bad[3, 1] = 8
        refused("INVALID_ARGUMENT", "triangle 3 names vertex 8", client.add_mesh, CUBE_VERTICES, bad)
        refused("NOT_FOUND", "geometry id", client.remove, geometry + 7)
        refused("NOT_FOUND", "does not exist yet", client.cast_rays, rays, dynamic_version=version + 50)
        with pytest.raises(ValueError):
            client.add_mesh(CUBE_VERTICES[:, :2], CUBE_TRIANGLES)
        # A raw request whose bytes do not match its count.
        stub = grpc.insecure_channel(dynamic_server.address).unary_unary(
            "/outcore.v1.SceneQuery/AddMesh", request_serializer=pb.AddMeshRequest.SerializeToString,
            response_deserializer=pb.AddMeshResponse.FromString)
        with pytest.raises(grpc.RpcError) as error:
            stub(pb.AddMeshRequest(vertex_count=5, vertices=b"\0" * 12, triangle_count=1, triangles=b"\0" * 12),
                 timeout=30)
        assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "vertices holds 12 bytes; vertex_count 5 needs 60" in error.value.details()

        after = client.cast_rays(rays)
        assert client.last_dynamic_version == version, "no failed change made a version"
        assert after["t_hit"].tobytes() == before["t_hit"].tobytes()


def frames_of(count: int, instances: int) -> np.ndarray:
    """(count, instances, 3, 4) placements: instance k at (FAR + 3k, 0, 0.5 frame)."""
    t = np.zeros((count, instances, 3, 4))
    for f in range(count):
        for k in range(instances):
            t[f, k] = placed_at(FAR + 3 * k, z=0.5 * f)
    return t


def test_trace_dynamic_file_answers_as_the_server_frame_by_frame(store, tmp_path):
    from support import run_outcore
    frames = frames_of(4, 3)
    rays = np.concatenate([rays_up_at(FAR + 3 * k, 32, seed=k) for k in range(3)])
    np.save(tmp_path / "rays.npy", rays)
    plain, packed = tmp_path / "scene.npz", tmp_path / "scene_compressed.npz"
    arrays = dict(mesh0_vertices=CUBE_VERTICES, mesh0_triangles=CUBE_TRIANGLES.astype(np.int64),
                  instance_mesh=np.zeros(3, np.int32), transforms=frames)
    np.savez(plain, **arrays)
    np.savez_compressed(packed, **arrays)
    hits = {}
    for path in (plain, packed):
        out, stats = tmp_path / f"{path.stem}.hits.npy", tmp_path / f"{path.stem}.json"
        result = run_outcore("trace", store, "--rays", tmp_path / "rays.npy", "-o", out, "--dynamic", path,
                             "--repeat", 4, "--stats-json", stats)
        assert result.returncode == 0, result.stderr
        hits[path] = np.load(out)
        import json
        runs = json.loads(stats.read_text())
        assert [r["dynamic"]["version"] for r in runs] == [4, 5, 6, 7]  # a mesh, 3 instances, then 3 frames
        assert all(r["dynamic"]["instances"] == 3 for r in runs)
    assert hits[plain].tobytes() == hits[packed].tobytes()
    # The last batch saw frame 3: the same as a server given the same changes.
    server = Server(store)
    try:
        with outcore.SceneClient(server.address, timeout=60) as client:
            mesh = client.add_mesh(CUBE_VERTICES, CUBE_TRIANGLES)
            ids = [client.add_instance(mesh, frames[0, k]) for k in range(3)]
            client.update_transforms(ids, frames[3])
            ans = client.cast_rays(rays)
    finally:
        assert server.stop() == 0
    got = hits[plain]
    assert got["t_hit"].tobytes() == ans["t_hit"].tobytes()
    assert got["geometry_id"].tobytes() == ans["geometry_ids"].tobytes()
    assert got["primitive_id"].tobytes() == ans["primitive_ids"].tobytes()
    assert np.allclose(got["t_hit"], 11.5, rtol=1e-6, atol=0)


def test_trace_dynamic_file_errors_name_the_file_and_array(store, tmp_path):
    from test_auto import run_failing
    rays = rays_up_at(FAR)
    np.save(tmp_path / "rays.npy", rays)

    def fails(name, words, **arrays):
        path = tmp_path / f"{name}.npz"
        np.savez(path, **arrays)
        result = run_failing("trace", store, "--rays", tmp_path / "rays.npy", "-o", tmp_path / "h.npy",
                             "--dynamic", path, "--repeat", 3)
        assert str(path) in result.stderr and words in result.stderr, result.stderr
        assert not (tmp_path / "h.npy").exists()
        return path

    good = dict(mesh0_vertices=CUBE_VERTICES, mesh0_triangles=CUBE_TRIANGLES, instance_mesh=np.zeros(1, np.int64),
                transforms=frames_of(3, 1))
    fails("no_mesh", "no meshes", instance_mesh=good["instance_mesh"], transforms=good["transforms"])
    fails("unknown", "unknown array 'colours'", colours=np.zeros(3), **good)
    fails("bad_mesh", "instance 0 names mesh 4", **{**good, "instance_mesh": np.array([4])})
    fails("shape", "array transforms has shape (3, 1, 4, 3)", **{**good, "transforms": np.zeros((3, 1, 4, 3))})
    fails("float_index", "mesh0_triangles must be an integer array",
          **{**good, "mesh0_triangles": CUBE_TRIANGLES.astype(np.float32)})
    nan = frames_of(3, 1)
    nan[2, 0, 0, 0] = np.nan
    fails("nan_frame", "frame 2", **{**good, "transforms": nan})
    path = tmp_path / "broken.npz"
    np.savez(path, **good)
    whole = path.read_bytes()
    path.write_bytes(whole[: len(whole) // 2])
    result = run_failing("trace", store, "--rays", tmp_path / "rays.npy", "-o", tmp_path / "h.npy", "--dynamic", path)
    assert str(path) in result.stderr and "ZIP" in result.stderr, result.stderr
    corrupt = bytearray(whole)
    corrupt[200] ^= 0xFF  # inside the first member's data
    path.write_bytes(bytes(corrupt))
    result = run_failing("trace", store, "--rays", tmp_path / "rays.npy", "-o", tmp_path / "h.npy", "--dynamic", path)
    assert str(path) in result.stderr and "CRC-32 mismatch" in result.stderr, result.stderr


def test_a_bkd_top_level_server_answers_as_the_bvh_one(store):
    answers = []
    for top in ("bvh", "bkd"):
        server = Server(store, "--dynamic-top", top)
        try:
            with outcore.SceneClient(server.address, timeout=60) as client:
                mesh = client.add_mesh(CUBE_VERTICES, CUBE_TRIANGLES)
                ids = [client.add_instance(mesh, placed_at(FAR + 2 * k, y=0.3 * k)) for k in range(20)]
                rng = np.random.default_rng(3)
                for frame in range(5):
                    t = np.stack([placed_at(FAR + 2 * k + rng.uniform(-1, 1), y=0.3 * k) for k in range(20)])
                    client.update_transforms(ids, t)
                rays = np.concatenate([rays_up_at(FAR + 2 * k, 16, seed=k) for k in range(20)])
                answers.append(client.cast_rays(rays))
        finally:
            assert server.stop() == 0
    for key in ("t_hit", "geometry_ids", "primitive_ids", "primitive_normals"):
        assert answers[0][key].tobytes() == answers[1][key].tobytes(), key
    assert np.any(answers[0]["primitive_ids"] != outcore.INVALID_ID)
    from test_auto import run_failing
    result = run_failing("serve", store, "--listen", "127.0.0.1:0", "--dynamic-top", "octree")
    assert "--dynamic-top must be bvh or bkd, got 'octree'" in result.stderr
