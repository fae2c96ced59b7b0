#!/usr/bin/env python3
"""The wire for clients on other hosts (issue 29): rays/s over the gRPC bytes
path on loopback (`--no-shared-memory`, shared_memory=False) against Open3D
0.20 in process, with the replies carrying all hit fields (32 bytes a ray),
t and ids (12) or t only (4); the cost of scraping /metrics under load; and
the bytes on the wire per ray each way.

For each scene and ray set (1 M incoherent, 1 M camera; bench/make_rays.py),
one `outcore serve --threads 2 --cache-mb 8192 --metrics-listen 127.0.0.1:0`
warmed by one query, then, interleaved round by round (--runs rounds, the
median of each):
- C++ client: one `outcore query --repeat 2 --no-shared-memory
  --hit-fields F` per round, the second call's wall time (client chunking
  and the wire included, .npy file I/O excluded);
- Python client: SceneClient(shared_memory=False).cast_rays(rays,
  hit_fields=F);
- Open3D: RaycastingScene.cast_rays on the triangles read back from the store;
- scrape: 5 C++ all-fields calls in one process, then 5 more while a thread
  GETs /metrics every 100 ms (10 Hz: 150 times Prometheus' default 15 s
  interval), their medians compared; and the wall time of one scrape of an
  idle server (median of 500), an upper bound of its cost.
Answers of every field set are checked equal to the all-fields answer's
fields. Ratios > 1: faster than Open3D in process.

Needs the bench venv: `bash scripts/install.sh --bench`.
Usage: .venv-bench/bin/python bench/service_wire_bench.py [--runs 5] [--scenes bunny,city]
       [--json docs/data/service_wire_bench.json]
"""
import argparse
import json
import os
import re
import statistics
import sys
import threading
import time
import urllib.request

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import OUTCORE, ROOT, prepare_store, read_store_triangles, run  # noqa: E402
import remote_bench  # noqa: E402
from remote_bench import Server  # noqa: E402
from trace_bench import SCENES, open3d_cast  # noqa: E402

FIELDS = {"all": "all", "t,ids": "t_ids", "t": "t"}  # CLI name -> Python name


def cpp_call(address, rays_path, out, fields, calls=1):
    """Median wall seconds of `calls` calls after a first one that warms the channel."""
    text = run([OUTCORE, "query", "--server", address, "--rays", rays_path, "-o", out, "--repeat", str(calls + 1),
                "--no-shared-memory", "--hit-fields", fields, "-q"])
    return statistics.median([float(s) for s in re.findall(r"call \d+/\d+ seconds (\S+)", text)][1:])


def python_call(client, rays, fields):
    t0 = time.perf_counter()
    result = client.cast_rays(rays, hit_fields=fields)
    return time.perf_counter() - t0, result


class Scraper:
    """GETs /metrics every `period` seconds until stopped; counts scrapes."""

    def __init__(self, address, period=0.1):
        self.scrapes, self._stop = 0, threading.Event()

        def loop():
            while not self._stop.wait(period):
                with urllib.request.urlopen(f"http://{address}/metrics", timeout=10) as reply:
                    reply.read()
                self.scrapes += 1

        self._thread = threading.Thread(target=loop, daemon=True)
        self._thread.start()

    def stop(self):
        self._stop.set()
        self._thread.join()


def scrape_seconds(address, scrapes=500):
    """Median wall seconds of one GET /metrics from an idle client: an upper
    bound of the server's work per scrape (HTTP and the client included)."""
    times = []
    for _ in range(scrapes):
        t0 = time.perf_counter()
        with urllib.request.urlopen(f"http://{address}/metrics", timeout=10) as reply:
            reply.read()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def wire_bytes(client, rays, fields):
    from outcore import _wire
    codes = {"all": _wire.HIT_FIELDS_ALL, "t_ids": _wire.HIT_FIELDS_T_IDS, "t": _wire.HIT_FIELDS_T}
    request = _wire.encode_query(np.ascontiguousarray(rays), hit_fields=codes[fields])
    reply = client._calls["/outcore.v1.SceneQuery/Intersect"](request, timeout=60)
    return len(request) / len(rays), len(reply) / len(rays)


def measure(server, client, store, tris, rays_path, rays, runs, work, tag):
    n = len(rays)
    times = {k: [] for k in ["o3d", "cpp_scraped", "cpp_unscraped"] + [f"cpp_{f}" for f in FIELDS] +
             [f"py_{f}" for f in FIELDS]}
    outs = {f: os.path.join(work, f"{tag}-{f.replace(',', '_')}.npy") for f in FIELDS}
    run([OUTCORE, "query", "--server", server.address, "--rays", rays_path, "-o", outs["all"], "-q"])  # warm-up
    results = {}
    scrapes = 0
    for _ in range(runs):
        for f, py_name in FIELDS.items():
            times[f"cpp_{f}"].append(cpp_call(server.address, rays_path, outs[f], f))
            seconds, results[py_name] = python_call(client, rays, py_name)
            times[f"py_{f}"].append(seconds)
        # Sustained load (several calls in one process), scraped and not, back to back.
        times["cpp_unscraped"].append(cpp_call(server.address, rays_path, outs["all"], "all", calls=5))
        scraper = Scraper(server.metrics)
        times["cpp_scraped"].append(cpp_call(server.address, rays_path, outs["all"], "all", calls=5))
        scraper.stop()
        scrapes += scraper.scrapes
        times["o3d"].append(open3d_cast(tris, rays, 1)[0])
    full = np.load(outs["all"])
    same = True
    for f, py_name in FIELDS.items():
        cli = np.load(outs[f])
        same &= np.array_equal(cli["t_hit"].view(np.uint32), full["t_hit"].view(np.uint32))
        same &= np.array_equal(results[py_name]["t_hit"].view(np.uint32), full["t_hit"].view(np.uint32))
        if f != "t":
            same &= np.array_equal(cli["primitive_id"], full["primitive_id"])
            same &= np.array_equal(results[py_name]["primitive_ids"], full["primitive_id"])
    med = {k: statistics.median(v) for k, v in times.items()}
    row = dict(rays=n, open3d_Mrays=n / med["o3d"] / 1e6, same_answers=bool(same), scrapes=scrapes,
               scraped_vs_unscraped=med["cpp_unscraped"] / med["cpp_scraped"], load_avg=os.getloadavg()[0])
    for f in FIELDS:
        key = f.replace(",", "_")
        row[f"cpp_{key}_Mrays"] = n / med[f"cpp_{f}"] / 1e6
        row[f"python_{key}_Mrays"] = n / med[f"py_{f}"] / 1e6
        row[f"cpp_{key}_vs_open3d"] = med["o3d"] / med[f"cpp_{f}"]
        row[f"python_{key}_vs_open3d"] = med["o3d"] / med[f"py_{f}"]
    return row


