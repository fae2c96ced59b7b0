#!/usr/bin/env python3
"""Remote API benchmark (issue 4): rays/s through gRPC on loopback, with the C++
client (`outcore query --repeat`) and the Python client (SceneClient.cast_rays),
against in-process `outcore trace` and Open3D 0.20 RaycastingScene.cast_rays,
all on the same rays in the same run, 2 threads each; plus latency of 1-ray and
1,000-ray requests and the bytes on the wire per ray.

For each scene and ray set (1M incoherent, 1M camera; bench/make_rays.py):
- `outcore serve STORE --listen 127.0.0.1:0 --threads 2 --cache-mb 8192` is
  started, and one warm-up query builds every brick the rays need;
- C++ client: median wall time of the calls of `outcore query --repeat R`
  (client chunking and the wire included, .npy file I/O excluded), once with
  the rays and hits in the gRPC messages (`--no-shared-memory`) and once
  through a same-host shared payload (the default against a loopback server);
- Python client: median wall time of R cast_rays calls (numpy in and out),
  likewise with shared_memory=False and with the default;
- in process: median of the warm runs of `outcore trace --repeat R+1`;
- Open3D: median of R cast_rays runs on the triangles read back from the store.
The CLI's hits files (both paths) are compared bitwise with trace's, and
Python's arrays with it. Ratios are against Open3D in process (> 1: faster than Open3D).

Latency (bunny server, Python client, one channel, sequential): p50/p99 of
--latency-calls calls each of 1 and 1,000 rays. Bytes on the wire: the
serialised request and reply of one 1,000-ray call (protobuf framing
included; HTTP/2 framing adds 9 bytes per 16 KiB frame).

Needs the bench venv (open3d) with the outcore client installed into it:
`bash scripts/install.sh --bench`.
Usage: .venv-bench/bin/python bench/remote_bench.py [--runs 5] [--scenes bunny,city]
       [--outcore build/client/outcore] [--work build/bench-remote] [--json rows.json]
"""
import argparse
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import threading
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import OUTCORE, ROOT, prepare_store, read_store_triangles, run  # noqa: E402
from trace_bench import SCENES, open3d_cast  # noqa: E402


