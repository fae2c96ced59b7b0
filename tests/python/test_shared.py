"""Same-host shared-memory payloads (proto SharedPayload, outcore._shared)
against real `outcore serve` processes on loopback: batches of >= 16,384 rays
go through a /dev/shm segment and give exactly the answers of `outcore trace`
and of the bytes path; when the path is not taken; the segment's life (reuse,
growth, removal); concurrent calls; strict errors; and the fallbacks to bytes
when no segment can be made or the server refuses it (FAILED_PRECONDITION).
Every test ends with no segment file of this process left in /dev/shm."""

import gc
import os
import threading

import numpy as np
import pytest

import outcore
from outcore import _shared, _wire
from support import Server, make_rays, trace
from test_client import HIT_KEYS, assert_equals_trace_bitwise, bits

pytestmark = pytest.mark.skipif(not _shared.supported() or not os.path.isdir(_shared.SHM_DIR),
                                reason="shared payloads need Linux and /dev/shm")

N = 20_000  # above the 16,384-ray threshold, small enough to be quick


def our_segments() -> list[str]:
    prefix = f"{_shared.NAME_PREFIX}{os.getpid()}-"
    return sorted(name for name in os.listdir(_shared.SHM_DIR) if name.startswith(prefix))


@pytest.fixture(autouse=True)
def no_segment_left():
    assert our_segments() == [], "a segment was left by an earlier test"
    yield
    gc.collect()
    assert our_segments() == [], "segment files left in /dev/shm"


@pytest.fixture(scope="module")
def refusing_server(store):
    """A server started with --no-shared-payloads."""
    server = Server(store, "--no-shared-payloads")
    yield server
    code = server.stop()
    assert code == 0, f"outcore serve exited {code} on SIGTERM:\n" + "".join(server.lines)


def assert_hits_equal(a, b):
    for key in HIT_KEYS:
        assert np.array_equal(bits(a[key]), bits(b[key])), key


def bytes_answers(address, rays):
    with outcore.SceneClient(address, timeout=60, shared_memory=False) as client:
        hits = client.cast_rays(rays)
        assert not client.last_call_shared
        occluded = client.test_occlusions(rays)
        assert not client.last_call_shared
    return hits, occluded


@pytest.mark.parametrize("columns", [6, 8])
def test_shared_cast_rays_equals_trace_and_the_bytes_path_bitwise(server, store, bounds, tmp_path, columns):
    rays = make_rays(bounds, N, seed=100 + columns, columns=columns)
    with outcore.SceneClient(server.address, timeout=60) as client:
        assert client.scene_info()["shared_payloads"] is True
        result = client.cast_rays(rays)
        assert client.last_call_shared
        assert client.last_stats["rays"] == N
        assert client.last_stats["rays_hit"] == int(np.isfinite(result["t_hit"]).sum())
        assert len(our_segments()) == 1
        # Results are a copy, not a view of the reused segment: another batch
        # through the same segment leaves them as they were.
        kept = {key: np.array(value) for key, value in result.items()}
        client.cast_rays(make_rays(bounds, N, seed=999, columns=columns))
        assert client.last_call_shared
        assert_hits_equal(result, kept)
    assert_equals_trace_bitwise(result, trace(store, rays, tmp_path))
    assert_hits_equal(result, bytes_answers(server.address, rays)[0])
    expected = {"t_hit": np.float32, "geometry_ids": np.uint32, "primitive_ids": np.uint32,
                "primitive_uvs": np.float32, "primitive_normals": np.float32}
    for key, dtype in expected.items():
        assert result[key].dtype == dtype and not result[key].flags.writeable, key
    assert result["primitive_uvs"].shape == (N, 2) and result["primitive_normals"].shape == (N, 3)


