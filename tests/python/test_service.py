"""Running `outcore serve` as a service (issue 29), end to end with the real
binary: the Prometheus endpoint and status page scraped over HTTP, JSON logs,
TLS (self-signed CA made with openssl) and mutual TLS, the bearer token on
every SceneQuery method (health exempt), the refusal to serve plaintext on a
non-loopback address, and `outcore health` / `outcore query` with the same
security flags (the C++ client).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import urllib.error
import urllib.request
from pathlib import Path

import grpc
import numpy as np
import pytest

import outcore
from outcore.v1 import scene_query_pb2 as pb
from support import Server, binary, make_rays

_METRICS = re.compile(r"metrics on http://(\S+)")
_SAMPLE = re.compile(r'^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{.*\})? (\S+)$')


def _metrics_address(server: Server) -> str:
    for line in server.lines:
        match = _METRICS.search(line)
        if match:
            return match.group(1)
    raise AssertionError("no 'metrics on' line:\n" + "".join(server.lines))


def _get(url: str) -> tuple[int, str, str]:
    with urllib.request.urlopen(url, timeout=10) as reply:
        return reply.status, reply.headers.get("Content-Type", ""), reply.read().decode()


def _samples(text: str) -> dict[str, float]:
    """Every sample line of a Prometheus text exposition, by 'name{labels}';
    fails on a line that is neither a comment nor a well-formed sample."""
    samples = {}
    for line in text.splitlines():
        if not line or line.startswith("# HELP ") or line.startswith("# TYPE "):
            continue
        match = _SAMPLE.match(line)
        assert match, f"not a Prometheus sample line: {line!r}"
        samples[match.group(1) + (match.group(2) or "")] = float(match.group(3))
    return samples


@pytest.fixture(scope="module")
def metrics_server(store):
    server = Server(store, "--metrics-listen", "127.0.0.1:0", "--log-format", "json")
    yield server
    assert server.stop() == 0, "".join(server.lines)


def test_metrics_endpoint_counts_calls_rays_and_cache(metrics_server, bounds):
    rays = make_rays(bounds, 5000, seed=29)
    with outcore.SceneClient(metrics_server.address, timeout=30, shared_memory=False) as client:
        hits = client.cast_rays(rays)
        with pytest.raises(outcore.OutcoreError):
            client.cast_rays(np.zeros((3, 6), np.float32), strict=True)  # zero directions
    status, content_type, text = _get(f"http://{_metrics_address(metrics_server)}/metrics")
    assert status == 200 and content_type.startswith("text/plain; version=0.0.4")
    samples = _samples(text)
    intersect = 'method="outcore.v1.SceneQuery/Intersect"'
    assert samples[f'outcore_requests_total{{{intersect},code="OK"}}'] >= 1
    assert samples[f'outcore_requests_total{{{intersect},code="INVALID_ARGUMENT"}}'] >= 1
    assert samples["outcore_rays_total"] >= 5000
    assert samples["outcore_rays_hit_total"] >= np.count_nonzero(np.isfinite(hits["t_hit"])) > 0
    assert samples["outcore_brick_builds_total"] >= 1
    assert samples["outcore_cache_misses_total"] >= 1
    assert samples["outcore_cache_budget_bytes"] > 0
    assert 0 < samples["outcore_cache_resident_bytes"] <= samples["outcore_cache_budget_bytes"]
    for name in ("outcore_cache_hits_total", "outcore_cache_evictions_total", "outcore_subtree_loads_total"):
        assert name in samples
    # The histogram: cumulative buckets ending in +Inf == count.
    buckets = [(k, v) for k, v in samples.items()
               if k.startswith("outcore_request_seconds_bucket{") and intersect in k]
    values = [v for _, v in buckets]
    assert values == sorted(values) and buckets[-1][0].endswith('le="+Inf"}')
    assert values[-1] == samples[f"outcore_request_seconds_count{{{intersect}}}"]
    assert samples[f"outcore_request_seconds_sum{{{intersect}}}"] > 0


def test_status_page_shows_scene_cache_and_throughput(metrics_server, store):
    status, content_type, html = _get(f"http://{_metrics_address(metrics_server)}/")
    assert status == 200 and content_type.startswith("text/html")
    for text in (str(store), "Cache", "fill", "Throughput", "rays/s", "policy", "/metrics"):
        assert text in html
    with pytest.raises(urllib.error.HTTPError) as missing:
        _get(f"http://{_metrics_address(metrics_server)}/nothing-here")
    assert missing.value.code == 404


def test_json_logs_are_one_object_per_line(metrics_server):
    logged = [line for line in metrics_server.lines if line.startswith("{")]
    assert logged, "".join(metrics_server.lines)
    for line in logged:
        record = json.loads(line)
        assert set(record) == {"time", "level", "logger", "message"}
        assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z", record["time"])
    assert any("serving" in json.loads(line)["message"] for line in logged)


def test_plaintext_on_a_non_loopback_address_is_refused_unless_insecure(store):
    refused = subprocess.run([str(binary()), "serve", str(store), "--listen", "0.0.0.0:0"],
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode != 0
    assert "--tls-cert" in refused.stderr and "--insecure" in refused.stderr
    server = Server(store, "--listen", "0.0.0.0:0", "--insecure")
    try:
        port = server.address.rsplit(":", 1)[1]
        with outcore.SceneClient(f"127.0.0.1:{port}", timeout=30) as client:
            assert client.scene_info()["triangle_count"] > 0
    finally:
        assert server.stop() == 0


# ---- the bearer token ----------------------------------------------------

@pytest.fixture(scope="module")
def token_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("token") / "token"
    path.write_text("s3cret-Token_29\n")
    return path


@pytest.fixture(scope="module")
def token_server(store, token_file):
    server = Server(store, "--auth-token-file", token_file)
    yield server
    assert server.stop() == 0, "".join(server.lines)


def test_every_scene_query_method_needs_the_token(token_server):
    service = pb.DESCRIPTOR.services_by_name["SceneQuery"]
    assert len(service.methods) >= 14
    with grpc.insecure_channel(token_server.address) as channel:
        for method in service.methods:
            path = f"/{service.full_name}/{method.name}"
            for metadata in ((), (("authorization", "Bearer wrong"),), (("authorization", "s3cret-Token_29"),)):
                if method.client_streaming:
                    call = channel.stream_stream(path)(iter([b""]), timeout=10, metadata=metadata)
                    with pytest.raises(grpc.RpcError) as error:
                        list(call)
                else:
                    with pytest.raises(grpc.RpcError) as error:
                        channel.unary_unary(path)(b"", timeout=10, metadata=metadata)
                assert error.value.code() == grpc.StatusCode.UNAUTHENTICATED, (path, metadata)


def test_health_needs_no_token_and_the_right_token_answers(token_server, token_file, bounds, store, tmp_path):
    health = subprocess.run([str(binary()), "health", "--server", token_server.address],
                            capture_output=True, text=True, timeout=60)
    assert health.returncode == 0 and "SERVING" in health.stdout, health.stderr
    rays = make_rays(bounds, 3000, seed=7)
    with outcore.SceneClient(token_server.address, timeout=30) as client:
        with pytest.raises(outcore.OutcoreError, match="UNAUTHENTICATED"):
            client.scene_info()
    with outcore.SceneClient(token_server.address, timeout=30, token="wrong") as client:
        with pytest.raises(outcore.OutcoreError, match="UNAUTHENTICATED"):
            client.cast_rays(rays)
    with outcore.SceneClient(token_server.address, timeout=30, token="s3cret-Token_29") as client:
        with_token = client.cast_rays(rays)
        big = make_rays(bounds, 40000, seed=8)
        streamed = outcore.SceneClient(token_server.address, timeout=30, token="s3cret-Token_29",
                                       chunk_rays=7000)
        with streamed:
            np.testing.assert_array_equal(streamed.cast_rays(big)["t_hit"], client.cast_rays(big)["t_hit"])
        assert client.count_intersections(rays).shape == (3000,)
    # The C++ client (outcore query) with and without the token file.
    rays_path, out_path = tmp_path / "rays.npy", tmp_path / "hits.npy"
    np.save(rays_path, rays)
    query = [str(binary()), "query", "--server", token_server.address, "--rays", str(rays_path), "-o", str(out_path)]
    refused = subprocess.run(query, capture_output=True, text=True, timeout=60)
    assert refused.returncode != 0 and "UNAUTHENTICATED" in refused.stderr
    accepted = subprocess.run(query + ["--auth-token-file", str(token_file)], capture_output=True, text=True,
                              timeout=60)
    assert accepted.returncode == 0, accepted.stderr
    np.testing.assert_array_equal(np.load(out_path)["t_hit"], with_token["t_hit"])


def test_bad_token_files_and_tokens_are_named(store, tmp_path):
    empty = tmp_path / "empty"
    empty.write_text("\n")
    spaced = tmp_path / "spaced"
    spaced.write_text("two words\n")
    for path, words in ((empty, "is empty"), (spaced, "space or control character"),
                        (tmp_path / "missing", "missing")):
        result = subprocess.run([str(binary()), "serve", str(store), "--listen", "127.0.0.1:0",
                                 "--auth-token-file", str(path)], capture_output=True, text=True, timeout=60)
        assert result.returncode != 0 and "--auth-token-file" in result.stderr and words in result.stderr
    with pytest.raises(ValueError, match="token"):
        outcore.SceneClient("127.0.0.1:1", token="two words")


# ---- TLS -----------------------------------------------------------------

def _openssl(*args, cwd: Path):
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


@pytest.fixture(scope="module")
def pki(tmp_path_factory) -> Path:
    """A CA, a server certificate for 127.0.0.1/localhost and a client
    certificate, both signed by it; and a second, unrelated CA."""
    if shutil.which("openssl") is None:
        pytest.fail("openssl is needed for the TLS tests (scripts/install.sh installs it)")
    d = tmp_path_factory.mktemp("pki")
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    for ca in ("ca", "other-ca"):
        _openssl("req", "-x509", *ec, "-keyout", f"{ca}.key", "-out", f"{ca}.pem", "-days", "2",
                 "-subj", f"/CN=outcore test {ca}", "-addext", "basicConstraints=critical,CA:TRUE",
                 "-addext", "keyUsage=critical,keyCertSign,cRLSign", cwd=d)
    for name, extensions in (("server", "subjectAltName=IP:127.0.0.1,DNS:localhost\nextendedKeyUsage=serverAuth\n"),
                             ("client", "extendedKeyUsage=clientAuth\n")):
        (d / f"{name}.ext").write_text(extensions)
        _openssl("req", *ec, "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN=outcore {name}",
                 cwd=d)
        _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
                 "-out", f"{name}.pem", "-days", "2", "-extfile", f"{name}.ext", cwd=d)
    return d


def test_tls_serves_clients_that_trust_its_ca_only(store, pki, bounds, tmp_path):
    server = Server(store, "--tls-cert", pki / "server.pem", "--tls-key", pki / "server.key")
    try:
        rays = make_rays(bounds, 4000, seed=11)
        with outcore.SceneClient(server.address, timeout=30, tls_ca=pki / "ca.pem") as client:
            hits = client.cast_rays(rays)
            assert np.isfinite(hits["t_hit"]).any()
        with outcore.SceneClient(server.address, timeout=5) as plaintext:
            with pytest.raises(outcore.OutcoreError, match="UNAVAILABLE"):
                plaintext.scene_info()
        with outcore.SceneClient(server.address, timeout=5, tls_ca=pki / "other-ca.pem") as untrusting:
            with pytest.raises(outcore.OutcoreError, match="UNAVAILABLE"):
                untrusting.scene_info()
        health = [str(binary()), "health", "--server", server.address]
        assert subprocess.run(health + ["--tls-ca", str(pki / "ca.pem")], capture_output=True,
                              timeout=60).returncode == 0
        assert subprocess.run(health + ["--timeout-s", "3"], capture_output=True, timeout=60).returncode != 0
        rays_path, out_path = tmp_path / "rays.npy", tmp_path / "hits.npy"
        np.save(rays_path, rays)
        query = subprocess.run([str(binary()), "query", "--server", server.address, "--rays", str(rays_path),
                                "-o", str(out_path), "--tls-ca", str(pki / "ca.pem")],
                               capture_output=True, text=True, timeout=60)
        assert query.returncode == 0, query.stderr
        np.testing.assert_array_equal(np.load(out_path)["t_hit"], hits["t_hit"])
    finally:
        assert server.stop() == 0, "".join(server.lines)


def test_mutual_tls_requires_a_client_certificate(store, pki, bounds):
    server = Server(store, "--tls-cert", pki / "server.pem", "--tls-key", pki / "server.key",
                    "--tls-client-ca", pki / "ca.pem")
    try:
        with outcore.SceneClient(server.address, timeout=5, tls_ca=pki / "ca.pem") as anonymous:
            with pytest.raises(outcore.OutcoreError, match="UNAVAILABLE"):
                anonymous.scene_info()
        with outcore.SceneClient(server.address, timeout=30, tls_ca=pki / "ca.pem", tls_cert=pki / "client.pem",
                                 tls_key=(pki / "client.key").read_bytes()) as client:
            assert client.cast_rays(make_rays(bounds, 100, seed=3))["t_hit"].shape == (100,)
        health = subprocess.run([str(binary()), "health", "--server", server.address, "--tls-ca", str(pki / "ca.pem"),
                                 "--tls-cert", str(pki / "client.pem"), "--tls-key", str(pki / "client.key")],
                                capture_output=True, text=True, timeout=60)
        assert health.returncode == 0, health.stderr
    finally:
        assert server.stop() == 0, "".join(server.lines)


def test_bad_tls_files_are_named(store, pki, tmp_path):
    not_pem = tmp_path / "not.pem"
    not_pem.write_text("hello\n")
    cases = [
        (["--tls-cert", pki / "server.pem"], "--tls-key"),
        (["--tls-key", pki / "server.key"], "--tls-cert"),
        (["--tls-cert", not_pem, "--tls-key", pki / "server.key"], str(not_pem)),
        (["--tls-cert", pki / "server.pem", "--tls-key", tmp_path / "missing.key"], "missing.key"),
        (["--tls-client-ca", pki / "ca.pem"], "--tls-client-ca"),
    ]
    for extra, words in cases:
        result = subprocess.run([str(binary()), "serve", str(store), "--listen", "127.0.0.1:0", *map(str, extra)],
                                capture_output=True, text=True, timeout=60)
        assert result.returncode != 0 and words in result.stderr, (extra, result.stderr)
    with pytest.raises(ValueError, match="tls_ca"):
        outcore.SceneClient("127.0.0.1:1", tls_ca=not_pem)
    with pytest.raises(ValueError, match="tls_ca"):
        outcore.SceneClient("127.0.0.1:1", tls_cert=pki / "client.pem", tls_key=pki / "client.key")


def test_render_from_a_server_with_the_token_and_tls(store, pki, token_file, tmp_path, bounds):
    server = Server(store, "--tls-cert", pki / "server.pem", "--tls-key", pki / "server.key",
                    "--auth-token-file", token_file)
    try:
        lo, hi = bounds
        center = (lo + hi) / 2
        eye = center + np.array([0, 0, 3 * float(np.linalg.norm(hi - lo))])
        render = [str(binary()), "render", "--server", server.address, "--eye", ",".join(map(str, eye)),
                  "--center", ",".join(map(str, center)), "--up", "0,1,0", "--fov", "40", "--size", "32x24",
                  "-q", "--tls-ca", str(pki / "ca.pem")]
        refused = subprocess.run(render + ["-o", str(tmp_path / "refused.png")], capture_output=True, text=True,
                                 timeout=120)
        assert refused.returncode != 0 and "UNAUTHENTICATED" in refused.stderr
        drawn = subprocess.run(render + ["-o", str(tmp_path / "drawn.png"), "--auth-token-file", str(token_file)],
                               capture_output=True, text=True, timeout=120)
        assert drawn.returncode == 0, drawn.stderr
        assert (tmp_path / "drawn.png").read_bytes().startswith(b"\x89PNG")
    finally:
        assert server.stop() == 0, "".join(server.lines)


def _environment(pid: int) -> list[bytes]:
    return Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")


def test_serve_runs_on_a_huge_page_heap_when_asked(server, store, monkeypatch):
    # By default the process keeps glibc's tunables as they were given (the fixture's server).
    given = os.environ.get("GLIBC_TUNABLES")
    expected = [] if given is None else [b"GLIBC_TUNABLES=" + given.encode()]
    assert [v for v in _environment(server.process.pid) if v.startswith(b"GLIBC_TUNABLES=")] == expected
    mode = Path("/sys/kernel/mm/transparent_hugepage/enabled")
    if not mode.is_file() or "[madvise]" not in mode.read_text():
        pytest.skip("the kernel's transparent huge pages are not 'madvise': outcore leaves glibc as it is")
    monkeypatch.setenv("OUTCORE_HUGE_PAGES", "1")
    huge = Server(store)
    try:
        # Re-executed (same pid) with glibc's tunable added to the given ones
        # (a given hugetlb setting is the user's and stays), and serving.
        if given is not None and "glibc.malloc.hugetlb=" in given:
            wanted = given
        else:
            wanted = (given + ":" if given else "") + "glibc.malloc.hugetlb=1"
        tunables = [v for v in _environment(huge.process.pid) if v.startswith(b"GLIBC_TUNABLES=")]
        assert tunables == [b"GLIBC_TUNABLES=" + wanted.encode()]
        with outcore.SceneClient(huge.address, timeout=30) as client:
            assert client.scene_info()["triangle_count"] > 0
    finally:
        assert huge.stop() == 0
