"""Hand-rolled protobuf codec for the two hot messages: QueryRequest out,
IntersectResponse/OccludedResponse in (proto/outcore/v1/scene_query.proto).

Why not the generated classes: they copy the packed ray/hit bytes two or three
times (into the message, out of it into a new bytes object). Here a request is
built with one copy (the rays straight into the serialised bytes) and a reply's
payload is handed to numpy as a zero-copy view of the bytes gRPC received.
A request with a shared payload (SharedPayload, field 5) carries no rays
bytes at all, and its reply no answers (answers_in_shared, field 6).
Everything else (scene info, stats, per-request QueryStats) uses the generated
classes. tests/python/test_wire.py checks this codec against them.

Thread-safety: pure functions.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

LAYOUT_VERSION = 1
RAY_LAYOUT_F32X8 = 1
RAY_LAYOUT_F32X6 = 2

# One 32-byte hit record (layout version 1). u and v are adjacent, so one
# (2,) field gives Open3D's (N, 2) primitive_uvs as a view.
HIT_DTYPE = np.dtype(
    [
        ("t_hit", "<f4"),
        ("geometry_id", "<u4"),
        ("primitive_id", "<u4"),
        ("uv", "<f4", (2,)),
        ("ng", "<f4", (3,)),
    ]
)
assert HIT_DTYPE.itemsize == 32
# The shorter records of QueryRequest.hit_fields (HIT_FIELDS_T = 1,
# HIT_FIELDS_T_IDS = 2): a hit record's leading fields, packed.
HIT_FIELDS_ALL, HIT_FIELDS_T, HIT_FIELDS_T_IDS = 0, 1, 2
HIT_T_DTYPE = np.dtype([("t_hit", "<f4")])
HIT_T_IDS_DTYPE = np.dtype([("t_hit", "<f4"), ("geometry_id", "<u4"), ("primitive_id", "<u4")])
assert HIT_T_IDS_DTYPE.itemsize == 12

# Wire types and tags (field_number << 3 | wire_type).
_VARINT, _I64, _LEN, _I32 = 0, 1, 2, 5
_TAG_REQUEST_BATCH = bytes([1 << 3 | _LEN])
_TAG_REQUEST_STRICT = bytes([2 << 3 | _VARINT])
_TAG_REQUEST_NO_REORDER = bytes([3 << 3 | _VARINT])
_TAG_REQUEST_SEQUENCE = bytes([4 << 3 | _VARINT])
_TAG_REQUEST_SHARED = bytes([5 << 3 | _LEN])
_TAG_REQUEST_DYNAMIC_VERSION = bytes([6 << 3 | _VARINT])
_TAG_REQUEST_HIT_FIELDS = bytes([7 << 3 | _VARINT])
_TAG_REQUEST_ONLY_BRICKS = bytes([8 << 3 | 2])  # packed uint32
_TAG_BATCH_VERSION = bytes([1 << 3 | _VARINT])
_TAG_BATCH_LAYOUT = bytes([2 << 3 | _VARINT])
_TAG_BATCH_COUNT = bytes([3 << 3 | _VARINT])
_TAG_BATCH_RAYS = bytes([4 << 3 | _LEN])
_TAG_SHARED_NAME = bytes([1 << 3 | _LEN])
_TAG_SHARED_RAYS_OFFSET = bytes([2 << 3 | _VARINT])
_TAG_SHARED_ANSWERS_OFFSET = bytes([3 << 3 | _VARINT])
_TAG_SHARED_TOKEN = bytes([4 << 3 | _LEN])
_TAG_SHARED_ANSWERS_BYTES = bytes([5 << 3 | _VARINT])
# Reply fields (same numbers in IntersectResponse and OccludedResponse).
_REPLY_VERSION, _REPLY_COUNT, _REPLY_PAYLOAD, _REPLY_SEQUENCE, _REPLY_STATS = 1, 2, 3, 4, 5
_REPLY_ANSWERS_IN_SHARED = 6
_REPLY_DYNAMIC_VERSION = 7


class SharedRef(NamedTuple):
    """A request's SharedPayload: the shared-memory object's name (with the
    leading '/'), the byte offsets of the rays and of the answers in it, the
    token in its header, and the answers' room (ListIntersections only)."""

    name: str
    rays_offset: int = 0
    answers_offset: int = 0
    token: bytes = b""
    answers_bytes: int = 0


class WireError(ValueError):
    """A reply that does not parse as the message it should be."""


def varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _encode_shared(shared: SharedRef) -> bytes:
    name = shared.name.encode("utf-8")
    parts = []
    # proto3: zero values are omitted; the submessage itself is always sent.
    if name:
        parts += [_TAG_SHARED_NAME, varint(len(name)), name]
    if shared.rays_offset:
        parts += [_TAG_SHARED_RAYS_OFFSET, varint(shared.rays_offset)]
    if shared.answers_offset:
        parts += [_TAG_SHARED_ANSWERS_OFFSET, varint(shared.answers_offset)]
    if shared.token:
        parts += [_TAG_SHARED_TOKEN, varint(len(shared.token)), bytes(shared.token)]
    if shared.answers_bytes:
        parts += [_TAG_SHARED_ANSWERS_BYTES, varint(shared.answers_bytes)]
    body = b"".join(parts)
    return b"".join((_TAG_REQUEST_SHARED, varint(len(body)), body))


