"""outcore.SceneClient end to end against real `outcore serve` processes:
results equal `outcore trace` bit for bit (unary and streamed batches), input
handling, errors, scene info and stats."""


import numpy as np
import pytest

import outcore
from support import SPHERE, Server, make_rays, trace, trace_stats

HIT_KEYS = ("t_hit", "geometry_ids", "primitive_ids", "primitive_uvs", "primitive_normals")


def bits(a):
    return np.asarray(a).view(np.uint32)


def assert_equals_trace_bitwise(result, reference):
    assert set(result) == set(HIT_KEYS)
    assert np.array_equal(bits(result["t_hit"]), bits(reference["t_hit"]))
    assert np.array_equal(result["geometry_ids"], reference["geometry_id"])
    assert np.array_equal(result["primitive_ids"], reference["primitive_id"])
    assert np.array_equal(bits(result["primitive_uvs"][:, 0]), bits(reference["u"]))
    assert np.array_equal(bits(result["primitive_uvs"][:, 1]), bits(reference["v"]))
    assert np.array_equal(bits(result["primitive_normals"]), bits(reference["ng"]))


@pytest.fixture
def client(server):
    with outcore.SceneClient(server.address, timeout=60) as c:
        yield c


@pytest.mark.parametrize("columns", [6, 8])
def test_cast_rays_equals_trace_bitwise(client, store, bounds, tmp_path, columns):
    rays = make_rays(bounds, 3000, seed=columns, columns=columns)
    result = client.cast_rays(rays)
    reference = trace(store, rays, tmp_path)
    assert_equals_trace_bitwise(result, reference)
    hit = np.isfinite(result["t_hit"])
    assert 0.1 < hit.mean() < 0.9, "rays should mix hits and misses"
    assert set(np.unique(result["geometry_ids"][hit])) == {0, 1}  # the sphere and the bunny
    assert np.all(result["primitive_ids"][~hit] == outcore.INVALID_ID)
    assert np.all(result["geometry_ids"][~hit] == outcore.INVALID_ID)
    assert client.last_stats["rays"] == len(rays)


def test_result_dtypes_shapes_and_read_only_views(client, bounds):
    result = client.cast_rays(make_rays(bounds, 100, seed=3))
    expected = {
        "t_hit": (np.float32, (100,)),
        "geometry_ids": (np.uint32, (100,)),
        "primitive_ids": (np.uint32, (100,)),
        "primitive_uvs": (np.float32, (100, 2)),
        "primitive_normals": (np.float32, (100, 3)),
    }
    for key, (dtype, shape) in expected.items():
        assert result[key].dtype == dtype, key
        assert result[key].shape == shape, key
        # Zero-copy: views of one reply buffer, hence read-only.
        assert not result[key].flags.writeable, key
        assert result[key].base is not None, key
    writable = np.array(result["t_hit"])
    writable[:] = 0  # a copy is an ordinary array


def test_streamed_batch_equals_trace_bitwise(small_server, store, bounds, tmp_path):
    # 1 MiB messages hold ~32k hits: this batch needs 5 chunks.
    rays = make_rays(bounds, 150_000, seed=11, columns=8)
    # Bytes only: shared memory would take it as one unary call (test_shared.py).
    with outcore.SceneClient(small_server.address, timeout=120, shared_memory=False) as client:
        assert client.scene_info()["max_message_bytes"] == 1 << 20
        requests_before = client.stats()["requests"]
        result = client.cast_rays(rays)
        requests = client.stats()["requests"] - requests_before
        occluded = client.test_occlusions(rays)
    assert requests >= 5, "the batch should have gone as several stream chunks"
    assert_equals_trace_bitwise(result, trace(store, rays, tmp_path))
    assert np.array_equal(occluded, trace(store, rays, tmp_path, any_hit=True))
    assert client.last_stats["rays"] == len(rays)


def test_explicit_chunk_rays_streams_and_keeps_order(server, store, bounds, tmp_path):
    rays = make_rays(bounds, 5000, seed=12)
    with outcore.SceneClient(server.address, timeout=60, chunk_rays=777) as client:
        before = client.stats()["requests"]
        result = client.cast_rays(rays)
        occluded = client.test_occlusions(rays)
        after = client.stats()["requests"]
    assert after - before == 2 * 7  # ceil(5000 / 777) chunks per query
    assert_equals_trace_bitwise(result, trace(store, rays, tmp_path))
    assert np.array_equal(occluded, trace(store, rays, tmp_path, any_hit=True))