class Server:
    """`outcore serve STORE` on loopback, 2 threads, 8 GiB cache unless `extra`
    (more flags) has its own --cache-mb; with --metrics-listen, `metrics` is
    its HOST:PORT."""

    def __init__(self, store, extra=()):
        cache = [] if "--cache-mb" in extra else ["--cache-mb", "8192"]
        self.proc = subprocess.Popen([OUTCORE, "serve", store, "--listen", "127.0.0.1:0", "--threads", "2",
                                      *cache, "--log-level", "warn", *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.address = self.metrics = None
        ready = threading.Event()

        def read():
            for line in self.proc.stdout:
                m = re.search(r"metrics on http://(\S+)", line)
                if m:
                    self.metrics = m.group(1)
                m = re.search(r"listening on (\S+):(\d+)", line)
                if m and self.address is None:
                    self.address = f"{m.group(1)}:{m.group(2)}"
                    ready.set()
            ready.set()

        threading.Thread(target=read, daemon=True).start()
        if not ready.wait(600) or self.address is None:
            self.proc.kill()
            sys.exit("outcore serve did not start")

    def stop(self):
        self.proc.send_signal(signal.SIGTERM)
        code = self.proc.wait(120)
        if code != 0:
            sys.exit(f"outcore serve exited {code} on SIGTERM")


def cpp_query(address, rays_path, out, runs, shared):
    extra = [] if shared else ["--no-shared-memory"]
    text = run([OUTCORE, "query", "--server", address, "--rays", rays_path, "-o", out, "--repeat", str(runs)] + extra)
    secs = [float(m) for m in re.findall(r"call \d+/\d+ seconds (\S+)", text)]
    return statistics.median(secs)


def trace_warm(store, rays_path, out, runs):
    stats_path = out + ".stats.json"
    # The same budget as the server's, so the warm runs are fully cached too.
    run([OUTCORE, "trace", store, "--rays", rays_path, "-o", out, "--threads", "2", "--repeat", str(runs + 1),
         "--cache-mb", "8192", "--stats-json", stats_path])
    with open(stats_path) as f:
        stats = json.load(f)
    return statistics.median(s["seconds"]["total"] for s in stats[1:])


def python_cast(client, rays, runs):
    times, result = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        result = client.cast_rays(rays)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def latency(client, rays, calls):
    out = {}
    for n in (1, 1000):
        batch = rays[:n]
        client.cast_rays(batch)
        times = []
        for _ in range(calls):
            t0 = time.perf_counter()
            client.cast_rays(batch)
            times.append(time.perf_counter() - t0)
        times = np.array(times) * 1e3
        out[n] = (float(np.percentile(times, 50)), float(np.percentile(times, 99)))
    return out


def wire_bytes(client, rays):
    from outcore import _wire
    request = _wire.encode_query(np.ascontiguousarray(rays))
    reply = client._calls["/outcore.v1.SceneQuery/Intersect"](request, timeout=60)
    return len(request) / len(rays), len(reply) / len(rays)


def main():
    global OUTCORE
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--scenes", default="bunny,city")
    ap.add_argument("--latency-calls", type=int, default=300)
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-remote"))
    ap.add_argument("--outcore", default=OUTCORE)
    ap.add_argument("--json")
    a = ap.parse_args()
    if a.runs < 2:
        ap.error("--runs must be at least 2 (`outcore query` times each call of a --repeat of 2 or more)")
    OUTCORE = os.path.abspath(a.outcore)
    import outcore
    os.makedirs(a.work, exist_ok=True)
    load_before = os.getloadavg()[0]
    rows, lat, wire = [], None, None
    for name in a.scenes.split(","):
        store, info = prepare_store(OUTCORE, a.work, name, SCENES[name])
        tris, _ = read_store_triangles(store)
        server = Server(store)
        try:
            with outcore.SceneClient(server.address, timeout=3600) as client, \
                    outcore.SceneClient(server.address, timeout=3600, shared_memory=False) as bytes_client:
                for kind in ("incoherent", "camera"):
                    rays_path = os.path.join(a.work, f"{name}-{kind}.npy")
                    run([sys.executable, os.path.join(ROOT, "bench", "make_rays.py"), info, kind, str(a.rays),
                         rays_path])
                    rays = np.load(rays_path)
                    n = len(rays)
                    cli_out = os.path.join(a.work, f"{name}-{kind}-query.npy")
                    trace_out = os.path.join(a.work, f"{name}-{kind}-trace.npy")
                    shm_out = os.path.join(a.work, f"{name}-{kind}-query-shm.npy")
                    run([OUTCORE, "query", "--server", server.address, "--rays", rays_path, "-o", cli_out])  # warm-up
                    cpp_s = cpp_query(server.address, rays_path, cli_out, a.runs, shared=False)
                    cpp_shm_s = cpp_query(server.address, rays_path, shm_out, a.runs, shared=True)
                    py_s, result = python_cast(bytes_client, rays, a.runs)
                    py_shm_s, result_shm = python_cast(client, rays, a.runs)
                    if not client.last_call_shared:
                        sys.exit("the Python client did not use shared memory against a loopback server")
                    trace_s = trace_warm(store, rays_path, trace_out, a.runs)
                    o3d_s = open3d_cast(tris, rays, a.runs)[0]
                    trace_bytes = open(trace_out, "rb").read()
                    same_cli = (open(cli_out, "rb").read() == trace_bytes and
                                open(shm_out, "rb").read() == trace_bytes)
                    ref = np.load(trace_out)
                    same_py = all(np.array_equal(ref["primitive_id"], r["primitive_ids"]) and
                                  np.array_equal(ref["t_hit"].view(np.uint32), r["t_hit"].view(np.uint32))
                                  for r in (result, result_shm))
                    row = dict(scene=name, triangles=len(tris), rays=kind, cpp_Mrays=n / cpp_s / 1e6,
                               cpp_shm_Mrays=n / cpp_shm_s / 1e6, python_Mrays=n / py_s / 1e6,
                               python_shm_Mrays=n / py_shm_s / 1e6, trace_Mrays=n / trace_s / 1e6,
                               open3d_Mrays=n / o3d_s / 1e6, cpp_vs_open3d=o3d_s / cpp_s,
                               cpp_shm_vs_open3d=o3d_s / cpp_shm_s, python_vs_open3d=o3d_s / py_s,
                               python_shm_vs_open3d=o3d_s / py_shm_s, cpp_vs_trace=trace_s / cpp_s,
                               cpp_shm_vs_trace=trace_s / cpp_shm_s,
                               bitwise_cli=same_cli, bitwise_python=same_py, load_avg=os.getloadavg()[0])
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                    if lat is None:
                        lat = latency(bytes_client, rays, a.latency_calls)
                        wire = wire_bytes(bytes_client, rays[:1000])
        finally:
            server.stop()
    print(f"\nload average (1 min) at start {load_before:.1f}, at end {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"{a.rays:,}-ray batches, medians of {a.runs} calls, 2 threads everywhere\n")
    print("M rays/s; 'bytes': rays and hits in the gRPC messages (--no-shared-memory / shared_memory=False), "
          "'shm': same-host shared payloads (the default on loopback); ratios against Open3D in process\n")
    print("| scene | rays | C++ bytes | C++ shm | Python bytes | Python shm | trace | Open3D "
          "| C++ bytes vs O3D | C++ shm vs O3D | Py bytes vs O3D | Py shm vs O3D | C++ shm vs trace | bitwise = trace |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['rays']} | {r['cpp_Mrays']:.2f} | {r['cpp_shm_Mrays']:.2f} | "
              f"{r['python_Mrays']:.2f} | {r['python_shm_Mrays']:.2f} | {r['trace_Mrays']:.2f} | "
              f"{r['open3d_Mrays']:.2f} | {r['cpp_vs_open3d']:.2f}x | {r['cpp_shm_vs_open3d']:.2f}x | "
              f"{r['python_vs_open3d']:.2f}x | {r['python_shm_vs_open3d']:.2f}x | {r['cpp_shm_vs_trace']:.2f}x | "
              f"{'yes' if r['bitwise_cli'] and r['bitwise_python'] else 'NO'} |")
    if lat:
        print(f"\nlatency (Python client, {a.latency_calls} sequential calls, first scene): "
              f"1 ray p50 {lat[1][0]:.2f} ms p99 {lat[1][1]:.2f} ms; "
              f"1000 rays p50 {lat[1000][0]:.2f} ms p99 {lat[1000][1]:.2f} ms")
        print(f"bytes on the wire per ray (1000-ray Intersect, protobuf): request {wire[0]:.2f}, reply {wire[1]:.2f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(dict(rows=rows, latency_ms=lat, wire_bytes_per_ray=wire), f, indent=1)


if __name__ == "__main__":
    main()
