"""Replicas with cache-affinity routing (issue 30), on loopback: three real
`outcore serve` processes over one store, each with a cache budget at most a
quarter of the scene's built size. A SceneClient given their addresses
either shares the bricks out (routing="bricks", the default: every replica
traces every ray in its own bricks, the nearest answer kept) or splits each
batch by routing key (routing="rays": parts in parallel, answers put back in
input order); either way bitwise the answers of one server, with every hit
field; each brick is built on one replica only (bricks); a replica killed
before or during a batch costs nothing but time; adding a replica moves few
keys; a "dns:" target is resolved into replicas."""

from __future__ import annotations

import signal
import threading

import numpy as np
import pytest

import outcore
from outcore import _routing
from support import Server, run_outcore

BUDGET_MB = 2  # the city below builds to ~10.7 MiB: more than 4x the budget


@pytest.fixture(scope="module")
def city(tmp_path_factory):
    path = tmp_path_factory.mktemp("replicas") / "city.oc"
    run_outcore("pack", "gen:city", "-o", path, "--brick-tris", 8192, "-q")
    return path


@pytest.fixture(scope="module")
def rays():
    rng = np.random.default_rng(30)
    n = 120_000
    origins = rng.standard_normal((n, 3))
    origins *= 80 / np.linalg.norm(origins, axis=1, keepdims=True)
    targets = rng.uniform(-40, 40, (n, 3))
    targets[:, 1] = rng.uniform(-1.5, 1.5, n)
    return np.ascontiguousarray(np.concatenate([origins, targets - origins], axis=1), dtype=np.float32)


def _start(city, count):
    return [Server(city, "--cache-mb", BUDGET_MB) for _ in range(count)]


def _stop(servers):
    for server in servers:
        if server.process.poll() is None:
            assert server.stop() == 0, "".join(server.lines)


@pytest.fixture(scope="module")
def reference(city, rays):
    [server] = _start(city, 1)
    try:
        with outcore.SceneClient(server.address, timeout=120) as client:
            return client.cast_rays(rays), client.test_occlusions(rays)
    finally:
        _stop([server])


@pytest.fixture(scope="module")
def replicas(city):
    servers = _start(city, 3)
    yield servers
    _stop(servers)


def _same_hits(a, b):
    np.testing.assert_array_equal(a["t_hit"].view(np.uint32), b["t_hit"].view(np.uint32))
    np.testing.assert_array_equal(a["primitive_ids"], b["primitive_ids"])
    np.testing.assert_array_equal(a["geometry_ids"], b["geometry_ids"])


def test_parts_by_brick_answer_bitwise_as_one_server_with_every_hit_field(replicas, rays, reference):
    addresses = [s.address for s in replicas]
    with outcore.SceneClient(addresses, timeout=120) as client:
        assert client.replicas() == sorted(addresses)
        hits = client.cast_rays(rays)
        assert client.last_replicas == 3
        # Every replica traced every ray; the batch's counts are its own.
        assert client.last_stats["rays"] == len(rays)
        assert client.last_stats["rays_hit"] == np.count_nonzero(np.isfinite(reference[0]["t_hit"]))
        _same_hits(hits, reference[0])
        for name in ("primitive_uvs", "primitive_normals"):
            np.testing.assert_array_equal(hits[name].view(np.uint32), reference[0][name].view(np.uint32))
        np.testing.assert_array_equal(client.test_occlusions(rays), reference[1])
        short = client.cast_rays(rays, hit_fields="t_ids")
        _same_hits(short, reference[0])
        t_only = client.cast_rays(rays, hit_fields="t")
        np.testing.assert_array_equal(t_only["t_hit"].view(np.uint32), reference[0]["t_hit"].view(np.uint32))
        # Streamed in chunks, each chunk naming the replica's bricks.
        with outcore.SceneClient(addresses, timeout=120, chunk_rays=20_000, shared_memory=False) as chunked:
            _same_hits(chunked.cast_rays(rays), reference[0])
        parts = client._router.plan_bricks()
        bricks = client.scene_info()["bricks"]
    owned = sorted(b for part in parts.values() for b in part)
    assert owned == list(range(len(bricks)))  # every brick on exactly one replica
    triangles = [sum(bricks[b]["triangle_count"] for b in part) for part in parts.values()]
    largest = max(b["triangle_count"] for b in bricks)
    # Over the bound by at most one brick (one that fits nowhere goes to the least loaded).
    assert max(triangles) <= np.ceil(1.01 * sum(triangles) / 3) + largest, triangles
    assert len(parts) == 3


