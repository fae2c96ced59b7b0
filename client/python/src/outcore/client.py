"""SceneClient: ray queries against an `outcore serve` server, with the look
of Open3D's RaycastingScene (cast_rays -> dict of arrays, test_occlusions ->
bools).

A batch that fits one message goes out as one unary call; a larger one is cut
into chunks sent over the bidirectional stream, answered in order, and put
back together, so callers never see the message limit. The chunk size comes
from the smaller of this client's max_message_mb and the server's
--max-message-mb (asked once, with GetSceneInfo, the first time a batch could
exceed it), unless chunk_rays is given; batches of more than 262,144 rays
are streamed in chunks of at most 65,536 rays even when they would fit one
message, so the wire overlaps the server's tracing. Streamed chunks are
memoryview slices of the caller's (contiguous float32) rays, serialised one
at a time as gRPC asks for them, and replies are copied straight into one
preallocated result array.

Same-host shared memory (proto SharedPayload; _shared.py): a batch of at
least 16,384 rays goes as ONE unary call whose rays and answers travel through
a POSIX shared-memory segment (/dev/shm/outcore-py-<pid>-<random>) instead of
the message, skipping protobuf framing and the socket buffers, when all of
these hold: shared_memory=True (the default), chunk_rays is None, the address
is this host ("localhost", 127.x.y.z, [::1], ipv4:/ipv6: loopback forms, or a
unix: socket), and the server says it accepts shared payloads (SceneInfo
shared_payloads, asked once, lazily). Smaller batches gain little over the
message and stay bytes. The rays are copied into the segment once, and the
answers copied out of it into a fresh array after the reply, so results never
alias the segment, which is kept for the client's life and reused (grown when
a batch needs more; unlinked by close()). Each segment starts with a 64-byte
header holding a random token that goes with the call, so only this client
can name its segments to the server. If the server refuses a segment
(FAILED_PRECONDITION with its "refused" trailing metadata: the peer it sees
is not loopback, it runs with --no-shared-payloads, it cannot open the
object because it has another /dev/shm), the call is redone as bytes and
shared memory stays off for this client; if no segment can be made (no
/dev/shm, no room in it), that batch and larger ones go as bytes.
`last_call_shared` tells which path the last query took.

Thread-safety: one SceneClient may be used from several threads at once (gRPC
channels are thread-safe; concurrent shared calls each take their own segment
from a locked pool); only `last_stats` and `last_call_shared` are per-client
and then belong to whichever call finished last.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import grpc
import numpy as np
import numpy.lib.recfunctions  # noqa: F401  (np.lib.recfunctions)

from . import _routing, _shared, _wire
from ._rays import as_wire_rays, rays_with_segment
from ._security import make_channel
from ._messages import add_fields
from ._messages import message_to_dict as _message_to_dict
from ._dynamic_layer import DynamicLayerCalls, dynamic_calls
from ._open3d_queries import Open3dQueries, _check_nthreads
from .errors import OutcoreError, from_rpc_error
from .v1 import scene_query_pb2 as pb

INVALID_ID = 0xFFFFFFFF  # Open3D's RaycastingScene.INVALID_ID: primitive/geometry id of a miss

_MIB = 1 << 20
_GRPC_MAX_LENGTH = (1 << 31) - 1  # gRPC's channel options are int32
# Room in a message for everything but the packed rays/hits (counts, stats).
_MESSAGE_MARGIN = 16 * 1024
# Requests and replies below this fit any server (--max-message-mb >= 1), so
# small batches never cost a GetSceneInfo round trip.
_ALWAYS_FITS = 512 * 1024
# Batches of more than _STREAM_ABOVE_RAYS rays are streamed in chunks of at
# most _STREAM_CHUNK_RAYS even when they would fit one message: the server then
# traces one chunk while the next one and the previous reply are on the wire
# (the C++ client's rule, client/cpp/scene_client.cpp; docs/BENCHMARKS.md).
_STREAM_ABOVE_RAYS = 262_144
_STREAM_CHUNK_RAYS = 65_536
# Batches of at least this many rays use a shared-memory segment when they
# can (see the module docstring); below it the message costs little and a
# segment would only hold memory.
_SHARED_MIN_RAYS = 16_384
# The server's trailing metadata on a refusal (proto/outcore/v1/shared_payload_wire.h).
_SHARED_REFUSED = ("outcore-shared-payload", "refused")
_SERVICE = pb.DESCRIPTOR.services_by_name["SceneQuery"].full_name


class _QueryOptions(NamedTuple):
    strict: bool
    dynamic_version: int | None
    only_bricks: tuple = ()  # a replica's part of the scene (routing="bricks")


def _check_version(version) -> int | None:
    if version is None:
        return None
    if isinstance(version, bool) or not isinstance(version, (int, np.integer)) or not 0 <= version < 2**64:
        raise ValueError(f"dynamic_version must be None or a non-negative int, got {version!r}")
    return int(version)


def _refused(error: grpc.RpcError) -> bool:
    """The server's FAILED_PRECONDITION refusing shared payloads (as opposed
    to a shared call that failed)."""
    code_fn = getattr(error, "code", None)
    if not callable(code_fn) or code_fn() != grpc.StatusCode.FAILED_PRECONDITION:
        return False
    trailers_fn = getattr(error, "trailing_metadata", None)
    trailers = (trailers_fn() if callable(trailers_fn) else None) or ()
    return any((key, value) == _SHARED_REFUSED for key, value in trailers)


class _Query:
    """What differs between closest-hit and any-hit queries."""

    def __init__(self, name: str, record_dtype: np.dtype, hit_fields: int = _wire.HIT_FIELDS_ALL):
        self.unary = f"/{_SERVICE}/{name}"
        self.stream = f"/{_SERVICE}/{name}Stream"
        self.record_dtype = np.dtype(record_dtype)
        self.hit_fields = hit_fields


_INTERSECT = _Query("Intersect", _wire.HIT_DTYPE)
_OCCLUDED = _Query("Occluded", np.uint8)
# cast_rays(hit_fields=...): the query, and the keys of its answer.
_CAST_FIELDS = {
    "all": (_INTERSECT, ("t_hit", "geometry_ids", "primitive_ids", "primitive_uvs", "primitive_normals")),
    "t": (_Query("Intersect", _wire.HIT_T_DTYPE, _wire.HIT_FIELDS_T), ("t_hit",)),
    "t_ids": (_Query("Intersect", _wire.HIT_T_IDS_DTYPE, _wire.HIT_FIELDS_T_IDS),
              ("t_hit", "geometry_ids", "primitive_ids")),
}


class SceneClient(Open3dQueries, DynamicLayerCalls):
    """A connection to `outcore serve`.

    address: "host:port" (gRPC target syntax). timeout: seconds allowed for
    each call (a whole streamed batch is one call), None for no deadline.
    max_message_mb: largest message this client sends or accepts, MiB.
    chunk_rays: rays per streamed chunk; None sizes chunks from the message
    limits, and batches that fit one message go as a single unary call.
    shared_memory: pass batches of >= 16,384 rays through a shared-memory
    segment when the server is on this host and accepts it (module
    docstring); False always sends bytes. Only with chunk_rays None.
    tls_ca: connect with TLS, trusting this CA (a path to a PEM file, or the
    PEM bytes); tls_cert and tls_key: a client certificate for servers that
    require one (serve --tls-client-ca). token: sent as "authorization:
    Bearer TOKEN" on every call (serve --auth-token-file). All keyword-only.

    Replicas (docs/SCALING.md): `address` may be a list of "host:port"
    strings or a "dns:///NAME:PORT" target; routing="bricks" (the default:
    each replica traces every ray in its part of the bricks, the nearest
    answer kept) or "rays" (each ray to one replica by its entry cell,
    route_cells a side); load_factor (bricks 1.01, rays 1.25) bounds a
    replica's share of the triangles or of the rays.
    """

    def __init__(self, address, timeout: float | None = None, max_message_mb: float = 64,
                 chunk_rays: int | None = None, shared_memory: bool = True, *, tls_ca=None, tls_cert=None,
                 tls_key=None, token: str | None = None, routing: str = "bricks", route_cells: int = 8,
                 load_factor: float | None = None):
        self._router = None
        if isinstance(address, (list, tuple)) or (isinstance(address, str) and address.startswith("dns:")):
            targets = [address] if isinstance(address, str) else list(address)
            if not targets or not all(isinstance(t, str) and t for t in targets):
                raise ValueError(f"replicas must be a non-empty list of 'host:port' strings, got {address!r}")
            if isinstance(route_cells, bool) or not isinstance(route_cells, int) or not 1 <= route_cells <= 64:
                raise ValueError(f"route_cells must be an int in 1..64, got {route_cells!r}")
            if routing not in ("bricks", "rays"):
                raise ValueError(f"routing must be 'bricks' or 'rays', got {routing!r}")
            if load_factor is not None and (isinstance(load_factor, bool) or
                                            not (load_factor >= 1 and math.isfinite(load_factor))):
                raise ValueError(f"load_factor must be None or a number >= 1, got {load_factor!r}")
            options = dict(timeout=timeout, max_message_mb=max_message_mb, chunk_rays=chunk_rays,
                           shared_memory=shared_memory, tls_ca=tls_ca, tls_cert=tls_cert, tls_key=tls_key,
                           token=token)
            self._router = _routing.Router(targets, lambda replica: SceneClient(replica, **options),
                                           cells=route_cells, load_factor=load_factor, routing=routing)
            # Calls other than the ray queries go to one replica (the same
            # answer on any); the dynamic layer is refused (it is per server).
            address = self._router.replicas()[0]
        if not isinstance(address, str) or not address:
            raise ValueError(f"address must be a non-empty 'host:port' string, got {address!r}")
        if timeout is not None and not (timeout > 0 and math.isfinite(timeout)):
            raise ValueError(f"timeout must be None or a positive number of seconds, got {timeout!r}")
        if not (max_message_mb > 0 and math.isfinite(max_message_mb)):
            raise ValueError(f"max_message_mb must be a positive number, got {max_message_mb!r}")
        if chunk_rays is not None and (isinstance(chunk_rays, bool) or not isinstance(chunk_rays, int)
                                       or chunk_rays < 1):
            raise ValueError(f"chunk_rays must be None or a positive int, got {chunk_rays!r}")
        if not isinstance(shared_memory, bool):
            raise ValueError(f"shared_memory must be True or False, got {shared_memory!r}")
        self.address = address
        self.timeout = timeout
        self.chunk_rays = chunk_rays
        self.shared_memory = shared_memory
        # Shared memory: only worth asking the server about for local targets.
        self._shared_local = _shared.supported() and _shared.is_loopback_target(address)
        self._server_shared_payloads: bool | None = None  # SceneInfo.shared_payloads, once asked
        self._server_shared_every_hit = False  # SceneInfo.shared_every_hit_payloads
        # Why shared memory is off for this client after a failure (None: not off).
        self._shared_disabled_reason: str | None = None
        self._shared_pool = _shared.SegmentPool()
        # Segments of this many bytes or more could not be made: such batches go as bytes.
        self._shared_failed_bytes = math.inf
        self._last_call_shared = False
        self._max_message_bytes = min(int(max_message_mb * _MIB), _GRPC_MAX_LENGTH)
        self._server_max_message_bytes: int | None = None
        self._channel = make_channel(
            address,
            [
                ("grpc.max_send_message_length", self._max_message_bytes),
                ("grpc.max_receive_message_length", self._max_message_bytes),
            ],
            tls_ca=tls_ca, tls_cert=tls_cert, tls_key=tls_key, token=token,
        )
        # Serializers None: requests and replies pass as raw bytes (see _wire).
        self._calls = {
            path: self._channel.unary_unary(path) for path in (_INTERSECT.unary, _OCCLUDED.unary)
        }
        self._calls.update(
            {path: self._channel.stream_stream(path) for path in (_INTERSECT.stream, _OCCLUDED.stream)}
        )
        self._get_scene_info = self._channel.unary_unary(
            f"/{_SERVICE}/GetSceneInfo",
            request_serializer=pb.GetSceneInfoRequest.SerializeToString,
            response_deserializer=pb.SceneInfo.FromString,
        )
        self._get_stats = self._channel.unary_unary(
            f"/{_SERVICE}/GetStats",
            request_serializer=pb.GetStatsRequest.SerializeToString,
            response_deserializer=pb.ServerStats.FromString,
        )
        #: The engine's figures for the last query (QueryStats fields: rays,
        #: rays_hit, brick_visits, brick_visits_without_hit,
        #: bricks_skipped_by_bound, upper_nodes_visited, proxy_tests,
        #: bricks_skipped_by_proxy, rays_traced_ahead, cache_hits,
        #: cache_misses, brick_builds, subtree_loads, subtree_writes,
        #: seconds_total, seconds_upper, seconds_brick, ...; summed over the
        #: chunks of a streamed batch), or None before the first.
        self.last_stats: dict | None = None
        self._plain_calls: dict = {}
        #: The dynamic layer's version the last query saw (0: the empty layer).
        self.last_dynamic_version = 0
        self._dynamic_calls = dynamic_calls(self._channel)

    # -- lifetime ---------------------------------------------------------

    def close(self) -> None:
        """Closes the channel and removes the shared-memory segments (a segment
        still in use by a running call goes when that call ends)."""
        self._shared_pool.close()
        self._channel.close()
        if self._router is not None:
            self._router.close()

    def __del__(self):
        # Best effort for clients never closed; weakref finalizers in _shared
        # still unlink the files at interpreter exit.
        pool = getattr(self, "_shared_pool", None)
        if pool is not None:
            try:
                pool.close()
            except Exception:
                pass

    def __enter__(self) -> "SceneClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"SceneClient({self.address!r}, timeout={self.timeout!r})"

    @property
    def last_call_shared(self) -> bool:
        """Whether the last query that succeeded passed its rays and answers
        through shared memory (False for bytes, streams and empty batches)."""
        return self._last_call_shared

    # -- queries ----------------------------------------------------------

    def cast_rays(self, rays, *, nthreads: int = 0, strict: bool = False,
                  dynamic_version: int | None = None, hit_fields: str = "all") -> dict:
        """Closest hit of each ray, as Open3D's RaycastingScene.cast_rays.

        rays: (..., 6) [ox oy oz dx dy dz] or (..., 8) [... tnear tfar]
        (tnear 0, tfar inf by default), float32 preferred (other real dtypes
        are converted). Returns a dict of read-only arrays shaped like the
        batch dims: t_hit (...,) float32, inf on a miss; geometry_ids and
        primitive_ids (...,) uint32, INVALID_ID on a miss; primitive_uvs
        (..., 2) float32; primitive_normals (..., 3) float32 (unit geometric
        normal, zeros on a miss). They are views of one buffer (the reply's
        bytes when the batch fitted one message; for a shared-memory call a
        fresh copy out of the segment, never the segment itself): use
        np.array(x) for a writable copy. strict: invalid rays (NaN/Inf, zero
        direction, bad tnear/tfar) raise OutcoreError INVALID_ARGUMENT naming
        the first bad ray, instead of being misses. dynamic_version: the
        dynamic layer's version to trace (see add_mesh), the latest if None;
        one no longer kept is OutcoreError NOT_FOUND. The version the answers
        saw is then in last_dynamic_version. nthreads: accepted for Open3D's
        signature and ignored (the server's --threads decide). hit_fields:
        "all" (the default, Open3D's five keys, 32 bytes a ray on the wire),
        "t_ids" (t_hit, geometry_ids, primitive_ids: 12 bytes) or "t" (t_hit
        only: 4 bytes), to cut reply bytes for a client on another host; the
        dict then holds only those keys (a shared-memory call fetches whole
        records and returns the same keys). Options are keyword-only.
        """
        _check_nthreads(nthreads)
        if hit_fields not in _CAST_FIELDS:
            raise ValueError(f"hit_fields must be one of {sorted(_CAST_FIELDS)}, got {hit_fields!r}")
        query, keys = _CAST_FIELDS[hit_fields]
        flat, batch_shape = as_wire_rays(rays)
        hits = self._query(query, flat, _QueryOptions(strict, _check_version(dynamic_version)))
        columns = {
            "t_hit": lambda: hits["t_hit"].reshape(batch_shape),
            "geometry_ids": lambda: hits["geometry_id"].reshape(batch_shape),
            "primitive_ids": lambda: hits["primitive_id"].reshape(batch_shape),
            "primitive_uvs": lambda: hits["uv"].reshape(batch_shape + (2,)),
            "primitive_normals": lambda: hits["ng"].reshape(batch_shape + (3,)),
        }
        return {key: columns[key]() for key in keys}

    def test_occlusions(self, rays, tnear: float = 0.0, tfar: float = math.inf, *, nthreads: int = 0,
                        strict: bool = False, dynamic_version: int | None = None) -> np.ndarray:
        """Whether each ray hits anything in (tnear, tfar]: a read-only bool
        array shaped like the batch dims, as Open3D's test_occlusions. tnear
        and tfar apply to (..., 6) rays; (..., 8) rays carry their own (and
        then tnear/tfar must be left at their defaults). Other arguments as
        cast_rays (keyword-only)."""
        _check_nthreads(nthreads)
        flat, batch_shape = rays_with_segment(rays, tnear, tfar)
        occluded = self._query(_OCCLUDED, flat, _QueryOptions(strict, _check_version(dynamic_version)))
        if occluded.size and occluded.max() > 1:
            raise OutcoreError("DATA_LOSS", "occlusion reply holds a byte that is neither 0 nor 1",
                               _OCCLUDED.unary)
        return occluded.view(np.bool_).reshape(batch_shape)

    def scene_info(self) -> dict:
        """The served scene (GetSceneInfo) as a dict: store_path, triangle_count,
        brick_count, bounds_lo/bounds_hi (3 floats each), inputs (list of
        {spec, triangle_count, degenerate_count}; geometry_id = index),
        cache_budget_bytes, max_message_bytes, shared_payloads (whether it
        accepts shared-memory payloads from this host), server_version, ..."""
        info = self._call_plain(self._get_scene_info, pb.GetSceneInfoRequest(), "GetSceneInfo")
        self._server_max_message_bytes = info.max_message_bytes
        self._server_shared_payloads = info.shared_payloads
        self._server_shared_every_hit = info.shared_every_hit_payloads
        return _message_to_dict(info)

    def stats(self) -> dict:
        """Server-wide figures since start (GetStats) as a dict: requests,
        failed_requests, rays, rays_hit, invalid_rays, seconds_tracing; the
        brick cache's (cache_hits, cache_misses, brick_builds,
        brick_builds_by_structure (a dict: structure -> builds; with
        --brick-accel auto, the structures chosen), brick_rebuilds, evictions,
        resident_bytes, peak_resident_bytes, cache_budget_bytes, ...); sums
        over the requests of brick_visits, brick_visits_without_hit,
        proxy_tests, bricks_skipped_by_proxy, bricks_skipped_by_bound,
        rays_traced_ahead and rays_in_brick_set;
        proxy_bytes; and the
        subtree tier's (subtree_dir, "" without one, subtree_loads,
        subtree_loads_checked, subtree_loads_kept, subtree_loads_recycled, subtree_writes,
        subtree_rejects, subtree_bytes_read,
        subtree_bytes_written, subtree_load_seconds, subtree_files,
        subtree_file_bytes, subtree_write_failures, subtree_writes_too_large,
        subtree_files_evicted, subtree_write_seconds; all 0 without a tier);
        the dynamic layer's (dynamic_version, dynamic_meshes,
        dynamic_instances, dynamic_triangles, dynamic_mesh_refits,
        dynamic_mesh_rebuilds, dynamic_top_refits, dynamic_top_rebuilds)."""
        return _message_to_dict(self._call_plain(self._get_stats, pb.GetStatsRequest(), "GetStats"))

    # -- internals --------------------------------------------------------

    def _call_plain(self, call, request, method: str):
        try:
            return call(request, timeout=self.timeout)
        except grpc.RpcError as e:
            raise from_rpc_error(e, method) from None

    def _chunk_size(self, query: _Query, n: int, ray_bytes: int) -> int:
        if self.chunk_rays is not None:
            return self.chunk_rays
        per_ray = max(ray_bytes, query.record_dtype.itemsize)
        if n * per_ray + _MESSAGE_MARGIN <= _ALWAYS_FITS:
            return n
        limit = self._max_message_bytes
        if self._server_max_message_bytes is None:
            self.scene_info()
        if self._server_max_message_bytes:  # 0: a server that does not say
            limit = min(limit, self._server_max_message_bytes)
        chunk = max(1, (limit - _MESSAGE_MARGIN) // per_ray)
        if n > _STREAM_ABOVE_RAYS:
            chunk = min(chunk, _STREAM_CHUNK_RAYS)
        return chunk

    def _query(self, query: _Query, rays: np.ndarray, opts: _QueryOptions) -> np.ndarray:
        """Answers (n, 6|8) wire rays: an (n,) array of query.record_dtype,
        or of whole hit records (_wire.HIT_DTYPE) from a shared-memory call
        that asked for fewer fields."""
        if self._router is not None and rays.shape[0]:
            return self._routed_query(query, rays, opts)
        n = rays.shape[0]
        if n == 0:
            out = np.empty(0, dtype=query.record_dtype)
            out.flags.writeable = False
            self.last_stats = None
            self._last_call_shared = False
            return out
        if self._shared_wanted(n):
            # Shared answers are whole records whatever fields were asked.
            out = self._query_shared(_INTERSECT if query.hit_fields else query, rays, opts)
            if out is not None:
                return out
            # The server refused the segment or none could be made: shared
            # memory is now off for this client, and the batch goes as bytes.
        chunk = self._chunk_size(query, n, rays.shape[1] * 4)
        if n <= chunk:
            return self._query_unary(query, rays, opts)
        return self._query_stream(query, rays, opts, chunk)

    def _routed_query(self, query: _Query, rays: np.ndarray, opts: _QueryOptions) -> np.ndarray:
        """_query over the replicas: parts by routing key, in parallel (_routing)."""
        def run_part(client, part, only_bricks):
            answers = client._query(query, np.ascontiguousarray(part), opts._replace(only_bricks=only_bricks))
            if answers.dtype != query.record_dtype:
                # A shared-memory call's whole records, cut to the fields asked.
                answers = np.lib.recfunctions.repack_fields(answers[list(query.record_dtype.names)])
            return answers, (client.last_stats, client.last_call_shared, client.last_dynamic_version)

        out = np.empty(rays.shape[0], dtype=query.record_dtype)
        parts, routed_by = self._router.query(np.ascontiguousarray(rays), run_part, out)
        self.last_stats = _routing.combined_stats([stats for stats, _, _ in parts], routed_by, out)
        self._last_call_shared = any(shared for _, shared, _ in parts)
        self.last_dynamic_version = max(version for _, _, version in parts)
        self.last_replicas = len(parts)
        out.flags.writeable = False
        return out

    def replicas(self) -> list[str]:
        """The replicas' addresses (a replicated client), else [address]."""
        return self._router.replicas() if self._router is not None else [self.address]

    def _check_reply(self, query: _Query, reply: _wire.Reply, expected_rays: int, method: str,
                     sequence: int | None = None, shared: bool = False) -> None:
        problem = None
        if reply.layout_version != _wire.LAYOUT_VERSION:
            problem = f"layout_version {reply.layout_version}, expected {_wire.LAYOUT_VERSION}"
        elif reply.ray_count != expected_rays:
            problem = f"ray_count {reply.ray_count}, expected {expected_rays}"
        elif reply.answers_in_shared != shared:
            problem = ("answers_in_shared not set for a request with a shared payload" if shared else
                       "answers_in_shared set for a request without a shared payload")
        elif shared and reply.payload_size:
            problem = f"{reply.payload_size} payload bytes beside answers in shared memory, expected none"
        elif not shared and reply.payload_size != expected_rays * query.record_dtype.itemsize:
            problem = (f"{reply.payload_size} payload bytes, expected "
                       f"{expected_rays} x {query.record_dtype.itemsize}")
        elif sequence is not None and reply.sequence != sequence:
            problem = f"sequence {reply.sequence}, expected {sequence} (chunks out of order)"
        if problem:
            raise OutcoreError("DATA_LOSS", f"malformed reply: {problem}", method)

    def _unary_reply(self, query: _Query, data: bytes, expected_rays: int, shared: bool = False) -> _wire.Reply:
        """A unary call's reply, decoded and checked (DATA_LOSS otherwise)."""
        try:
            reply = _wire.decode_reply(data)
        except _wire.WireError as e:
            raise OutcoreError("DATA_LOSS", f"malformed reply: {e}", query.unary) from None
        self._check_reply(query, reply, expected_rays, query.unary, shared=shared)
        return reply

    def _query_unary(self, query: _Query, rays: np.ndarray, opts: _QueryOptions) -> np.ndarray:
        request = _wire.encode_query(rays, strict=opts.strict, dynamic_version=opts.dynamic_version,
                                     hit_fields=query.hit_fields, only_bricks=opts.only_bricks)
        try:
            data = self._calls[query.unary](request, timeout=self.timeout)
        except grpc.RpcError as e:
            raise from_rpc_error(e, query.unary) from None
        reply = self._unary_reply(query, data, rays.shape[0])
        self.last_stats = _message_to_dict(pb.QueryStats.FromString(reply.stats))
        self.last_dynamic_version = reply.dynamic_version
        self._last_call_shared = False
        return reply.payload(query.record_dtype)

    def _shared_wanted(self, n: int) -> bool:
        if not (self.shared_memory and self.chunk_rays is None and n >= _SHARED_MIN_RAYS
                and self._shared_local and self._shared_disabled_reason is None):
            return False
        if self._server_shared_payloads is None:
            self.scene_info()
        return bool(self._server_shared_payloads)

    def _disable_shared(self, reason: str) -> None:
        self._shared_disabled_reason = reason
        self._shared_pool.close()  # frees /dev/shm now; in-use segments go when given back

    def _query_shared(self, query: _Query, rays: np.ndarray, opts: _QueryOptions) -> np.ndarray | None:
        """One unary call with the rays and answers in a shared segment. None
        when the batch must go as bytes (see _shared_call)."""
        n = rays.shape[0]

        def finish(data, segment, answers_offset):
            return (self._unary_reply(query, data, n, shared=True),
                    segment.read_answers(query.record_dtype, n, answers_offset))

        done = self._shared_call(self._calls[query.unary], query.unary, rays, n * query.record_dtype.itemsize,
                                 finish, strict=opts.strict, dynamic_version=opts.dynamic_version,
                                 only_bricks=opts.only_bricks)
        if done is None:
            return None
        reply, out = done
        self.last_stats = _message_to_dict(pb.QueryStats.FromString(reply.stats))
        self.last_dynamic_version = reply.dynamic_version
        self._last_call_shared = True
        return out

    def _shared_call(self, call, method: str, rays: np.ndarray, answers_bytes: int, finish, answers_room=False,
                     **encode_options):
        """Calls `call` (unary, request as bytes) with the rays and the
        answers in a shared segment, answers_bytes of room for them (also
        sent as shared.answers_bytes when answers_room): finish(reply,
        segment, answers_offset), run before the segment is given back.
        None when the batch must go as bytes: the server refused the segment
        (shared memory is then off for this client) or no segment of its
        size can be made (then for batches at least as large). Other errors
        raise as usual."""
        n, columns = rays.shape
        rays_offset = _shared.HEADER_BYTES
        answers_offset = rays_offset + _shared.round_up(n * columns * 4, _shared.ALIGNMENT)
        need = answers_offset + answers_bytes
        if need >= self._shared_failed_bytes:
            return None
        try:
            segment = self._shared_pool.take(need)
        except OSError:
            self._shared_failed_bytes = min(self._shared_failed_bytes, need)
            return None
        # Only after a reply is the server certainly done with the segment: a
        # call abandoned on our side (deadline, interrupt) may still be traced
        # and its answers written, so that segment must never serve another.
        reusable = False
        try:
            segment.write_rays(rays, rays_offset)
            shared = _wire.SharedRef(segment.name, rays_offset, answers_offset, segment.token,
                                     answers_bytes if answers_room else 0)
            request = _wire.encode_query(rays, shared=shared, **encode_options)
            try:
                data = call(request, timeout=self.timeout)
            except grpc.RpcError as e:
                if _refused(e):
                    details_fn = getattr(e, "details", None)
                    self._disable_shared((details_fn() if callable(details_fn) else None) or str(e))
                    return None
                raise from_rpc_error(e, method) from None
            reusable = True
            return finish(data, segment, answers_offset)
        finally:
            self._shared_pool.give(segment, reusable)

    def _query_stream(self, query: _Query, rays: np.ndarray, opts: _QueryOptions, chunk: int) -> np.ndarray:
        n = rays.shape[0]
        starts = range(0, n, chunk)
        # Chunks are serialised lazily as gRPC asks for them, so at most a
        # few are held at once, not a second copy of the batch.
        requests = (
            _wire.encode_query(rays[start : start + chunk], strict=opts.strict, sequence=sequence,
                               dynamic_version=opts.dynamic_version, hit_fields=query.hit_fields,
                               only_bricks=opts.only_bricks)
            for sequence, start in enumerate(starts)
        )
        out = np.empty(n, dtype=query.record_dtype)
        out_bytes = out.view(np.uint8)
        itemsize = query.record_dtype.itemsize
        stats = []  # serialised QueryStats per chunk, summed once the stream is done
        call = self._calls[query.stream](requests, timeout=self.timeout)
        sequence = 0
        try:
            for data in call:
                if sequence >= len(starts):
                    raise OutcoreError("DATA_LOSS", f"more replies than the {len(starts)} chunks sent",
                                       query.stream)
                start = starts[sequence]
                count = min(chunk, n - start)
                try:
                    reply = _wire.decode_reply(data)
                except _wire.WireError as e:
                    raise OutcoreError("DATA_LOSS", f"malformed reply to chunk {sequence}: {e}",
                                       query.stream) from None
                self._check_reply(query, reply, count, query.stream, sequence)
                out_bytes[start * itemsize : (start + count) * itemsize] = reply.payload(np.uint8)
                stats.append(reply.stats)
                self.last_dynamic_version = reply.dynamic_version
                sequence += 1
        except grpc.RpcError as e:
            raise from_rpc_error(e, query.stream) from None
        except BaseException:
            call.cancel()  # stop the server's work for a batch we are abandoning
            raise
        if sequence != len(starts):
            raise OutcoreError("DATA_LOSS", f"stream ended after {sequence} of {len(starts)} chunks",
                               query.stream)
        totals = pb.QueryStats()
        for data in stats:
            add_fields(totals, pb.QueryStats.FromString(data))
        self.last_stats = _message_to_dict(totals)
        self._last_call_shared = False
        out.flags.writeable = False
        return out