def plot(rows, path):
    """Bars of each row's ratios against Open3D, the 0.8x target drawn."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    series = [(f"{client} {f}", f"{key}_{f.replace(',', '_')}_vs_open3d")
              for client, key in (("C++", "cpp"), ("Python", "python")) for f in FIELDS]
    fig, ax = plt.subplots(figsize=(10, 4.5))
    width = 0.8 / len(series)
    for k, (label, key) in enumerate(series):
        ax.bar([i + k * width for i in range(len(rows))], [r[key] for r in rows], width, label=label)
    ax.axhline(0.8, color="black", linestyle="--", linewidth=1, label="target 0.8x")
    ax.set_xticks([i + 0.4 - width / 2 for i in range(len(rows))], [f"{r['scene']} {r['kind']}" for r in rows])
    ax.set_ylabel("throughput / Open3D in process")
    ax.set_title("gRPC bytes path on loopback, 1 M rays, by hit fields in the reply")
    ax.legend(ncol=4, fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main():
    global OUTCORE
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--scenes", default="bunny,city")
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-service-wire"))
    ap.add_argument("--outcore", default=OUTCORE)
    ap.add_argument("--json")
    ap.add_argument("--png", help="bar chart of the ratios (matplotlib)")
    ap.add_argument("--plot-only", metavar="JSON", help="only draw --png from an earlier run's --json")
    a = ap.parse_args()
    if a.plot_only:
        with open(a.plot_only) as f:
            plot(json.load(f)["rows"], a.png)
        return
    OUTCORE = remote_bench.OUTCORE = os.path.abspath(a.outcore)
    import outcore
    os.makedirs(a.work, exist_ok=True)
    rows, wire, scrape_s = [], {}, None
    for name in a.scenes.split(","):
        store, info = prepare_store(OUTCORE, a.work, name, SCENES[name])
        tris, _ = read_store_triangles(store)
        server = Server(store, ["--metrics-listen", "127.0.0.1:0"])
        try:
            with outcore.SceneClient(server.address, timeout=3600, shared_memory=False) as client:
                for kind in ("incoherent", "camera"):
                    rays_path = os.path.join(a.work, f"{name}-{kind}.npy")
                    run([sys.executable, os.path.join(ROOT, "bench", "make_rays.py"), info, kind, str(a.rays),
                         rays_path])
                    rays = np.load(rays_path)
                    row = dict(scene=name, kind=kind, triangles=len(tris))
                    row.update(measure(server, client, store, tris, rays_path, rays, a.runs, a.work, f"{name}-{kind}"))
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                    if not wire:
                        wire = {f: wire_bytes(client, rays[:1000], f) for f in FIELDS.values()}
                        scrape_s = scrape_seconds(server.metrics)
        finally:
            server.stop()
    print(f"\n{a.rays:,}-ray batches over the gRPC bytes path on loopback, medians of {a.runs} interleaved "
          f"rounds, 2 threads each, {os.cpu_count()} cores; x = ratio against Open3D in process\n")
    print("| scene | rays | Open3D M rays/s | C++ all | C++ t,ids | C++ t | Python all | Python t_ids | Python t "
          "| /metrics at 10 Hz | answers equal |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['kind']} | {r['open3d_Mrays']:.2f} | {r['cpp_all_vs_open3d']:.2f}x | "
              f"{r['cpp_t_ids_vs_open3d']:.2f}x | {r['cpp_t_vs_open3d']:.2f}x | {r['python_all_vs_open3d']:.2f}x | "
              f"{r['python_t_ids_vs_open3d']:.2f}x | {r['python_t_vs_open3d']:.2f}x | "
              f"{r['scraped_vs_unscraped']:.3f}x ({r['scrapes']} scrapes) | {'yes' if r['same_answers'] else 'NO'} |")
    print(f"\none GET /metrics (idle server, median of 500): {scrape_s * 1e3:.3f} ms wall, i.e. at most "
          f"{scrape_s / 15 * 100:.4f} % of one core at Prometheus' default 15 s interval, "
          f"{scrape_s * 10 * 100:.2f} % at 10 Hz")
    print("\nbytes on the wire per ray (1000-ray Intersect, protobuf framing included): " +
          ", ".join(f"{f}: request {q:.2f}, reply {p:.2f}" for f, (q, p) in wire.items()))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(dict(rows=rows, wire_bytes_per_ray=wire, scrape_seconds=scrape_s), f, indent=1)
    if a.png:
        plot(rows, a.png)


if __name__ == "__main__":
    main()
