"""Replies that carry only some hit fields (QueryRequest.hit_fields, issue 29):
t or t and ids are bitwise the same as the full records' fields over the
unary call, the stream and the shared-memory path, from the Python client and
the C++ client (`outcore query --hit-fields`); bad values are refused."""

from __future__ import annotations

import subprocess

import grpc
import numpy as np
import pytest

import outcore
from outcore import _wire
from support import binary, make_rays


@pytest.fixture(scope="module")
def rays(bounds):
    return make_rays(bounds, 50000, seed=2929)


@pytest.mark.parametrize("path", ["unary", "stream", "shared"])
def test_fewer_fields_are_the_full_records_fields(server, rays, path):
    options = {"unary": dict(shared_memory=False), "stream": dict(chunk_rays=6000),
               "shared": dict(shared_memory=True)}[path]
    with outcore.SceneClient(server.address, timeout=60, **options) as client:
        full = client.cast_rays(rays)
        assert client.last_call_shared == (path == "shared")
        t_only = client.cast_rays(rays, hit_fields="t")
        t_ids = client.cast_rays(rays, hit_fields="t_ids")
    assert set(t_only) == {"t_hit"}
    assert set(t_ids) == {"t_hit", "geometry_ids", "primitive_ids"}
    assert np.isfinite(full["t_hit"]).sum() > 1000
    for answer in (t_only, t_ids):
        for key, values in answer.items():
            np.testing.assert_array_equal(values, full[key])


def test_fewer_fields_cut_the_reply_bytes(server, rays):
    with grpc.insecure_channel(server.address) as channel:
        call = channel.unary_unary("/outcore.v1.SceneQuery/Intersect")
        sizes = {}
        for fields in (_wire.HIT_FIELDS_ALL, _wire.HIT_FIELDS_T_IDS, _wire.HIT_FIELDS_T):
            reply = _wire.decode_reply(call(_wire.encode_query(rays[:1000], hit_fields=fields), timeout=30))
            sizes[fields] = reply.payload_size
    assert sizes == {_wire.HIT_FIELDS_ALL: 32000, _wire.HIT_FIELDS_T_IDS: 12000, _wire.HIT_FIELDS_T: 4000}


def test_bad_hit_fields_are_refused(server, rays):
    with grpc.insecure_channel(server.address) as channel:
        for method, fields, words in (("Intersect", 7, "not a HitFields value"),
                                      ("Occluded", _wire.HIT_FIELDS_T, "applies to Intersect only")):
            with pytest.raises(grpc.RpcError) as error:
                channel.unary_unary(f"/outcore.v1.SceneQuery/{method}")(
                    _wire.encode_query(rays[:10], hit_fields=fields), timeout=30)
            assert error.value.code() == grpc.StatusCode.INVALID_ARGUMENT and words in error.value.details()
        # A stream keeps its first chunk's fields.
        chunks = [_wire.encode_query(rays[:10], hit_fields=_wire.HIT_FIELDS_T),
                  _wire.encode_query(rays[10:20], sequence=1, hit_fields=_wire.HIT_FIELDS_ALL)]
        replies = channel.stream_stream("/outcore.v1.SceneQuery/IntersectStream")(iter(chunks), timeout=30)
        with pytest.raises(grpc.RpcError) as error:
            list(replies)
        assert "one set of fields a stream" in error.value.details()
    with pytest.raises(ValueError, match="hit_fields"):
        with outcore.SceneClient(server.address) as client:
            client.cast_rays(rays[:3], hit_fields="normals")


@pytest.mark.parametrize("fields", ["t", "t,ids"])
def test_the_cpp_client_fills_the_fields_asked_and_a_miss_elsewhere(server, rays, tmp_path, fields):
    np.save(tmp_path / "rays.npy", rays)
    outputs = {}
    for asked in ("all", fields):
        out = tmp_path / f"hits-{asked}.npy"
        result = subprocess.run([str(binary()), "query", "--server", server.address, "--rays",
                                 str(tmp_path / "rays.npy"), "-o", str(out), "--no-shared-memory", "--chunk-rays",
                                 "20000", "--hit-fields", asked], capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
        outputs[asked] = np.load(out)
    full, short = outputs["all"], outputs[fields]
    np.testing.assert_array_equal(short["t_hit"], full["t_hit"])
    if fields == "t,ids":
        np.testing.assert_array_equal(short["geometry_id"], full["geometry_id"])
        np.testing.assert_array_equal(short["primitive_id"], full["primitive_id"])
    else:
        assert (short["primitive_id"] == 0xFFFFFFFF).all()
    assert (short["u"] == 0).all() and (short["ng"] == 0).all()