def test_by_brick_each_brick_is_built_on_one_replica_only(city, rays):
    # Budgets that hold the scene: builds show where each brick went.
    servers = [Server(city, "--cache-mb", 256) for _ in range(3)]
    try:
        with outcore.SceneClient([s.address for s in servers], timeout=120) as client:
            client.cast_rays(rays)
            client.cast_rays(rays[::-1].copy())
            bricks = client.scene_info()["brick_count"]
            parts = client._router.plan_bricks()
            builds = {s.address: outcore.SceneClient(s.address).stats()["brick_builds"] for s in servers}
        for address, part in parts.items():
            assert builds[address] <= len(part), (builds, {a: len(p) for a, p in parts.items()})
        assert sum(builds.values()) <= bricks
    finally:
        _stop(servers)


def test_replicas_that_list_no_bricks_are_routed_by_ray(replicas, rays, reference):
    # As servers from before SceneInfo.bricks answer: the client routes by ray.
    with outcore.SceneClient([s.address for s in replicas], timeout=120) as client:
        client._router._bounds = tuple(client.scene_info()[k] for k in ("bounds_lo", "bounds_hi"))
        client._router._bricks = []
        assert client._router.plan_bricks() == {}
        _same_hits(client.cast_rays(rays), reference[0])
        assert client.last_stats["rays"] == len(rays)


def test_a_part_names_bricks_of_the_scene(replicas, rays):
    from outcore.client import _INTERSECT, _QueryOptions
    with outcore.SceneClient(replicas[0].address, timeout=30) as client:
        bricks = client.scene_info()["brick_count"]
        with pytest.raises(outcore.OutcoreError, match=f"brick {bricks} is not in the scene") as e:
            client._query(_INTERSECT, rays[:10], _QueryOptions(False, None, (0, bricks)))
        assert e.value.code == "INVALID_ARGUMENT"


def test_a_stream_keeps_one_part_and_every_hit_calls_take_none(replicas, rays):
    import grpc
    from outcore import _wire
    with grpc.insecure_channel(replicas[0].address) as channel:
        chunks = [_wire.encode_query(rays[:10], only_bricks=[0, 1]),
                  _wire.encode_query(rays[10:20], sequence=1, only_bricks=[0, 2])]
        replies = channel.stream_stream("/outcore.v1.SceneQuery/IntersectStream")(iter(chunks), timeout=30)
        with pytest.raises(grpc.RpcError) as error:
            list(replies)
        assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
        assert "names other only_bricks than the stream's first chunk" in error.value.details()
        for method in ("CountIntersections", "ListIntersections"):
            with pytest.raises(grpc.RpcError) as error:
                channel.unary_unary(f"/outcore.v1.SceneQuery/{method}")(
                    _wire.encode_query(rays[:10], only_bricks=[0]), timeout=30)
            assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT
            assert "only_bricks is for closest-hit and any-hit queries" in error.value.details()


def test_routed_by_ray_answers_are_one_servers_bitwise_and_spread_within_the_bound(replicas, rays, reference):
    addresses = [s.address for s in replicas]
    with outcore.SceneClient(addresses, timeout=120, routing="rays") as client:
        assert client.replicas() == sorted(addresses)
        hits = client.cast_rays(rays)
        assert client.last_replicas == 3
        assert client.last_stats["rays"] == len(rays)
        occluded = client.test_occlusions(rays)
        # The bound: no replica above 1.25x the average, unless one key is larger.
        ring, replica_of_ray, _ = client._router.plan(rays)
    _same_hits(hits, reference[0])
    np.testing.assert_array_equal(occluded, reference[1])
    loads = np.bincount(replica_of_ray, minlength=3)
    keys = _routing.ray_keys(rays, *client._router._bounds, cells=client._router.cells)
    largest_key = np.unique(keys, return_counts=True)[1].max()
    assert loads.max() <= max(np.ceil(1.25 * len(rays) / 3), largest_key), loads
    assert (loads > 0).all()