def test_copies_in_parts_give_the_same_answers(server, store, bounds, tmp_path, monkeypatch):
    """Large batches' copies into and out of the segment run in parts on a
    thread pool; forced here on a small batch (and an odd byte count)."""
    monkeypatch.setattr(_shared, "_PARALLEL_COPY_BYTES", 4096)
    rays = make_rays(bounds, N + 3, seed=120, columns=6)
    with outcore.SceneClient(server.address, timeout=60) as client:
        result = client.cast_rays(rays)
        assert client.last_call_shared
    assert_equals_trace_bitwise(result, trace(store, rays, tmp_path))
    for size in (4096, 4097, 1_000_003):
        src = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)
        dst = np.zeros(size, dtype=np.uint8)
        _shared.parallel_copy(dst, src)
        assert np.array_equal(dst, src), size


@pytest.mark.parametrize("columns", [6, 8])
def test_shared_occlusions_equal_trace_and_the_bytes_path(server, store, bounds, tmp_path, columns):
    rays = make_rays(bounds, N, seed=110 + columns, columns=columns)
    with outcore.SceneClient(server.address, timeout=60) as client:
        occluded = client.test_occlusions(rays)
        assert client.last_call_shared
        assert client.last_stats["rays"] == N
    assert occluded.dtype == np.bool_ and occluded.shape == (N,) and not occluded.flags.writeable
    assert 0.1 < occluded.mean() < 0.9
    assert np.array_equal(occluded, trace(store, rays, tmp_path, any_hit=True))
    assert np.array_equal(occluded, bytes_answers(server.address, rays)[1])


def test_leading_batch_dims_through_shared_memory(server, bounds):
    rays = make_rays(bounds, 128 * 160, seed=120, columns=8)
    with outcore.SceneClient(server.address, timeout=60) as client:
        flat = client.cast_rays(rays)
        image = client.cast_rays(rays.reshape(128, 160, 8))
        assert client.last_call_shared
        occluded = client.test_occlusions(rays.reshape(128, 160, 8))
        assert client.last_call_shared
    assert image["t_hit"].shape == (128, 160) and image["primitive_uvs"].shape == (128, 160, 2)
    for key in HIT_KEYS:
        assert np.array_equal(bits(image[key]).reshape(bits(flat[key]).shape), bits(flat[key])), key
    assert occluded.shape == (128, 160)
    assert np.array_equal(occluded.reshape(-1), np.isfinite(flat["t_hit"]))


def test_small_batches_chunked_and_opted_out_clients_send_bytes(server, bounds):
    rays = make_rays(bounds, 16_384, seed=130)
    with outcore.SceneClient(server.address, timeout=60) as client:
        below = client.cast_rays(rays[:16_383])
        assert not client.last_call_shared
        assert our_segments() == [], "a batch below the threshold made a segment"
        at = client.cast_rays(rays)
        assert client.last_call_shared
        assert client.test_occlusions(rays[:100]).shape == (100,)
        assert not client.last_call_shared
    with outcore.SceneClient(server.address, timeout=60, chunk_rays=10_000) as client:
        chunked = client.cast_rays(rays)
        assert not client.last_call_shared
    with outcore.SceneClient(server.address, timeout=60, shared_memory=False) as client:
        opted_out = client.cast_rays(rays)
        assert not client.last_call_shared
        assert our_segments() == []
    for key in HIT_KEYS:
        assert np.array_equal(bits(below[key]), bits(at[key])[:16_383]), key
    assert_hits_equal(at, chunked)
    assert_hits_equal(at, opted_out)


def test_server_without_shared_payloads_gets_bytes_and_the_same_answers(server, refusing_server, bounds):
    rays = make_rays(bounds, N, seed=140, columns=8)
    with outcore.SceneClient(server.address, timeout=60) as client:
        want_hits, want_occluded = client.cast_rays(rays), client.test_occlusions(rays)
        assert client.last_call_shared
    with outcore.SceneClient(refusing_server.address, timeout=60) as client:
        assert client.scene_info()["shared_payloads"] is False
        hits = client.cast_rays(rays)
        assert not client.last_call_shared
        occluded = client.test_occlusions(rays)
        assert not client.last_call_shared
        assert client.last_stats["rays"] == N
        assert our_segments() == [], "no segment for a server that does not take them"
    assert_hits_equal(hits, want_hits)
    assert np.array_equal(occluded, want_occluded)


