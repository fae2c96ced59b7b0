#!/usr/bin/env python3
"""The cost of a ray by what it meets (issue 23, "rays that hit nothing"), on
the sparse scene (bench/sparse_scene.py: 27 spaced copies of the Igea scan),
for one or more outcore binaries in the same run, next to Open3D's
RaycastingScene on the same triangles.

Ray sets (--rays each, bench/miss_rays.py, and bench/make_rays.py):
outside (every ray misses the scene's box), between (every ray enters the
box but no brick's), hit (every ray aimed at a triangle), and the bench's
camera and incoherent rays.

For each set, --runs rounds; in each round every binary runs `outcore trace
--threads 2 --repeat R` (cold run, then R-1 warm ones; the binaries in turn,
so a load spike hits them alike) and the warm median of that process is
kept; the figure is the median over the rounds (and, in parentheses, the
fastest round: the least disturbed by other load), as wall ns per ray (2
threads) = warm seconds / rays. Open3D: the median of --runs cast_rays
calls, 2 threads. The answers of every binary must be byte-identical (the
script exits otherwise). The 1-minute load average is printed per row.

Needs the bench venv: `bash scripts/install.sh --bench`.
Usage: .venv-bench/bin/python bench/miss_cost_bench.py [--outcore NAME=BINARY ...] [--runs 5] [--repeat 6]
       [--rays 1000000] [--sets outside,between,hit,camera,incoherent] [--work build/bench-trace] [--no-open3d]
       [--json rows.json]
"""
import argparse
import filecmp
import json
import os
import statistics
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import OUTCORE, ROOT, make_rays, open3d_scene, open3d_timed_cast, prepare_store, read_store_triangles, run  # noqa: E402
from miss_rays import between_rays, hit_rays, outside_rays  # noqa: E402
from sparse_scene import sparse_layout, write_sparse_scene  # noqa: E402


def ray_set(name, work, info, triangles, count):
    """The rays of set `name`, saved once in work/miss-NAME-COUNT.npy; returns the path."""
    path = os.path.join(work, f"miss-{name}-{count}.npy")
    if os.path.exists(path):
        return path
    if name in ("camera", "incoherent"):
        make_rays(info, name, count, path)
        return path
    with open(info) as f:
        bounds = json.load(f)["bounds"]
    lo, hi = np.array(bounds["min"], np.float64), np.array(bounds["max"], np.float64)
    rng = np.random.default_rng({"outside": 11, "between": 12, "hit": 13}[name])
    if name == "outside":
        rays = outside_rays(lo, hi, count, rng)
    elif name == "between":
        rays = between_rays(lo, hi, *sparse_layout(work), count, rng)
    else:
        rays = hit_rays(lo, hi, triangles, count, rng)
    np.save(path, rays)
    return path


def warm_seconds(binary, store, rays_path, out, repeat):
    """The warm median of one `outcore trace --repeat` process, and its last stats."""
    stats_path = out + ".stats.json"
    run([binary, "trace", store, "--rays", rays_path, "-o", out, "--threads", "2", "--repeat", str(repeat),
         "--cache-mb", "8192", "--stats-json", stats_path])
    with open(stats_path) as f:
        stats = json.load(f)
    if any(s["brick_builds"] > 0 for s in stats[1:]):
        sys.exit(f"a warm run of {rays_path} built bricks")
    return statistics.median(s["seconds"]["total"] for s in stats[1:]), stats[-1]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--outcore", action="append", help="NAME=BINARY (repeatable; default: this build)")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=6)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--sets", default="outside,between,hit,camera,incoherent")
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-trace"))
    ap.add_argument("--no-open3d", action="store_true")
    ap.add_argument("--json", help="also write the rows as JSON to this file")
    a = ap.parse_args()
    binaries = dict(spec.split("=", 1) for spec in (a.outcore or [f"outcore={OUTCORE}"]))
    binaries = {name: os.path.abspath(path) for name, path in binaries.items()}
    os.makedirs(a.work, exist_ok=True)
    first_binary = next(iter(binaries.values()))
    store, info = prepare_store(first_binary, a.work, "sparse", [write_sparse_scene(first_binary, a.work)])
    triangles, _ = read_store_triangles(store)
    scene = None if a.no_open3d else open3d_scene(triangles)
    rows = []
    for name in a.sets.split(","):
        rays_path = ray_set(name, a.work, info, triangles, a.rays)
        rays = np.load(rays_path)
        load_before = os.getloadavg()[0]
        seconds = {b: [] for b in binaries}
        last_stats, outs = {}, {}
        for _ in range(a.runs):
            for b, binary in binaries.items():
                outs[b] = os.path.join(a.work, f"miss-{name}-hits-{b}.npy")
                s, last_stats[b] = warm_seconds(binary, store, rays_path, outs[b], a.repeat)
                seconds[b].append(s)
        reference = next(iter(outs.values()))
        for b, out in outs.items():
            if not filecmp.cmp(reference, out, shallow=False):
                sys.exit(f"{name}: the answers of {b} differ from those of {next(iter(outs))}")
        hits = np.load(reference)
        row = dict(set=name, rays=len(rays), hit_fraction=float(np.mean(hits["primitive_id"] != 0xFFFFFFFF)))
        for b in binaries:
            row[f"{b}_ns"] = statistics.median(seconds[b]) * 1e9 / len(rays)
            row[f"{b}_min_ns"] = min(seconds[b]) * 1e9 / len(rays)
            row[f"{b}_runs_ns"] = [s * 1e9 / len(rays) for s in seconds[b]]
            st = last_stats[b]
            row[f"{b}_outside_bounds"] = st.get("rays_outside_bounds")
            row[f"{b}_entering_no_brick"] = st.get("rays_entering_no_brick")
            row[f"{b}_upper_nodes_per_ray"] = st["upper_nodes_visited"] / len(rays)
        if scene is not None:
            o3d_seconds, _ = open3d_timed_cast(scene, rays, a.runs)
            row["open3d_ns"] = o3d_seconds * 1e9 / len(rays)
        row["load_avg"] = [load_before, os.getloadavg()[0]]
        rows.append(row)
        print(json.dumps(row), flush=True)
    print(f"\n{os.cpu_count()} cores; wall ns per ray, 2 threads, warm, median of {a.runs} processes "
          f"(each the median of {a.repeat - 1} warm batches of {a.rays:,} rays)")
    names = list(binaries) + (["open3d"] if scene is not None else [])
    print("\n| rays | hit | " + " | ".join(f"{n} ns/ray" for n in names) + " | load (1 min) |")
    print("|---|---|" + "---|" * len(names) + "---|")
    for r in rows:
        # outcore: median (fastest round) of the rounds.
        cells = [f"{r[n + '_ns']:.1f} ({r[n + '_min_ns']:.1f})" if n in binaries else f"{r[n + '_ns']:.1f}"
                 for n in names]
        print(f"| {r['set']} | {r['hit_fraction'] * 100:.1f} % | " + " | ".join(cells) +
              f" | {r['load_avg'][0]:.1f}-{r['load_avg'][1]:.1f} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