def test_large_batch_streams_by_default_in_order_and_equals_trace_bitwise(server, store, bounds, tmp_path):
    # Fits one 64 MiB message, but batches of > 262,144 rays stream in
    # 65,536-ray chunks (the server may trace queued chunks together).
    rays = make_rays(bounds, 300_001, seed=21)
    with outcore.SceneClient(server.address, timeout=120, shared_memory=False) as client:
        before = client.stats()["requests"]
        result = client.cast_rays(rays)
        after = client.stats()["requests"]
    assert after - before == 5  # ceil(300,001 / 65,536) chunks
    assert_equals_trace_bitwise(result, trace(store, rays, tmp_path))
    assert client.last_stats["rays"] == len(rays)
    assert client.last_stats["rays_hit"] == int(np.isfinite(result["t_hit"]).sum())


def test_batch_many_times_the_max_message_streams_with_any_ray_layout(small_server, store, bounds, tmp_path):
    # 330 k rays against 1 MiB messages: 11 chunks of 32,256 rays for the hits
    # (32 bytes each), 8 of 43,008 for occlusion (the 24-byte rays limit).
    rays = make_rays(bounds, 330_000, seed=22, columns=6)
    with outcore.SceneClient(small_server.address, timeout=120, shared_memory=False) as client:
        before = client.stats()["requests"]
        result = client.cast_rays(rays)
        occluded = client.test_occlusions(rays)
        requests = client.stats()["requests"] - before
    assert requests == 11 + 8
    assert_equals_trace_bitwise(result, trace(store, rays, tmp_path))
    assert np.array_equal(occluded, trace(store, rays, tmp_path, any_hit=True))


def test_oversize_unary_message_is_resource_exhausted_and_server_keeps_serving(small_server, bounds):
    rays = make_rays(bounds, 60_000, seed=13)  # ~1.9 MiB of hits in one reply
    with outcore.SceneClient(small_server.address, timeout=60, chunk_rays=len(rays)) as client:
        with pytest.raises(outcore.OutcoreError) as error:
            client.cast_rays(rays)
        assert error.value.code == "RESOURCE_EXHAUSTED"
        assert client.cast_rays(rays[:10])["t_hit"].shape == (10,)


@pytest.mark.parametrize("columns", [6, 8])
def test_occlusions_equal_trace_any_hit(client, store, bounds, tmp_path, columns):
    rays = make_rays(bounds, 3000, seed=20 + columns, columns=columns)
    occluded = client.test_occlusions(rays)
    assert occluded.dtype == np.bool_ and occluded.shape == (3000,)
    assert np.array_equal(occluded, trace(store, rays, tmp_path, any_hit=True))
    # Consistent with the closest hit where both apply.
    assert np.array_equal(occluded, np.isfinite(client.cast_rays(rays)["t_hit"]))


def test_six_columns_mean_default_tnear_and_tfar(client, bounds):
    rays6 = make_rays(bounds, 2000, seed=30)
    rays8 = np.concatenate(
        [rays6, np.zeros((2000, 1), np.float32), np.full((2000, 1), np.inf, np.float32)], axis=1
    )
    a, b = client.cast_rays(rays6), client.cast_rays(rays8)
    for key in HIT_KEYS:
        assert np.array_equal(bits(a[key]), bits(b[key])), key
    assert np.array_equal(client.test_occlusions(rays6), client.test_occlusions(rays8))


def test_float64_and_non_contiguous_input_is_converted(client, bounds):
    rays = make_rays(bounds, 1000, seed=40)
    reference = client.cast_rays(rays)
    as_float64 = rays.astype(np.float64)
    strided = np.zeros((1000, 12), np.float32)[:, ::2]
    strided[:] = rays
    fortran = np.asfortranarray(rays)
    for variant in (as_float64, strided, fortran, rays.tolist()):
        result = client.cast_rays(variant)
        for key in HIT_KEYS:
            assert np.array_equal(bits(result[key]), bits(reference[key])), key