def test_server_refusing_a_shared_call_is_answered_through_bytes(refusing_server, bounds, tmp_path, store):
    # As if the server had said yes in SceneInfo: the call itself is refused
    # with FAILED_PRECONDITION, redone as bytes, and shared memory stays off.
    rays = make_rays(bounds, N, seed=150)
    with outcore.SceneClient(refusing_server.address, timeout=60) as client:
        client._server_shared_payloads = True
        hits = client.cast_rays(rays)
        assert not client.last_call_shared
        assert "--no-shared-payloads" in client._shared_disabled_reason
        assert our_segments() == []
        occluded = client.test_occlusions(rays)
        assert not client.last_call_shared
        assert client.last_stats["rays"] == N
    assert_equals_trace_bitwise(hits, trace(store, rays, tmp_path))
    assert np.array_equal(occluded, np.isfinite(hits["t_hit"]))


def test_shared_counts_and_lists_equal_the_bytes_path(server, refusing_server, bounds):
    # count_intersections and list_intersections take the same-host path as
    # cast_rays: bitwise the bytes path's answers, also when a list outgrows
    # its segment's room (its hits then come as bytes) and from a server that
    # refuses shared payloads; strict errors name the ray.
    rays = make_rays(bounds, N, seed=145).reshape(40, N // 40, 6)
    with outcore.SceneClient(server.address, timeout=60) as client:
        counts = client.count_intersections(rays)
        assert client.scene_info()["shared_every_hit_payloads"] is True
        assert client.last_call_shared and client.last_stats["rays"] == N
        assert counts.dtype == np.int32 and counts.shape == rays.shape[:-1]
        listed = client.list_intersections(rays)
        assert client.last_call_shared and client.last_stats["rays"] == N
        # A segment with too little room for the hits: they come in the reply's bytes.
        client._list_hits_per_ray = 0.001
        overflowed = client.list_intersections(rays)
        assert client._list_hits_per_ray >= 1.0, "the next segment is sized from what this list held"
        bad = rays.reshape(-1, 6).copy()
        bad[17_003, 0] = np.inf
        with pytest.raises(outcore.OutcoreError, match="ray 17003") as error:
            client.count_intersections(bad, strict=True)
        assert error.value.code == "INVALID_ARGUMENT" and client._shared_disabled_reason is None
    with outcore.SceneClient(server.address, timeout=60, shared_memory=False) as client:
        by_bytes = client.count_intersections(rays)
        listed_by_bytes = client.list_intersections(rays)
        assert not client.last_call_shared
    with outcore.SceneClient(refusing_server.address, timeout=60) as client:
        assert client.scene_info()["shared_every_hit_payloads"] is False
        # As if it had said yes: the call is refused, redone as bytes.
        client._server_shared_payloads = client._server_shared_every_hit = True
        refused = client.count_intersections(rays)
        assert not client.last_call_shared and "--no-shared-payloads" in client._shared_disabled_reason
    assert counts.sum() > N // 10, "the rays must hit something for the test to mean anything"
    np.testing.assert_array_equal(counts, by_bytes)
    np.testing.assert_array_equal(counts, refused)
    np.testing.assert_array_equal(np.diff(listed["ray_splits"].astype(np.int64)), counts.ravel())
    for key in listed:
        np.testing.assert_array_equal(bits(listed[key]), bits(listed_by_bytes[key]), err_msg=key)
        np.testing.assert_array_equal(bits(overflowed[key]), bits(listed_by_bytes[key]), err_msg=key)


def test_a_shared_list_larger_than_its_room_and_a_message_is_sent_again_with_more_room(small_server, bounds):
    # --max-message-mb 1: a list whose hits outgrow the segment cannot come
    # back as bytes either (RESOURCE_EXHAUSTED); the client grows the room
    # and asks again, and the answer is the bytes path's.
    rays = make_rays(bounds, 60_000, seed=147)
    with outcore.SceneClient(small_server.address, timeout=60, shared_memory=False) as client:
        want = client.list_intersections(rays)
    assert want["ray_splits"][-1] * 32 > (1 << 20), "the hits must exceed a message for the test to mean anything"
    with outcore.SceneClient(small_server.address, timeout=60) as client:
        client._list_hits_per_ray = 0.001
        got = client.list_intersections(rays)
        assert client.last_call_shared and client._list_hits_per_ray >= 1.0
    for key in want:
        np.testing.assert_array_equal(bits(got[key]), bits(want[key]), err_msg=key)


def test_object_the_server_cannot_open_falls_back_to_bytes(server, bounds, monkeypatch):
    rays = make_rays(bounds, N, seed=160)
    want = bytes_answers(server.address, rays)[0]
    # The request names a valid object that does not exist.
    real = _wire.SharedRef
    monkeypatch.setattr(_wire, "SharedRef",
                        lambda name, *offsets: real(f"/outcore-py-{os.getpid()}-missing", *offsets))
    with outcore.SceneClient(server.address, timeout=60) as client:
        hits = client.cast_rays(rays)
        assert not client.last_call_shared
        assert client._shared_disabled_reason
        assert our_segments() == [], "the refused segment should be gone"
        assert_hits_equal(hits, want)
        monkeypatch.undo()
        assert_hits_equal(client.cast_rays(rays), want)
        assert not client.last_call_shared, "shared memory stays off after a refusal"


def test_segment_removed_from_outside_falls_back_to_bytes(server, bounds):
    # E.g. /dev/shm cleaned by someone else between two calls.
    rays = make_rays(bounds, N, seed=170, columns=8)
    with outcore.SceneClient(server.address, timeout=60) as client:
        first = client.cast_rays(rays)
        assert client.last_call_shared
        (segment,) = our_segments()
        os.unlink(os.path.join(_shared.SHM_DIR, segment))
        second = client.cast_rays(rays)
        assert not client.last_call_shared
        assert client._shared_disabled_reason
    assert_hits_equal(first, second)


def test_no_room_for_a_segment_falls_back_to_bytes(server, bounds, monkeypatch, tmp_path):
    rays = make_rays(bounds, N, seed=180)
    want = bytes_answers(server.address, rays)[0]
    monkeypatch.setattr(_shared, "SHM_DIR", str(tmp_path / "no-such-dir"))
    with outcore.SceneClient(server.address, timeout=60) as client:
        hits = client.cast_rays(rays)
        assert not client.last_call_shared
        assert client._shared_disabled_reason is None, "the server did not refuse anything"
    assert_hits_equal(hits, want)


def test_a_full_dev_shm_sends_large_batches_as_bytes_and_smaller_ones_through_it(server, bounds, monkeypatch):
    # As in a container whose /dev/shm (64 MiB by default) holds small
    # segments but not large ones: ENOSPC from posix_fallocate above a size.
    real = _shared.Segment
    room = 2 << 20

    def limited(size):
        if size > room:
            raise OSError(28, "No space left on device")
        return real(size)

    monkeypatch.setattr(_shared, "Segment", limited)
    big = make_rays(bounds, 60_000, seed=181)
    small = make_rays(bounds, N, seed=182, columns=6)
    with outcore.SceneClient(server.address, timeout=60) as client:
        big_hits = client.cast_rays(big)
        assert not client.last_call_shared
        client.cast_rays(big)
        assert not client.last_call_shared
        small_hits = client.cast_rays(small)
        assert client.last_call_shared, "a batch whose segment fits still goes through shared memory"
        assert client._shared_disabled_reason is None
    assert_hits_equal(big_hits, bytes_answers(server.address, big)[0])
    assert_hits_equal(small_hits, bytes_answers(server.address, small)[0])


def test_another_segments_token_is_permission_denied_and_keeps_shared_memory_on(server, bounds, monkeypatch):
    rays = make_rays(bounds, N, seed=185)
    real = _wire.SharedRef
    monkeypatch.setattr(_wire, "SharedRef",
                        lambda name, rays_offset, answers_offset, token, answers_bytes=0:
                        real(name, rays_offset, answers_offset, bytes(16), answers_bytes))
    with outcore.SceneClient(server.address, timeout=60) as client:
        with pytest.raises(outcore.OutcoreError, match="token does not match") as error:
            client.cast_rays(rays)
        assert error.value.code == "PERMISSION_DENIED"
        assert client._shared_disabled_reason is None
        monkeypatch.undo()
        client.cast_rays(rays)
        assert client.last_call_shared


def test_refusal_marker_matches_the_servers():
    header = os.path.join(os.path.dirname(__file__), "..", "..", "proto", "outcore", "v1", "shared_payload_wire.h")
    text = open(header).read()
    key, value = outcore.client._SHARED_REFUSED
    assert f'kSharedRefusedKey = "{key}";' in text
    assert f'kSharedRefusedValue = "{value}";' in text


def test_segment_is_reused_grown_and_removed_on_close(server, bounds):
    small = make_rays(bounds, N, seed=190, columns=6)
    big = make_rays(bounds, 100_000, seed=191, columns=8)
    with outcore.SceneClient(server.address, timeout=60) as client:
        client.cast_rays(small)
        (first,) = our_segments()
        assert os.stat(os.path.join(_shared.SHM_DIR, first)).st_mode & 0o777 == 0o600
        client.test_occlusions(small)
        client.cast_rays(small)
        assert client.last_call_shared
        assert our_segments() == [first], "the segment should be reused"
        size = os.path.getsize(os.path.join(_shared.SHM_DIR, first))
        assert size >= _shared.HEADER_BYTES + N * 24 + N * 32
        client.cast_rays(big)
        assert client.last_call_shared
        (grown,) = our_segments()
        assert grown != first, "a bigger batch should replace the segment by a larger one"
        assert os.path.getsize(os.path.join(_shared.SHM_DIR, grown)) >= 100_000 * 64 > size
        client.cast_rays(small)  # the big one serves small batches too
        assert our_segments() == [grown]
    assert our_segments() == []


def test_unclosed_client_removes_its_segment_when_collected(server, bounds):
    client = outcore.SceneClient(server.address, timeout=60)
    client.cast_rays(make_rays(bounds, N, seed=200))
    assert client.last_call_shared and len(our_segments()) == 1
    del client
    gc.collect()
    assert our_segments() == []


def test_concurrent_calls_on_one_client_each_get_their_own_answers(server, bounds):
    batches = [make_rays(bounds, n, seed=210 + i, columns=(6, 8)[i % 2])
               for i, n in enumerate((16_384, 20_000, 30_000, 45_000))]
    with outcore.SceneClient(server.address, timeout=60) as client:
        serial = [(client.cast_rays(rays), client.test_occlusions(rays)) for rays in batches]
        start = threading.Barrier(len(batches))
        results: list = [None] * len(batches)
        errors = []

        def work(i):
            try:
                start.wait()
                results[i] = [(client.cast_rays(batches[i]), client.test_occlusions(batches[i]))
                              for _ in range(3)]
            except BaseException as e:  # reported below
                errors.append(e)

        threads = [threading.Thread(target=work, args=(i,)) for i in range(len(batches))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(60)
        assert not errors, errors
        assert client.last_call_shared
        assert client._shared_disabled_reason is None
        assert 1 <= len(our_segments()) <= len(batches)
    for (want_hits, want_occluded), got in zip(serial, results):
        for hits, occluded in got:
            assert_hits_equal(hits, want_hits)
            assert np.array_equal(occluded, want_occluded)


def test_strict_nan_ray_in_a_shared_call_is_named_by_its_index(server, bounds):
    rays = make_rays(bounds, 30_000, seed=220)
    rays[20_001, 3] = np.nan
    with outcore.SceneClient(server.address, timeout=60) as client:
        with pytest.raises(outcore.OutcoreError, match="ray 20001") as error:
            client.cast_rays(rays, strict=True)
        assert error.value.code == "INVALID_ARGUMENT"
        with pytest.raises(outcore.OutcoreError, match="ray 20001"):
            client.test_occlusions(rays, strict=True)
        assert client._shared_disabled_reason is None, "a bad ray is no reason to give up shared memory"
        # Not strict: the bad ray is a miss and the others are answered.
        result = client.cast_rays(rays)
        assert client.last_call_shared
        assert result["t_hit"][20_001] == np.inf and result["primitive_ids"][20_001] == outcore.INVALID_ID
        assert client.last_stats["invalid_rays"] == 1


@pytest.mark.parametrize(
    "target,local",
    [("localhost:5", True), ("LOCALHOST:5", True), ("127.0.0.1:50051", True), ("127.8.9.10:1", True),
     ("[::1]:50051", True), ("::1", True), ("ipv4:127.0.0.1:5", True), ("ipv4:127.0.0.1:5,127.0.0.2:6", True),
     ("ipv6:[::1]:5", True), ("unix:/tmp/outcore.sock", True), ("unix:///tmp/x", True),
     ("dns:///localhost:5", True), ("dns:localhost:5", True), ("[::ffff:127.0.0.1]:5", True),
     ("10.0.0.1:5", False), ("example.com:443", False), ("[2001:db8::1]:5", False),
     ("ipv4:127.0.0.1:5,10.0.0.1:6", False), ("dns:///example.com:5", False), ("0.0.0.0:5", False)],
)
def test_loopback_targets(target, local):
    assert _shared.is_loopback_target(target) is local


def test_pool_reuses_grows_and_closes():
    pool = _shared.SegmentPool(keep=2)
    a = pool.take(1000)
    assert a.size >= 1000 and a.name.startswith(f"/{_shared.NAME_PREFIX}{os.getpid()}-")
    b = pool.take(1000)  # a is in use: a second segment
    assert b.name != a.name and len(our_segments()) == 2
    pool.give(a)
    pool.give(b, reusable=False)  # a failed call's segment is not kept
    assert our_segments() == [a.name[1:]]
    assert pool.take(500) is a
    pool.give(a)
    c = pool.take(a.size + 1)  # grows: replaces a
    assert c.size > a.size and our_segments() == [c.name[1:]]
    pool.close()
    assert our_segments() == [c.name[1:]], "in use: removed when given back"
    pool.give(c)
    assert our_segments() == []
    with pytest.raises(OSError):
        pool.take(10)


def test_segment_sizes_are_rounded_up_with_little_spare():
    for need in (1, 1 << 20, (1 << 20) + 1, 6_400_000, 3 << 30):
        size = _shared.segment_size(need)
        assert need <= size < need + max(1 << 20, need / 4), need
        assert size % _shared.ALIGNMENT == 0  # whole MiB steps


def test_orphans_of_dead_clients_are_removed_and_others_kept():
    child = os.fork()
    if child == 0:
        os._exit(0)
    os.waitpid(child, 0)  # now a dead pid
    names = {"dead": f"{_shared.NAME_PREFIX}{child}-0123456789abcdef",
             "alive": f"{_shared.NAME_PREFIX}{os.getppid()}-0123456789abcdef",
             "not a pid": f"{_shared.NAME_PREFIX}12x4-0123456789abcdef"}
    for name in names.values():
        with open(os.path.join(_shared.SHM_DIR, name), "wb"):
            pass
    try:
        assert _shared.remove_orphans() == 1
        left = set(os.listdir(_shared.SHM_DIR))
        assert names["dead"] not in left
        assert names["alive"] in left and names["not a pid"] in left
    finally:
        for name in names.values():
            try:
                os.unlink(os.path.join(_shared.SHM_DIR, name))
            except FileNotFoundError:
                pass


def test_a_segment_starts_with_its_token():
    segment = _shared.Segment(1 << 20)
    try:
        assert len(segment.token) == _shared.TOKEN_BYTES == 16
        with open(segment.path, "rb") as f:
            assert f.read(16) == segment.token
        assert _shared.Segment(1 << 20).token != segment.token
    finally:
        segment.close()