def encode_query(
    rays: np.ndarray,
    strict: bool = False,
    no_reorder: bool = False,
    sequence: int = 0,
    shared: SharedRef | None = None,
    dynamic_version: int | None = None,
    hit_fields: int = HIT_FIELDS_ALL,
    only_bricks=None,
) -> bytes:
    """Serialises a QueryRequest for C-contiguous (n, 6|8) '<f4' rays. With
    `shared` the rays are not copied in (batch.rays is omitted: they are in
    the shared object); `rays` then only gives the count and layout."""
    n, columns = rays.shape
    layout = RAY_LAYOUT_F32X6 if columns == 6 else RAY_LAYOUT_F32X8
    head = [
        _TAG_BATCH_VERSION, varint(LAYOUT_VERSION),
        _TAG_BATCH_LAYOUT, varint(layout),
        _TAG_BATCH_COUNT, varint(n),
    ]
    if shared is None:
        payload = memoryview(rays.reshape(-1).view(np.uint8))
        head += [_TAG_BATCH_RAYS, varint(payload.nbytes)]
        payload_bytes = payload.nbytes
    else:
        payload, payload_bytes = b"", 0
    batch_head = b"".join(head)
    parts = [_TAG_REQUEST_BATCH, varint(len(batch_head) + payload_bytes), batch_head, payload]
    if strict:
        parts += [_TAG_REQUEST_STRICT, b"\x01"]
    if no_reorder:
        parts += [_TAG_REQUEST_NO_REORDER, b"\x01"]
    if sequence:
        parts += [_TAG_REQUEST_SEQUENCE, varint(sequence)]
    if shared is not None:
        parts.append(_encode_shared(shared))
    if dynamic_version is not None:
        parts += [_TAG_REQUEST_DYNAMIC_VERSION, varint(dynamic_version)]
    if hit_fields:
        parts += [_TAG_REQUEST_HIT_FIELDS, varint(hit_fields)]
    if only_bricks is not None and len(only_bricks):
        packed = b"".join(varint(int(b)) for b in only_bricks)
        parts += [_TAG_REQUEST_ONLY_BRICKS, varint(len(packed)), packed]
    return b"".join(parts)


class Reply:
    """A parsed IntersectResponse/OccludedResponse; the payload stays in `data`."""

    __slots__ = ("data", "layout_version", "ray_count", "payload_offset", "payload_size", "sequence", "stats",
                 "answers_in_shared", "dynamic_version")

    def __init__(self, data: bytes):
        self.data = data
        self.layout_version = 0
        self.ray_count = 0
        self.payload_offset = 0
        self.payload_size = 0
        self.sequence = 0
        self.stats = b""  # serialised QueryStats
        self.answers_in_shared = False  # the answers are in the request's shared object
        self.dynamic_version = 0  # the dynamic layer's version the answers saw

    def payload(self, dtype: np.dtype) -> np.ndarray:
        """The hits/occluded bytes as a read-only view of `data` (no copy)."""
        dtype = np.dtype(dtype)
        return np.frombuffer(
            self.data, dtype=dtype, count=self.payload_size // dtype.itemsize, offset=self.payload_offset
        )


def _read_varint(data: bytes, pos: int) -> tuple[int, int]:
    result = 0
    shift = 0
    end = len(data)
    while True:
        if pos >= end:
            raise WireError("reply ends inside a varint")
        byte = data[pos]
        pos += 1
        result |= (byte & 0x7F) << shift
        if byte < 0x80:
            return result, pos
        shift += 7
        if shift >= 64:
            raise WireError("reply has a varint longer than 10 bytes")


def decode_reply(data: bytes) -> Reply:
    """Parses an IntersectResponse or OccludedResponse (unknown fields skipped)."""
    reply = Reply(data)
    pos = 0
    end = len(data)
    while pos < end:
        key, pos = _read_varint(data, pos)
        field, wire_type = key >> 3, key & 7
        if wire_type == _VARINT:
            value, pos = _read_varint(data, pos)
            if field == _REPLY_VERSION:
                reply.layout_version = value
            elif field == _REPLY_COUNT:
                reply.ray_count = value
            elif field == _REPLY_SEQUENCE:
                reply.sequence = value
            elif field == _REPLY_ANSWERS_IN_SHARED:
                reply.answers_in_shared = value != 0
            elif field == _REPLY_DYNAMIC_VERSION:
                reply.dynamic_version = value
        elif wire_type == _LEN:
            size, pos = _read_varint(data, pos)
            if pos + size > end:
                raise WireError(f"reply field {field} claims {size} bytes but only {end - pos} remain")
            if field == _REPLY_PAYLOAD:
                reply.payload_offset, reply.payload_size = pos, size
            elif field == _REPLY_STATS:
                reply.stats = data[pos : pos + size]
            pos += size
        elif wire_type == _I64:
            pos += 8
        elif wire_type == _I32:
            pos += 4
        else:
            raise WireError(f"reply field {field} has unsupported wire type {wire_type}")
        if pos > end:
            raise WireError(f"reply field {field} runs past the end of the message")
    return reply