def test_leading_batch_dims_give_results_of_the_same_shape(client, bounds):
    rays = make_rays(bounds, 12 * 10, seed=50, columns=8)
    flat = client.cast_rays(rays)
    image = client.cast_rays(rays.reshape(12, 10, 8))
    assert image["t_hit"].shape == (12, 10)
    assert image["geometry_ids"].shape == (12, 10)
    assert image["primitive_ids"].shape == (12, 10)
    assert image["primitive_uvs"].shape == (12, 10, 2)
    assert image["primitive_normals"].shape == (12, 10, 3)
    for key in HIT_KEYS:
        assert np.array_equal(bits(image[key]).reshape(bits(flat[key]).shape), bits(flat[key])), key
    occluded = client.test_occlusions(rays.reshape(2, 6, 10, 8))
    assert occluded.shape == (2, 6, 10)
    assert np.array_equal(occluded.reshape(-1), client.test_occlusions(rays))


def test_empty_batch_needs_no_call():
    # Nothing listens here: an empty batch must not even try.
    with outcore.SceneClient("127.0.0.1:1", timeout=5) as client:
        result = client.cast_rays(np.zeros((0, 6), np.float32))
        assert result["t_hit"].shape == (0,) and result["primitive_uvs"].shape == (0, 2)
        assert client.test_occlusions(np.zeros((0, 4, 8), np.float32)).shape == (0, 4)


@pytest.mark.parametrize(
    "rays", [np.zeros((4, 7), np.float32), np.zeros(6, np.float32), np.zeros((4, 6), np.complex64),
             np.array([["x"] * 6])]
)
def test_wrong_rays_are_a_value_error(client, rays):
    with pytest.raises(ValueError, match="rays must"):
        client.cast_rays(rays)
    with pytest.raises(ValueError, match="rays must"):
        client.test_occlusions(rays)


def test_strict_nan_ray_is_an_error_naming_its_index(client, bounds):
    rays = make_rays(bounds, 50, seed=60)
    rays[37, 4] = np.nan
    with pytest.raises(outcore.OutcoreError) as error:
        client.cast_rays(rays, strict=True)
    assert isinstance(error.value, RuntimeError)
    assert error.value.code == "INVALID_ARGUMENT"
    assert "ray 37" in str(error.value)
    with pytest.raises(outcore.OutcoreError, match="ray 37"):
        client.test_occlusions(rays, strict=True)
    # Not strict: the bad ray is a miss and the others are answered.
    result = client.cast_rays(rays)
    assert result["t_hit"][37] == np.inf and result["primitive_ids"][37] == outcore.INVALID_ID
    assert client.last_stats["invalid_rays"] == 1


def test_strict_nan_ray_in_a_later_stream_chunk_is_named_by_its_batch_index(server, bounds):
    rays = make_rays(bounds, 3000, seed=61)
    rays[2345, 0] = np.inf
    with outcore.SceneClient(server.address, timeout=60, chunk_rays=1000) as client:
        with pytest.raises(outcore.OutcoreError, match="ray 2345") as error:
            client.cast_rays(rays, strict=True)
        assert error.value.code == "INVALID_ARGUMENT"
        assert client.cast_rays(rays[:5])["t_hit"].shape == (5,)  # still serving


def test_scene_info_describes_the_store(client, store):
    info = client.scene_info()
    assert info["store_path"].rstrip("/").endswith(store.name)
    assert info["inputs"][0]["spec"] == SPHERE
    assert info["inputs"][1]["spec"].endswith("stanford-bunny.obj")
    assert info["triangle_count"] == sum(i["triangle_count"] for i in info["inputs"])
    assert info["brick_count"] > 1
    assert len(info["bounds_lo"]) == 3 and len(info["bounds_hi"]) == 3
    assert all(lo < hi for lo, hi in zip(info["bounds_lo"], info["bounds_hi"]))
    assert info["max_message_bytes"] == 64 << 20
    assert info["cache_budget_bytes"] > 0
    assert isinstance(info["server_version"], str) and info["server_version"]


