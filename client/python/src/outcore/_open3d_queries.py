"""Open3D's RaycastingScene calls beyond cast_rays and test_occlusions, for
SceneClient (a mixin: it uses the client's channel, timeout, message limit
and last_stats): count_intersections, list_intersections,
compute_closest_points, compute_distance, compute_signed_distance,
compute_occupancy, over the CountIntersections, ListIntersections and
QueryPoints calls (proto "Every hit and point queries"). Batches are cut
into chunks that fit a message; a list chunk whose hits do not fit is sent
again in quarters.

Thread-safety: as SceneClient.
"""

from __future__ import annotations

import grpc
import numpy as np

from . import _wire
from ._messages import add_fields
from ._messages import message_to_dict as _message_to_dict
from ._rays import as_wire_points, as_wire_rays
from .errors import OutcoreError, from_rpc_error
from .v1 import scene_query_pb2 as pb

_SERVICE = pb.DESCRIPTOR.services_by_name["SceneQuery"].full_name
# Room in a message for everything but the packed rays or points.
_MESSAGE_MARGIN = 16 * 1024
# Rays per shared-memory ListIntersections call (the server's limit).
_SHARED_LIST_RAYS = 1 << 20
# Times a shared list whose hits fit neither its segment nor a message is
# sent again with 4x the room.
_SHARED_LIST_GROWTHS = 4


# QueryPoints' CLOSEST record (proto "Point queries").
_CLOSEST_DTYPE = np.dtype([("point", "<f4", (3,)), ("geometry_id", "<u4"), ("primitive_id", "<u4"),
                           ("uv", "<f4", (2,)), ("normal", "<f4", (3,)), ("distance", "<f4")])
assert _CLOSEST_DTYPE.itemsize == 44


def _check_nthreads(nthreads) -> None:
    if isinstance(nthreads, bool) or not isinstance(nthreads, (int, np.integer)) or nthreads < 0:
        raise ValueError(f"nthreads must be an int >= 0 (it is ignored: the server decides), got {nthreads!r}")


def _check_nsamples(nsamples) -> None:
    if isinstance(nsamples, bool) or not isinstance(nsamples, (int, np.integer)) or nsamples < 1 \
            or nsamples % 2 == 0:
        raise ValueError(f"nsamples must be an odd int >= 1, got {nsamples!r}")


