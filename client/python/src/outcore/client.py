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

Thread-safety: one SceneClient may be used from several threads at once (gRPC
channels are thread-safe); only `last_stats` is per-client and then belongs
to whichever call finished last.
"""

from __future__ import annotations

import math

import grpc
import numpy as np

from . import _wire
from ._rays import as_wire_rays
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
_SERVICE = pb.DESCRIPTOR.services_by_name["SceneQuery"].full_name


def _message_to_dict(message) -> dict:
    """A protobuf message as plain Python values (ints stay ints, unlike
    json_format, which turns uint64 into strings)."""
    out = {}
    for field in message.DESCRIPTOR.fields:
        value = getattr(message, field.name)
        if field.type == field.TYPE_MESSAGE:
            if field.is_repeated:
                value = [_message_to_dict(v) for v in value]
            else:
                value = _message_to_dict(value)
        elif field.is_repeated:
            value = list(value)
        elif field.enum_type is not None:
            value = field.enum_type.values_by_number[value].name
        out[field.name] = value
    return out


class _Query:
    """What differs between closest-hit and any-hit queries."""

    def __init__(self, name: str, record_dtype: np.dtype):
        self.unary = f"/{_SERVICE}/{name}"
        self.stream = f"/{_SERVICE}/{name}Stream"
        self.record_dtype = np.dtype(record_dtype)


_INTERSECT = _Query("Intersect", _wire.HIT_DTYPE)
_OCCLUDED = _Query("Occluded", np.uint8)


class SceneClient:
    """A connection to `outcore serve`.

    address: "host:port" (gRPC target syntax). timeout: seconds allowed for
    each call (a whole streamed batch is one call), None for no deadline.
    max_message_mb: largest message this client sends or accepts, MiB.
    chunk_rays: rays per streamed chunk; None sizes chunks from the message
    limits, and batches that fit one message go as a single unary call.
    """

    def __init__(self, address: str, timeout: float | None = None, max_message_mb: float = 64,
                 chunk_rays: int | None = None):
        if not isinstance(address, str) or not address:
            raise ValueError(f"address must be a non-empty 'host:port' string, got {address!r}")
        if timeout is not None and not (timeout > 0 and math.isfinite(timeout)):
            raise ValueError(f"timeout must be None or a positive number of seconds, got {timeout!r}")
        if not (max_message_mb > 0 and math.isfinite(max_message_mb)):
            raise ValueError(f"max_message_mb must be a positive number, got {max_message_mb!r}")
        if chunk_rays is not None and (isinstance(chunk_rays, bool) or not isinstance(chunk_rays, int)
                                       or chunk_rays < 1):
            raise ValueError(f"chunk_rays must be None or a positive int, got {chunk_rays!r}")
        self.address = address
        self.timeout = timeout
        self.chunk_rays = chunk_rays
        self._max_message_bytes = min(int(max_message_mb * _MIB), _GRPC_MAX_LENGTH)
        self._server_max_message_bytes: int | None = None
        self._channel = grpc.insecure_channel(
            address,
            options=[
                ("grpc.max_send_message_length", self._max_message_bytes),
                ("grpc.max_receive_message_length", self._max_message_bytes),
            ],
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
        #: rays_hit, brick_visits, upper_nodes_visited, proxy_tests,
        #: bricks_skipped_by_proxy, rays_traced_ahead, cache_hits,
        #: cache_misses, brick_builds, subtree_loads, subtree_writes,
        #: seconds_total, seconds_upper, seconds_brick, ...; summed over the
        #: chunks of a streamed batch), or None before the first.
        self.last_stats: dict | None = None

    # -- lifetime ---------------------------------------------------------

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "SceneClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"SceneClient({self.address!r}, timeout={self.timeout!r})"

    # -- queries ----------------------------------------------------------

    def cast_rays(self, rays, strict: bool = False) -> dict:
        """Closest hit of each ray, as Open3D's RaycastingScene.cast_rays.

        rays: (..., 6) [ox oy oz dx dy dz] or (..., 8) [... tnear tfar]
        (tnear 0, tfar inf by default), float32 preferred (other real dtypes
        are converted). Returns a dict of read-only arrays shaped like the
        batch dims: t_hit (...,) float32, inf on a miss; geometry_ids and
        primitive_ids (...,) uint32, INVALID_ID on a miss; primitive_uvs
        (..., 2) float32; primitive_normals (..., 3) float32 (unit geometric
        normal, zeros on a miss). They are views of one buffer (the reply's
        bytes when the batch fitted one message): use np.array(x) for a
        writable copy. strict: invalid rays (NaN/Inf, zero direction, bad
        tnear/tfar) raise OutcoreError INVALID_ARGUMENT naming the first bad
        ray, instead of being misses.
        """
        flat, batch_shape = as_wire_rays(rays)
        hits = self._query(_INTERSECT, flat, strict)
        return {
            "t_hit": hits["t_hit"].reshape(batch_shape),
            "geometry_ids": hits["geometry_id"].reshape(batch_shape),
            "primitive_ids": hits["primitive_id"].reshape(batch_shape),
            "primitive_uvs": hits["uv"].reshape(batch_shape + (2,)),
            "primitive_normals": hits["ng"].reshape(batch_shape + (3,)),
        }

    def test_occlusions(self, rays, strict: bool = False) -> np.ndarray:
        """Whether each ray hits anything in [tnear, tfar]: a read-only bool
        array shaped like the batch dims. Arguments as cast_rays."""
        flat, batch_shape = as_wire_rays(rays)
        occluded = self._query(_OCCLUDED, flat, strict)
        if occluded.size and occluded.max() > 1:
            raise OutcoreError("DATA_LOSS", "occlusion reply holds a byte that is neither 0 nor 1",
                               _OCCLUDED.unary)
        return occluded.view(np.bool_).reshape(batch_shape)

    def scene_info(self) -> dict:
        """The served scene (GetSceneInfo) as a dict: store_path, triangle_count,
        brick_count, bounds_lo/bounds_hi (3 floats each), inputs (list of
        {spec, triangle_count, degenerate_count}; geometry_id = index),
        cache_budget_bytes, max_message_bytes, server_version, ..."""
        info = self._call_plain(self._get_scene_info, pb.GetSceneInfoRequest(), "GetSceneInfo")
        self._server_max_message_bytes = info.max_message_bytes
        return _message_to_dict(info)

    def stats(self) -> dict:
        """Server-wide figures since start (GetStats) as a dict: requests,
        failed_requests, rays, rays_hit, invalid_rays, seconds_tracing; the
        brick cache's (cache_hits, cache_misses, brick_builds, evictions,
        resident_bytes, peak_resident_bytes, cache_budget_bytes, ...); sums
        over the requests of brick_visits, proxy_tests,
        bricks_skipped_by_proxy, rays_traced_ahead and rays_in_brick_set;
        proxy_bytes; and the
        subtree tier's (subtree_dir, "" without one, subtree_loads,
        subtree_writes, subtree_rejects, subtree_bytes_read,
        subtree_bytes_written, subtree_load_seconds, subtree_files,
        subtree_file_bytes, subtree_write_failures, subtree_writes_too_large,
        subtree_files_evicted, subtree_write_seconds; all 0 without a tier)."""
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

    def _query(self, query: _Query, rays: np.ndarray, strict: bool) -> np.ndarray:
        """Answers (n, 6|8) wire rays: an (n,) array of query.record_dtype."""
        n = rays.shape[0]
        if n == 0:
            out = np.empty(0, dtype=query.record_dtype)
            out.flags.writeable = False
            self.last_stats = None
            return out
        chunk = self._chunk_size(query, n, rays.shape[1] * 4)
        if n <= chunk:
            return self._query_unary(query, rays, strict)
        return self._query_stream(query, rays, strict, chunk)

    def _check_reply(self, query: _Query, reply: _wire.Reply, expected_rays: int, method: str,
                     sequence: int | None = None) -> None:
        problem = None
        if reply.layout_version != _wire.LAYOUT_VERSION:
            problem = f"layout_version {reply.layout_version}, expected {_wire.LAYOUT_VERSION}"
        elif reply.ray_count != expected_rays:
            problem = f"ray_count {reply.ray_count}, expected {expected_rays}"
        elif reply.payload_size != expected_rays * query.record_dtype.itemsize:
            problem = (f"{reply.payload_size} payload bytes, expected "
                       f"{expected_rays} x {query.record_dtype.itemsize}")
        elif sequence is not None and reply.sequence != sequence:
            problem = f"sequence {reply.sequence}, expected {sequence} (chunks out of order)"
        if problem:
            raise OutcoreError("DATA_LOSS", f"malformed reply: {problem}", method)

    def _query_unary(self, query: _Query, rays: np.ndarray, strict: bool) -> np.ndarray:
        request = _wire.encode_query(rays, strict=strict)
        try:
            data = self._calls[query.unary](request, timeout=self.timeout)
            reply = _wire.decode_reply(data)
        except grpc.RpcError as e:
            raise from_rpc_error(e, query.unary) from None
        except _wire.WireError as e:
            raise OutcoreError("DATA_LOSS", f"malformed reply: {e}", query.unary) from None
        self._check_reply(query, reply, rays.shape[0], query.unary)
        self.last_stats = _message_to_dict(pb.QueryStats.FromString(reply.stats))
        return reply.payload(query.record_dtype)

    def _query_stream(self, query: _Query, rays: np.ndarray, strict: bool, chunk: int) -> np.ndarray:
        n = rays.shape[0]
        starts = range(0, n, chunk)
        # Chunks are serialised lazily as gRPC asks for them, so at most a
        # few are held at once, not a second copy of the batch.
        requests = (
            _wire.encode_query(rays[start : start + chunk], strict=strict, sequence=sequence)
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
            chunk_stats = pb.QueryStats.FromString(data)
            for field in chunk_stats.DESCRIPTOR.fields:
                setattr(totals, field.name, getattr(totals, field.name) + getattr(chunk_stats, field.name))
        self.last_stats = _message_to_dict(totals)
        out.flags.writeable = False
        return out
