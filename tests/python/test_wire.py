"""The hand-rolled codec (outcore._wire) against the generated protobuf
classes, its reference: same bytes both ways. Needs no server."""

import numpy as np
import pytest

from outcore import _wire
from outcore.v1 import scene_query_pb2 as pb


def key(field, wire_type):
    return _wire.varint(field << 3 | wire_type)


def reference_request(rays, strict=False, no_reorder=False, sequence=0, shared=None):
    layout = pb.RAY_LAYOUT_F32X6 if rays.shape[1] == 6 else pb.RAY_LAYOUT_F32X8
    request = pb.QueryRequest(
        batch=pb.RayBatch(layout_version=1, ray_layout=layout, ray_count=rays.shape[0],
                          rays=b"" if shared else rays.tobytes()),
        strict=strict,
        no_reorder=no_reorder,
        sequence=sequence,
    )
    if shared is not None:
        request.shared.CopyFrom(pb.SharedPayload(name=shared.name, rays_offset=shared.rays_offset,
                                                 answers_offset=shared.answers_offset, token=shared.token))
    return request


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


@pytest.mark.parametrize("n", [1, 16_384, 300_001])
@pytest.mark.parametrize("columns", [6, 8])
@pytest.mark.parametrize(
    "shared",
    [_wire.SharedRef("/outcore-py-12-0123456789abcdef", 0, 1 << 20, bytes(range(16))),
     _wire.SharedRef("/outcore-x", 64, 0),  # zero offsets and an empty token are omitted, as proto3 does
     _wire.SharedRef("/outcore-" + "a" * 200, 2**40, 2**41 + 64, b"\xff" * 16)],
)
def test_encode_query_with_a_shared_payload_parses_as_the_generated_request(n, columns, shared):
    rays = np.zeros((n, columns), "<f4")
    data = _wire.encode_query(rays, strict=True, shared=shared)
    parsed = pb.QueryRequest.FromString(data)
    assert parsed.HasField("shared")
    assert parsed.batch.rays == b"" and parsed.batch.ray_count == n
    assert parsed == reference_request(rays, True, shared=shared)
    assert data == reference_request(rays, True, shared=shared).SerializeToString()
    assert len(data) < 300  # no rays: the message is tiny whatever the batch


def test_encode_query_with_an_empty_shared_payload_still_sends_the_field():
    # proto3 submessage presence: an all-default SharedPayload is still "set".
    rays = np.zeros((3, 6), "<f4")
    parsed = pb.QueryRequest.FromString(_wire.encode_query(rays, shared=_wire.SharedRef("")))
    assert parsed.HasField("shared") and parsed.shared == pb.SharedPayload()


def test_shared_payload_field_numbers_match_the_proto():
    assert pb.QueryRequest.DESCRIPTOR.fields_by_name["shared"].number == 5
    fields = pb.SharedPayload.DESCRIPTOR.fields_by_name
    assert [fields[name].number for name in ("name", "rays_offset", "answers_offset", "token")] == [1, 2, 3, 4]
    for message in (pb.IntersectResponse, pb.OccludedResponse):
        assert message.DESCRIPTOR.fields_by_name["answers_in_shared"].number == 6
    assert pb.SceneInfo.DESCRIPTOR.fields_by_name["shared_payloads"].number == 16


@pytest.mark.parametrize("message_type", [pb.IntersectResponse, pb.OccludedResponse])
def test_decode_reply_reads_answers_in_shared(message_type):
    stats = pb.QueryStats(rays=20_000, rays_hit=7)
    message = message_type(layout_version=1, ray_count=20_000, stats=stats, answers_in_shared=True)
    reply = _wire.decode_reply(message.SerializeToString())
    assert reply.answers_in_shared
    assert (reply.layout_version, reply.ray_count, reply.payload_size) == (1, 20_000, 0)
    assert pb.QueryStats.FromString(reply.stats) == stats
    plain = message_type(layout_version=1, ray_count=1).SerializeToString()
    assert not _wire.decode_reply(plain).answers_in_shared


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


def test_hit_fields_encode_as_the_generated_request_and_match_the_proto():
    assert (_wire.HIT_FIELDS_ALL, _wire.HIT_FIELDS_T, _wire.HIT_FIELDS_T_IDS) == (
        pb.HIT_FIELDS_ALL, pb.HIT_FIELDS_T, pb.HIT_FIELDS_T_IDS)
    rays = np.random.default_rng(3).standard_normal((7, 6)).astype("<f4")
    for fields in (pb.HIT_FIELDS_T, pb.HIT_FIELDS_T_IDS):
        parsed = pb.QueryRequest.FromString(_wire.encode_query(rays, hit_fields=fields))
        expected = reference_request(rays)
        expected.hit_fields = fields
        assert parsed == expected
    # The short records are the whole record's leading fields.
    assert _wire.HIT_T_IDS_DTYPE.names == _wire.HIT_DTYPE.names[:3]
    assert _wire.HIT_T_DTYPE.names == _wire.HIT_DTYPE.names[:1]