class Open3dQueries:
    """The calls; SceneClient provides _channel, timeout,
    _max_message_bytes, _plain_calls and _call_plain."""

    # Hits per ray of this client's last list: the room its next shared
    # list's segment gets (x 1.25); a list that outgrows it comes as bytes.
    _list_hits_per_ray = 2.0

    def count_intersections(self, rays, *, nthreads: int = 0, strict: bool = False) -> np.ndarray:
        """How many triangles each ray hits in (tnear, tfar], each once, as
        Open3D's count_intersections: an int32 array shaped like the batch
        dims. Rays as cast_rays; the dynamic layer is not seen (OutcoreError
        FAILED_PRECONDITION while it holds instances)."""
        _check_nthreads(nthreads)
        flat, batch_shape = as_wire_rays(rays)
        counts, _ = self._every_hit(flat, strict, listing=False)
        return counts.astype(np.int32).reshape(batch_shape)

    def list_intersections(self, rays, *, nthreads: int = 0, strict: bool = False) -> dict:
        """Every hit of every ray, as Open3D's list_intersections: a dict of
        ray_splits ((N+1,) uint32: ray i's hits are [ray_splits[i],
        ray_splits[i+1])), ray_ids (M,) uint32, geometry_ids and primitive_ids
        (M,) uint32, primitive_uvs (M, 2) float32 and t_hit (M,) float32, for
        N rays in C order of the batch dims; each ray's hits sorted by t, then
        ids. Rays as cast_rays."""
        _check_nthreads(nthreads)
        flat, _ = as_wire_rays(rays)
        counts, hits = self._every_hit(flat, strict, listing=True)
        splits = np.zeros(counts.size + 1, dtype=np.uint32)
        np.cumsum(counts, out=splits[1:])
        return {
            "ray_splits": splits,
            "ray_ids": np.repeat(np.arange(counts.size, dtype=np.uint32), counts),
            "geometry_ids": np.ascontiguousarray(hits["geometry_id"]),
            "primitive_ids": np.ascontiguousarray(hits["primitive_id"]),
            "primitive_uvs": np.ascontiguousarray(hits["uv"]),
            "t_hit": np.ascontiguousarray(hits["t_hit"]),
        }

    def compute_closest_points(self, query_points, *, nthreads: int = 0, strict: bool = False) -> dict:
        """The closest point of the scene to each query point, as Open3D's
        compute_closest_points: a dict of points (..., 3) float32,
        geometry_ids and primitive_ids (...,) uint32, primitive_uvs (..., 2)
        and primitive_normals (..., 3) float32, shaped like the points' batch
        dims. query_points: (..., 3) real numbers."""
        _check_nthreads(nthreads)
        records = self._points(query_points, pb.POINT_QUERY_CLOSEST, _CLOSEST_DTYPE, strict)
        shape = records.shape
        return {
            "points": np.ascontiguousarray(records["point"]).reshape(shape + (3,)),
            "geometry_ids": np.ascontiguousarray(records["geometry_id"]),
            "primitive_ids": np.ascontiguousarray(records["primitive_id"]),
            "primitive_uvs": np.ascontiguousarray(records["uv"]).reshape(shape + (2,)),
            "primitive_normals": np.ascontiguousarray(records["normal"]).reshape(shape + (3,)),
        }

    def compute_distance(self, query_points, *, nthreads: int = 0, strict: bool = False) -> np.ndarray:
        """Distance from each query point to the scene (float32, shaped like
        the points' batch dims), as Open3D's compute_distance; computed in
        float64 and rounded."""
        _check_nthreads(nthreads)
        return self._points(query_points, pb.POINT_QUERY_DISTANCE, np.dtype("<f4"), strict)

    def compute_signed_distance(self, query_points, *, nthreads: int = 0, nsamples: int = 1,
                                strict: bool = False) -> np.ndarray:
        """compute_distance, negative inside (compute_occupancy), as Open3D's
        compute_signed_distance. nsamples: accepted for Open3D's signature
        (odd, >= 1); the server's parity rule retries rays that meet an edge
        instead of voting over random ones (docs/REMOTE_API.md)."""
        _check_nthreads(nthreads)
        _check_nsamples(nsamples)
        return self._points(query_points, pb.POINT_QUERY_SIGNED_DISTANCE, np.dtype("<f4"), strict)

    def compute_occupancy(self, query_points, *, nthreads: int = 0, nsamples: int = 1,
                          strict: bool = False) -> np.ndarray:
        """1.0 for each query point inside the scene's closed surfaces, else
        0.0 (float32, as Open3D's compute_occupancy), by the parity of the
        surfaces a ray from the point crosses; exact on closed,
        non-intersecting meshes (docs/REMOTE_API.md, "Point queries")."""
        _check_nthreads(nthreads)
        _check_nsamples(nsamples)
        inside = self._points(query_points, pb.POINT_QUERY_OCCUPANCY, np.dtype("u1"), strict)
        return inside.astype(np.float32)

    def _plain_call(self, name: str, response_type, request_type=None):
        """The unary call `name`, made once; request_type None: requests
        are sent as already-serialised bytes."""
        path = f"/{_SERVICE}/{name}"
        call = self._plain_calls.get(path)
        if call is None:
            serializer = None if request_type is None else request_type.SerializeToString
            call = self._channel.unary_unary(path, request_serializer=serializer,
                                             response_deserializer=response_type.FromString)
            self._plain_calls[path] = call
        return call

    def _every_hit(self, flat: np.ndarray, strict: bool, listing: bool):
        """Counts (n,) uint32 and, when listing, the hits (HIT_DTYPE), over
        chunks that fit a message (a list chunk whose reply does not fit is
        sent again in quarters)."""
        name, response = ("ListIntersections", pb.ListResponse) if listing else \
            ("CountIntersections", pb.CountResponse)
        # Requests serialised by _wire (one copy of the rays, no message object).
        call = self._plain_call(name, response)
        n = flat.shape[0]
        # Only a server that says so takes every-hit calls through shared
        # memory (an older one refuses them as INVALID_ARGUMENT).
        if self._shared_wanted(n) and self._server_shared_every_hit:
            done = self._every_hit_shared(call, name, flat, strict, listing)
            if done is not None:
                return done
        self._last_call_shared = False
        chunk = max(1, min(n, (self._max_message_bytes - _MESSAGE_MARGIN) // (flat.shape[1] * 4), 1 << 18))
        counts, hits, stats = [], [], pb.QueryStats()
        start = 0
        while start < n:
            part = flat[start:start + chunk]
            request = _wire.encode_query(part, strict=strict)
            try:
                reply = call(request, timeout=self.timeout)
            except grpc.RpcError as e:
                if listing and e.code() == grpc.StatusCode.RESOURCE_EXHAUSTED and chunk > 1:
                    chunk = max(1, chunk // 4)
                    continue
                raise from_rpc_error(e, name) from None
            self._check_every_hit_reply(reply, part.shape[0], name, shared=False, listing=listing)
            counts.append(np.frombuffer(reply.counts, dtype="<u4"))
            if listing:
                self._check_hit_count(reply, counts[-1], name)
                hits.append(np.frombuffer(reply.hits, dtype=_wire.HIT_DTYPE))
            add_fields(stats, reply.stats)
            start += part.shape[0]
        self.last_stats = _message_to_dict(stats) if counts else None
        all_counts = np.concatenate(counts) if counts else np.zeros(0, np.uint32)
        all_hits = np.concatenate(hits) if hits else np.zeros(0, _wire.HIT_DTYPE)
        return all_counts, all_hits

    def _every_hit_shared(self, call, name: str, flat: np.ndarray, strict: bool, listing: bool):
        """_every_hit through shared segments (as cast_rays' same-host path):
        counts in one call; lists in calls of at most _SHARED_LIST_RAYS rays,
        each segment with room for the hits this client saw per ray so far
        (a list that does not fit comes back in the reply's bytes). None when
        the rays must go as bytes."""
        n = flat.shape[0]
        if not listing:
            def finish_counts(reply, segment, offset):  # a CountResponse (the call deserialises it)
                self._check_every_hit_reply(reply, n, name, shared=True, listing=False)
                return reply, segment.read_answers(np.dtype("<u4"), n, offset)

            done = self._shared_call(call, name, flat, 4 * n, finish_counts, strict=strict)
            if done is None:
                return None
            reply, counts = done
            self.last_stats = _message_to_dict(reply.stats)
            self._last_call_shared = True
            return counts, np.zeros(0, _wire.HIT_DTYPE)
        counts, hits, stats = [], [], pb.QueryStats()
        for start in range(0, n, _SHARED_LIST_RAYS):
            part = flat[start:start + _SHARED_LIST_RAYS]
            m = part.shape[0]

            def finish_list(reply, segment, offset, m=m):
                self._check_every_hit_reply(reply, m, name, shared=None, listing=True)
                if not reply.answers_in_shared:
                    return reply, np.frombuffer(reply.counts, dtype="<u4"), \
                        np.frombuffer(reply.hits, dtype=_wire.HIT_DTYPE)
                return reply, segment.read_answers(np.dtype("<u4"), m, offset), \
                    segment.read_answers(_wire.HIT_DTYPE, reply.hit_count, offset + 4 * m)

            for attempt in range(_SHARED_LIST_GROWTHS + 1):
                room = 4 * m + _wire.HIT_DTYPE.itemsize * (int(m * 1.25 * self._list_hits_per_ray) + 64)
                try:
                    done = self._shared_call(call, name, part, room, finish_list, answers_room=True,
                                             strict=strict)
                    break
                except OutcoreError as e:
                    # More hits than the room and than a message holds: a
                    # roomier segment (the part is traced again).
                    if e.code != "RESOURCE_EXHAUSTED" or attempt == _SHARED_LIST_GROWTHS:
                        raise
                    self._list_hits_per_ray = 4 * max(1.0, self._list_hits_per_ray)
            if done is None:
                return None
            reply, part_counts, part_hits = done
            self._check_hit_count(reply, part_counts, name)
            self._list_hits_per_ray = max(1.0, reply.hit_count / max(1, m))
            counts.append(part_counts)
            hits.append(part_hits)
            add_fields(stats, reply.stats)
        self.last_stats = _message_to_dict(stats)
        self._last_call_shared = True
        return np.concatenate(counts), np.concatenate(hits)

    @staticmethod
    def _check_every_hit_reply(reply, n: int, name: str, shared, listing: bool) -> None:
        """DATA_LOSS unless `reply` (a CountResponse or ListResponse) answers
        n rays, in shared memory (shared True), in its bytes (False) or
        either (None), with a list's hit bytes where its answers are."""
        in_shared = reply.answers_in_shared
        hit_bytes = len(reply.hits) if listing else 0
        problem = None
        if reply.ray_count != n:
            problem = f"ray_count {reply.ray_count} for {n} rays"
        elif shared is not None and in_shared != shared:
            problem = f"answers_in_shared {in_shared}, expected {shared}"
        elif in_shared and (reply.counts or hit_bytes):
            problem = f"{len(reply.counts) + hit_bytes} payload bytes beside answers in shared memory"
        elif not in_shared and len(reply.counts) != 4 * n:
            problem = f"{len(reply.counts)} count bytes for {n} rays"
        elif not in_shared and listing and hit_bytes != reply.hit_count * _wire.HIT_DTYPE.itemsize:
            problem = f"{hit_bytes} hit bytes for {reply.hit_count} hits"
        if problem:
            raise OutcoreError("DATA_LOSS", f"malformed reply: {problem}", name)

    @staticmethod
    def _check_hit_count(reply, counts: np.ndarray, name: str) -> None:
        """DATA_LOSS unless a list reply's hit_count is the sum of its counts."""
        if reply.hit_count != int(counts.sum(dtype=np.uint64)):
            raise OutcoreError("DATA_LOSS", "list reply's hits do not match its counts", name)

    def _points(self, query_points, kind, dtype: np.dtype, strict: bool) -> np.ndarray:
        """Answers (..., 3) points with one record of `dtype` each, shaped
        like the points' batch dims."""
        flat, batch_shape = as_wire_points(query_points)
        call = self._plain_call("QueryPoints", pb.PointResponse, pb.PointRequest)
        n = flat.shape[0]
        chunk = max(1, min(n, (self._max_message_bytes - _MESSAGE_MARGIN) // max(12, dtype.itemsize), 1 << 18))
        parts, stats = [], pb.QueryStats()
        for start in range(0, n, chunk):
            part = flat[start:start + chunk]
            request = pb.PointRequest(layout_version=1, kind=kind, point_count=part.shape[0],
                                      points=part.tobytes(), strict=strict)
            reply = self._call_plain(call, request, "QueryPoints")
            if reply.point_count != part.shape[0] or len(reply.answers) != part.shape[0] * dtype.itemsize:
                raise OutcoreError("DATA_LOSS", f"reply for {reply.point_count} points, sent {part.shape[0]}",
                                   "QueryPoints")
            parts.append(np.frombuffer(reply.answers, dtype=dtype))
            add_fields(stats, reply.stats)
        self.last_stats = _message_to_dict(stats) if parts else None
        out = np.concatenate(parts) if parts else np.zeros(0, dtype)
        return out.reshape(batch_shape)