def test_stats_count_the_rays_answered(client, bounds):
    rays = make_rays(bounds, 1234, seed=70)
    before = client.stats()
    hits = np.isfinite(client.cast_rays(rays)["t_hit"]).sum()
    after = client.stats()
    # Other tests share this server, but none runs concurrently with this one.
    assert after["rays"] - before["rays"] == 1234
    assert after["rays_hit"] - before["rays_hit"] == hits
    assert after["requests"] - before["requests"] == 1
    assert after["cache_hits"] + after["cache_misses"] >= before["cache_hits"] + before["cache_misses"]
    assert after["resident_bytes"] <= after["cache_budget_bytes"]
    assert after["eviction_policy"]
    # The per-request sums grow by this request's figures.
    for key in REQUEST_SUMS:
        assert after[key] - before[key] == client.last_stats[key], key
    assert after["proxy_bytes"] > 0  # proxies are on by default
    # No subtree tier on this server.
    assert after["subtree_dir"] == ""
    for key in SUBTREE_COUNTS:
        assert after[key] == 0, key
    assert after["subtree_load_seconds"] == 0
    assert after["subtree_write_seconds"] == 0


SUBTREE_COUNTS = ("subtree_loads", "subtree_loads_checked", "subtree_loads_kept", "subtree_loads_recycled", "subtree_writes", "subtree_rejects", "subtree_bytes_read",
                  "subtree_bytes_written", "subtree_files", "subtree_file_bytes", "subtree_write_failures",
                  "subtree_writes_too_large", "subtree_files_evicted")
# What the engine counts per request (beyond rays and cache counters), in
# last_stats as in `outcore trace --stats-json`.
ENGINE_COUNTS = ("rays", "rays_hit", "invalid_rays", "upper_nodes_visited", "brick_visits", "proxy_tests",
                 "bricks_skipped_by_proxy", "rays_traced_ahead", "brick_acquisitions", "cache_hits",
                 "cache_misses", "brick_builds", "evictions", "subtree_loads", "subtree_writes",
                 "rays_in_brick_set", "brick_visits_without_hit", "bricks_skipped_by_bound")
# The per-request sums ServerStats keeps.
REQUEST_SUMS = ("brick_visits", "brick_visits_without_hit", "proxy_tests", "bricks_skipped_by_proxy",
                "bricks_skipped_by_bound", "rays_traced_ahead")


def test_last_stats_equal_traces_for_the_same_rays_on_a_fresh_cache(store, bounds, tmp_path):
    # One engine thread each: the split of candidates into visits and proxy
    # skips can change with the thread count (their sum and the answers cannot).
    rays = make_rays(bounds, 3000, seed=71)
    server = Server(store, "--threads", 1)
    try:
        with outcore.SceneClient(server.address, timeout=60) as client:
            client.cast_rays(rays)
            got = client.last_stats
            totals = client.stats()
    finally:
        assert server.stop() == 0
    want = trace_stats(store, rays, tmp_path, "--threads", 1)
    assert {key: got[key] for key in ENGINE_COUNTS} == {key: want[key] for key in ENGINE_COUNTS}
    # The budget holds the scene: the proxies are asked when a brick is to be
    # built (passed over only when no queued ray may hit it), so tests, maybe
    # no skips.
    assert got["proxy_tests"] > 0 and got["proxy_tests"] >= got["bricks_skipped_by_proxy"]
    assert 0 < got["seconds_upper"] <= got["seconds_total"]
    assert totals["proxy_bytes"] == want["proxy_bytes"]
    for key in REQUEST_SUMS:
        assert totals[key] == got[key], key


@pytest.mark.parametrize("bound", ["sphere", "obb"])
def test_brick_bounds_answer_as_trace_and_count_what_they_turn_away(store, bounds, tmp_path, bound):
    # serve --brick-bounds: the same answers as trace without a bound, and the
    # same figures as trace with it (one engine thread each, fresh caches).
    rays = make_rays(bounds, 3000, seed=72)
    server = Server(store, "--threads", 1, "--brick-bounds", bound)
    try:
        with outcore.SceneClient(server.address, timeout=60) as client:
            result = client.cast_rays(rays)
            got = client.last_stats
            totals = client.stats()
    finally:
        assert server.stop() == 0
    assert_equals_trace_bitwise(result, trace(store, rays, tmp_path))
    want = trace_stats(store, rays, tmp_path, "--threads", 1, "--brick-bounds", bound)
    assert {key: got[key] for key in ENGINE_COUNTS} == {key: want[key] for key in ENGINE_COUNTS}
    assert got["bricks_skipped_by_bound"] > 0
    assert 0 < got["brick_visits_without_hit"] <= got["brick_visits"]
    for key in REQUEST_SUMS:
        assert totals[key] == got[key], key


