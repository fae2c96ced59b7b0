#!/usr/bin/env python3
"""Issue 26's benchmark: `--brick-accel auto` against every single structure.

For each scene and ray count, each structure answers the same incoherent
rays (bench/make_rays.py) in a fresh `outcore trace --repeat B` process with
a budget that holds the scene: `cold` is the first batch (every brick built
for it: build + trace, what a one-off query pays), `served` the sum of the B
batches (the same bricks serving a stream of batches, as under `serve`:
auto may start cheap and rebuild bricks once their rays pay). Each figure is
the median of --runs processes (in rounds: each round runs every structure
once); ratios are against the best single structure
of the same run (auto's target: within 10 %, and faster than all on the
mixed scene). Every structure's hits must equal the first's, bitwise.

Scenes: the bunny; `terrain` (320 k-triangle height field); `stadium` (the
teapot in a stadium, default bricks); `city` (spheres in a sparse city,
~1.6 M triangles); `mixed` (all four in one store).

Usage: .venv/bin/python bench/auto_bench.py [--runs 3] [--rays 10000,100000,1000000]
       [--batches 3] [--scenes bunny,terrain,stadium,city,mixed]
       [--structures bvh,grid,kdtree,hgrid,octree,quadtree,auto]
       [--outcore build/client/outcore] [--work build/bench-auto] [--json rows.json] [--png chart.png]
The chart needs matplotlib (.venv-bench).
"""
import argparse
import filecmp
import json
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import OUTCORE, ROOT, make_rays, prepare_store, run  # noqa: E402

BUNNY = os.path.join(ROOT, "tests", "data", "models", "stanford-bunny.obj")
SCENES = {
    "bunny": [BUNNY],
    "terrain": ["gen:terrain?n=400&size=100&height=3"],
    "stadium": ["gen:stadium?level=6"],
    "city": ["gen:city?of=(gen:sphere?level=4)&copies=320&spacing=4"],
}
SCENES["mixed"] = [spec for name in ("bunny", "terrain", "stadium", "city") for spec in SCENES[name]]
CACHE_MB = 8192


def trace_stats(store, rays_path, batches, accel, extra=()):
    out = rays_path + f".{accel}.hits.npy"
    stats_path = out + ".stats.json"
    run([OUTCORE, "trace", store, "--rays", rays_path, "-o", out, "--threads", "2", "--repeat", str(batches),
         "--cache-mb", str(CACHE_MB), "--stats-json", stats_path, "--brick-accel", accel, *extra])
    with open(stats_path) as f:
        stats = json.load(f)
    return (stats if isinstance(stats, list) else [stats]), out


def rows_for(name, store, rays_path, count, runs, batches, structures):
    rows = []
    reference_hits = None
    cold = {accel: [] for accel in structures}
    served = {accel: [] for accel in structures}
    builds, rebuilds = {}, {}
    # Rounds outermost: each round runs every structure once, so that the
    # machine's drift over minutes weighs on all of them alike.
    for _ in range(runs):
        for accel in structures:
            stats, hits = trace_stats(store, rays_path, batches, accel)
            cold[accel].append(stats[0]["seconds"]["total"])
            served[accel].append(sum(s["seconds"]["total"] for s in stats))
            builds[accel] = {k: sum(s["brick_builds_by_structure"][k] for s in stats)
                             for k in stats[0]["brick_builds_by_structure"]}
            rebuilds[accel] = sum(s["brick_rebuilds"] for s in stats)
            if reference_hits is None:
                reference_hits = hits + ".reference.npy"
                os.replace(hits, reference_hits)
            elif not filecmp.cmp(reference_hits, hits, shallow=False):
                sys.exit(f"{name}: {accel}'s hits differ from {structures[0]}'s")
    for accel in structures:
        rows.append({"scene": name, "rays": count, "accel": accel, "cold_s": statistics.median(cold[accel]),
                     "served_s": statistics.median(served[accel]),
                     "builds": {k: v for k, v in builds[accel].items() if v}, "rebuilds": rebuilds[accel]})
    singles = [r for r in rows if r["accel"] != "auto"]
    for key in ("cold_s", "served_s"):
        best = min(r[key] for r in singles)
        for r in rows:
            r[key.replace("_s", "_vs_best")] = r[key] / best
    for r in rows:
        print(f"{name:8s} {count:>8d} {r['accel']:8s} cold {r['cold_s']:.3f} s ({r['cold_vs_best']:.2f}x best)  "
              f"served {r['served_s']:.3f} s ({r['served_vs_best']:.2f}x best)  builds {r['builds']}"
              + (f" rebuilds {r['rebuilds']}" if r["rebuilds"] else ""), flush=True)
    return rows


def draw(rows, png):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    groups = list(dict.fromkeys((r["scene"], r["rays"]) for r in rows))
    accels = list(dict.fromkeys(r["accel"] for r in rows))
    fig, axes = plt.subplots(2, 1, figsize=(13, 8))
    width = 0.8 / max(1, len(accels))
    for ax, key, title in ((axes[0], "cold_vs_best", "one batch, cold (build + trace)"),
                           (axes[1], "served_vs_best", "three batches on the same bricks")):
        for i, accel in enumerate(accels):
            values = {(r["scene"], r["rays"]): r[key] for r in rows if r["accel"] == accel}
            ax.bar([g + i * width for g in range(len(groups))], [values.get(k, 0) for k in groups], width,
                   label=accel, edgecolor="black" if accel == "auto" else None)
        ax.set_xticks([g + 0.4 - width / 2 for g in range(len(groups))],
                      [f"{s}\n{c // 1000}k rays" for s, c in groups], fontsize=8)
        ax.set_yscale("log")
        ax.axhline(1.0, color="grey", lw=0.8)
        ax.axhline(1.1, color="red", lw=0.6, ls="--")
        ax.set_title(f"{title}: time x the best single structure's (log; lower is faster; red: 1.1)")
        ax.legend(fontsize=7, ncol=len(accels))
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def main():
    global OUTCORE, CACHE_MB
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--rays", default="10000,100000,1000000")
    ap.add_argument("--batches", type=int, default=3)
    ap.add_argument("--scenes", default="bunny,terrain,stadium,city,mixed")
    ap.add_argument("--structures", default="bvh,grid,kdtree,hgrid,octree,quadtree,auto",
                    help="the first one's answers are the reference")
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-auto"))
    ap.add_argument("--outcore", default=OUTCORE)
    ap.add_argument("--json")
    ap.add_argument("--png")
    a = ap.parse_args()
    OUTCORE = os.path.abspath(a.outcore)
    os.makedirs(a.work, exist_ok=True)
    rows = []
    for name in a.scenes.split(","):
        store, info = prepare_store(OUTCORE, a.work, name, SCENES[name])
        for count in (int(c) for c in a.rays.split(",")):
            path = os.path.join(a.work, f"{name}-incoherent-{count}.npy")
            if not os.path.exists(path):
                make_rays(info, "incoherent", count, path)
            rows += rows_for(name, store, path, count, a.runs, a.batches, a.structures.split(","))
    load = os.getloadavg()[0]
    print(f"load average at the end: {load:.2f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "load_end": load, "runs": a.runs, "batches": a.batches}, f, indent=1)
    if a.png:
        draw(rows, a.png)


if __name__ == "__main__":
    main()