def test_the_same_key_goes_to_the_same_replica_every_batch(replicas, rays):
    with outcore.SceneClient([s.address for s in replicas], timeout=120, routing="rays") as client:
        _, first, _ = client._router.plan(rays)
        _, again, _ = client._router.plan(rays)
        _, half, _ = client._router.plan(rays[: len(rays) // 2])
    np.testing.assert_array_equal(first, again)
    # Another batch of the same region keeps most rays where they were.
    assert np.mean(half == first[: len(rays) // 2]) > 0.6


@pytest.mark.parametrize("routing", ["bricks", "rays"])
def test_a_replica_down_before_or_during_a_batch_changes_no_answer(city, rays, reference, routing):
    servers = _start(city, 3)
    try:
        addresses = [s.address for s in servers]
        servers[0].process.send_signal(signal.SIGKILL)
        servers[0].process.wait(30)
        with outcore.SceneClient(addresses, timeout=120, routing=routing) as client:
            _same_hits(client.cast_rays(rays), reference[0])
            assert servers[0].address not in client._router._live()
        # During: kill a second replica while a batch is in flight.
        with outcore.SceneClient(addresses[1:], timeout=120, routing=routing) as client:
            client.cast_rays(rays[:1000])  # connected
            killer = threading.Timer(0.02, lambda: servers[1].process.send_signal(signal.SIGKILL))
            killer.start()
            big = np.concatenate([rays] * 4)
            hits = client.cast_rays(big)
            killer.join()
            assert client._router.failovers >= 1  # the killed replica's part was sent again
            for k in range(4):
                _same_hits({key: value[k * len(rays):(k + 1) * len(rays)] for key, value in hits.items()},
                           reference[0])
            # Only the last replica is left; a batch still completes.
            _same_hits(client.cast_rays(rays), reference[0])
    finally:
        _stop(servers)


def test_adding_a_replica_moves_few_bricks(replicas):
    with outcore.SceneClient([s.address for s in replicas], timeout=120) as client:
        info = client.scene_info()
    # The 400-copy city's bricks are too few for shares to mean much: its
    # bricks' boxes, repeated 8 x 8 over a larger ground, stand in for a
    # large scene's.
    bricks = []
    for i in range(8):
        for j in range(8):
            for b in info["bricks"]:
                shift = np.array([i * 100.0, 0, j * 100.0])
                bricks.append({"bounds_lo": list(np.asarray(b["bounds_lo"]) + shift),
                               "bounds_hi": list(np.asarray(b["bounds_hi"]) + shift),
                               "triangle_count": b["triangle_count"]})
    lo = np.min([b["bounds_lo"] for b in bricks], axis=0)
    hi = np.max([b["bounds_hi"] for b in bricks], axis=0)
    positions = _routing.brick_positions(bricks, lo, hi)
    assert len(set(int(p) for p in positions)) == len(bricks)
    load = {int(p): b["triangle_count"] for p, b in zip(positions, bricks)}
    nodes = _routing.BRICK_VIRTUAL_NODES
    three = _routing.HashRing(["a:1", "b:1", "c:1"], nodes).assign(load, _routing.BRICK_LOAD_FACTOR)
    four = _routing.HashRing(["a:1", "b:1", "c:1", "d:1"], nodes).assign(load, _routing.BRICK_LOAD_FACTOR)
    moved = sum(load[k] for k in load if three[k] != four[k]) / sum(load.values())
    # The new replica's fair share is a quarter of the triangles.
    assert 0.2 < moved < 0.45, moved


def test_adding_a_replica_moves_few_keys(replicas, rays):
    with outcore.SceneClient([s.address for s in replicas], timeout=120, routing="rays") as client:
        client._router.plan(rays[:10])
        keys = _routing.ray_keys(rays, *client._router._bounds, cells=client._router.cells)
    unique, counts = np.unique(keys, return_counts=True)
    load = {int(k): int(c) for k, c in zip(unique, counts)}
    three = _routing.HashRing(["a:1", "b:1", "c:1"]).assign(load)
    four = _routing.HashRing(["a:1", "b:1", "c:1", "d:1"]).assign(load)
    moved_rays = sum(load[k] for k in load if three[k] != four[k]) / sum(load.values())
    # The new replica's fair share is a quarter; bounded load moves a little more.
    assert 0.1 < moved_rays < 0.5, moved_rays


def test_a_dns_target_is_resolved_into_replicas(replicas, rays, reference):
    port = replicas[0].address.rsplit(":", 1)[1]
    with outcore.SceneClient(f"dns:///localhost:{port}", timeout=120) as client:
        assert f"127.0.0.1:{port}" in client.replicas()
        _same_hits(client.cast_rays(rays), reference[0])


def test_replicas_refuse_the_dynamic_layer_and_bad_arguments(replicas):
    with outcore.SceneClient([s.address for s in replicas], timeout=30) as client:
        with pytest.raises(outcore.OutcoreError, match="dynamic layer belongs to one server"):
            client.add_mesh(np.zeros((3, 3), np.float32), np.array([[0, 1, 2]], np.uint32))
        assert client.scene_info()["triangle_count"] == 128000  # other calls: one replica
    with pytest.raises(ValueError, match="replicas"):
        outcore.SceneClient([])
    with pytest.raises(ValueError, match="route_cells"):
        outcore.SceneClient([replicas[0].address], route_cells=0)
    with pytest.raises(ValueError, match="routing"):
        outcore.SceneClient([replicas[0].address], routing="cells")
    with pytest.raises(ValueError, match="load_factor"):
        outcore.SceneClient([replicas[0].address], load_factor=0.9)
    with pytest.raises(outcore.OutcoreError, match="cannot resolve"):
        outcore.SceneClient("dns:///no-such-host.invalid:50051")


def test_ring_walks_and_keys():
    ring = _routing.HashRing(["a:1", "b:1", "c:1"])
    for position in range(0, 2**64, 2**58):
        walk = ring.walk(position)
        assert sorted(walk) == ["a:1", "b:1", "c:1"] and walk == ring.walk(position)
    # A flat box gets a flat grid.
    assert list(_routing.grid_dims([0, 0, 0], [100, 3, 50], 8)) == [8, 1, 4]
    # Keys: ring positions of the entry cell, in Morton order; the same
    # column entered from above or below is one key; misses are hashed.
    rays = np.array([[0.3, 5, 0.3, 0, -1, 0], [0.3, -5, 0.3, 0, 1, 0], [0.9, 5, 0.9, 0, -1, 0],
                     [-5, 5, 5, -1, 0, 0], [0.01, 0.01, 0.01, 1, 0, 0]], np.float32)
    keys = _routing.ray_keys(rays, [0, 0, 0], [1, 0.1, 1], cells=4)
    assert keys[0] == keys[1] != keys[2]
    assert keys[3] not in keys[:3]
    # Morton order: cell (0, 0, 0) is the first slice of the ring, (3, 0, 3) a later one.
    assert keys[4] < keys[0] < keys[2]


@pytest.mark.parametrize("routing", ["bricks", "rays"])
def test_outcore_query_routes_over_a_replica_list(replicas, rays, reference, tmp_path, routing):
    np.save(tmp_path / "rays.npy", rays)
    out = tmp_path / "hits.npy"
    run_outcore("query", "--server", ",".join(s.address for s in replicas), "--rays", tmp_path / "rays.npy",
                "-o", out, "--stats", "--routing", routing)
    hits = np.load(out)
    np.testing.assert_array_equal(hits["t_hit"].view(np.uint32), reference[0]["t_hit"].view(np.uint32))
    np.testing.assert_array_equal(hits["primitive_id"], reference[0]["primitive_ids"])
    np.testing.assert_array_equal(hits["geometry_id"], reference[0]["geometry_ids"])
    # The C++ and Python clients place the same rays on the same replicas.
    with outcore.SceneClient([s.address for s in replicas], timeout=120, routing="rays") as client:
        _, replica_of_ray, names = client._router.plan(rays)
    assert names == sorted(s.address for s in replicas)
    assert np.bincount(replica_of_ray, minlength=3).min() > 0


def test_outcore_query_resolves_a_dns_target_into_replicas(replicas, rays, reference, tmp_path):
    np.save(tmp_path / "rays.npy", rays)
    out = tmp_path / "hits.npy"
    port = replicas[0].address.rsplit(":", 1)[1]
    # localhost may also resolve to ::1, where nothing listens: left out.
    run_outcore("query", "--server", f"dns:///localhost:{port}", "--rays", tmp_path / "rays.npy", "-o", out)
    np.testing.assert_array_equal(np.load(out)["t_hit"].view(np.uint32), reference[0]["t_hit"].view(np.uint32))