def test_streamed_last_stats_add_up_to_the_servers(small_server, bounds):
    # Chunks the server traced together carry the call's figures in the last
    # reply only, so the client's sums over the replies are exact.
    rays = make_rays(bounds, 100_000, seed=72)
    with outcore.SceneClient(small_server.address, timeout=60, shared_memory=False) as client:
        before = client.stats()
        client.cast_rays(rays)
        after = client.stats()
        stats = client.last_stats
    assert stats["rays"] == len(rays)
    assert after["requests"] - before["requests"] > 1, "the batch should have been streamed"
    for key in ("rays", "brick_visits", "proxy_tests", "bricks_skipped_by_proxy", "rays_traced_ahead"):
        assert after[key] - before[key] == stats[key], key


def test_subtree_tier_loads_and_writes_are_in_stats(store, bounds, tmp_path):
    # bvh bricks of ~4k triangles are ~0.5 MiB each, the store's several MiB:
    # a 2 MiB budget evicts, and the second batch loads from the tier.
    tier = tmp_path / "subtrees"
    rays = make_rays(bounds, 3000, seed=73)
    server = Server(store, "--brick-accel", "bvh", "--cache-mb", 2, "--subtree-dir", tier)
    try:
        with outcore.SceneClient(server.address, timeout=60) as client:
            first = client.cast_rays(rays)
            first_stats = client.last_stats
            second = client.cast_rays(rays)
            second_stats = client.last_stats
            stats = client.stats()
            info = client.scene_info()
    finally:
        assert server.stop() == 0
    assert np.array_equal(first["t_hit"], second["t_hit"], equal_nan=True)
    assert stats["subtree_dir"] == str(tier)
    assert stats["evictions"] > 0, "the budget held the scene: nothing to reload"
    assert 0 < stats["subtree_writes"] == stats["brick_builds"] <= info["brick_count"]
    assert stats["subtree_loads"] > 0
    assert stats["subtree_rejects"] == 0
    assert stats["subtree_bytes_written"] > 0 and stats["subtree_bytes_read"] > 0
    assert stats["subtree_load_seconds"] >= 0
    assert stats["subtree_files"] == stats["subtree_writes"]
    assert stats["subtree_file_bytes"] == stats["subtree_bytes_written"]
    assert len(list(tier.glob("*.subtree"))) == stats["subtree_files"]
    for key in ("subtree_loads", "subtree_writes", "subtree_bytes_read", "subtree_bytes_written"):
        assert first_stats[key] + second_stats[key] == stats[key], key
    assert second_stats["subtree_loads"] > 0


@pytest.mark.parametrize("chunk_rays", [200_000, 20_000], ids=["unary", "streamed"])
def test_deadline_exceeded_is_named_and_server_stays_healthy(server, bounds, chunk_rays):
    rays = make_rays(bounds, 200_000, seed=80)
    with outcore.SceneClient(server.address, timeout=1e-4, chunk_rays=chunk_rays) as client:
        with pytest.raises(outcore.OutcoreError) as error:
            client.cast_rays(rays)
        assert error.value.code == "DEADLINE_EXCEEDED"
        assert "DEADLINE_EXCEEDED" in str(error.value)
    with outcore.SceneClient(server.address, timeout=60) as client:
        assert client.cast_rays(rays[:10])["t_hit"].shape == (10,)


def test_unreachable_server_is_unavailable():
    with outcore.SceneClient("127.0.0.1:1", timeout=5) as client:
        with pytest.raises(outcore.OutcoreError) as error:
            client.scene_info()
        assert error.value.code == "UNAVAILABLE"


@pytest.mark.parametrize(
    "kwargs",
    [dict(address=""), dict(timeout=0), dict(timeout=-1), dict(max_message_mb=0), dict(chunk_rays=0),
     dict(chunk_rays=2.5), dict(shared_memory=1), dict(shared_memory=None), dict(shared_memory="yes")],
)
def test_bad_client_options_are_a_value_error(kwargs):
    args = dict(address="127.0.0.1:1") | kwargs
    with pytest.raises(ValueError):
        outcore.SceneClient(**args)


def test_sigterm_drains_and_exits_zero(store):
    server = Server(store)
    with outcore.SceneClient(server.address, timeout=30) as client:
        assert client.scene_info()["triangle_count"] > 0
    assert server.stop() == 0
