"""The hand-rolled codec (outcore._wire) against the generated protobuf
classes, its reference: same bytes both ways. Needs no server."""

import numpy as np
import pytest

from outcore import _wire
from outcore.v1 import scene_query_pb2 as pb


def key(field, wire_type):
    return _wire.varint(field << 3 | wire_type)


def reference_request(rays, strict=False, no_reorder=False, sequence=0):
    layout = pb.RAY_LAYOUT_F32X6 if rays.shape[1] == 6 else pb.RAY_LAYOUT_F32X8
    return pb.QueryRequest(
        batch=pb.RayBatch(layout_version=1, ray_layout=layout, ray_count=rays.shape[0], rays=rays.tobytes()),
        strict=strict,
        no_reorder=no_reorder,
        sequence=sequence,
    )


@pytest.mark.parametrize("n", [0, 1, 5, 4097])
@pytest.mark.parametrize("columns", [6, 8])
@pytest.mark.parametrize("strict,no_reorder,sequence", [(False, False, 0), (True, True, 300), (True, False, 2**40)])
def test_encode_query_parses_as_the_generated_request(n, columns, strict, no_reorder, sequence):
    rays = np.random.default_rng(n).standard_normal((n, columns)).astype("<f4")
    data = _wire.encode_query(rays, strict=strict, no_reorder=no_reorder, sequence=sequence)
    parsed = pb.QueryRequest.FromString(data)
    assert parsed == reference_request(rays, strict, no_reorder, sequence)
    # Field order matches the generated serializer, so the bytes are identical
    # too (but for n = 0, where proto3 omits the zero count; never sent).
    if n:
        assert data == reference_request(rays, strict, no_reorder, sequence).SerializeToString()


def test_layout_constants_match_the_proto():
    assert _wire.RAY_LAYOUT_F32X8 == pb.RAY_LAYOUT_F32X8
    assert _wire.RAY_LAYOUT_F32X6 == pb.RAY_LAYOUT_F32X6
    fields = pb.IntersectResponse.DESCRIPTOR.fields_by_name
    assert [fields[name].number for name in ("layout_version", "ray_count", "hits", "sequence", "stats")] == [1, 2, 3, 4, 5]
    fields = pb.OccludedResponse.DESCRIPTOR.fields_by_name
    assert [fields[name].number for name in ("layout_version", "ray_count", "occluded", "sequence", "stats")] == [1, 2, 3, 4, 5]


@pytest.mark.parametrize("n", [0, 1, 1000])
def test_decode_reply_reads_the_generated_intersect_response(n):
    hits = np.zeros(n, dtype=_wire.HIT_DTYPE)
    rng = np.random.default_rng(7)
    hits["t_hit"] = rng.random(n)
    hits["primitive_id"] = rng.integers(0, 2**32 - 1, n)
    hits["ng"] = rng.random((n, 3))
    stats = pb.QueryStats(rays=n, cache_hits=3, seconds_total=0.25)
    message = pb.IntersectResponse(layout_version=1, ray_count=n, hits=hits.tobytes(), sequence=9, stats=stats)
    reply = _wire.decode_reply(message.SerializeToString())
    assert (reply.layout_version, reply.ray_count, reply.sequence) == (1, n, 9)
    assert pb.QueryStats.FromString(reply.stats) == stats
    decoded = reply.payload(_wire.HIT_DTYPE)
    assert decoded.tobytes() == hits.tobytes()
    assert not decoded.flags.writeable  # a view of the reply's bytes


def test_decode_reply_reads_occluded_response_and_skips_unknown_fields():
    message = pb.OccludedResponse(layout_version=1, ray_count=3, occluded=b"\x01\x00\x01")
    # Unknown fields of every wire type a newer server might add.
    extra = key(99, 0) + b"\x05" + key(98, 1) + b"\0" * 8 + key(97, 5) + b"\0" * 4
    extra += key(96, 2) + b"\x02ab"
    reply = _wire.decode_reply(message.SerializeToString() + extra)
    assert reply.ray_count == 3
    assert reply.payload(np.uint8).tolist() == [1, 0, 1]


@pytest.mark.parametrize(
    "data",
    [
        bytes([2 << 3 | 0, 0x80]),  # varint cut short
        bytes([3 << 3 | 2, 10]) + b"abc",  # length past the end
        bytes([3 << 3 | 3]),  # group wire type
        bytes([1 << 3 | 0]) + b"\xff" * 11,  # overlong varint
        key(99, 1) + b"\0" * 3,  # fixed64 cut short
    ],
)
def test_decode_reply_rejects_malformed_bytes(data):
    with pytest.raises(_wire.WireError):
        _wire.decode_reply(data)
