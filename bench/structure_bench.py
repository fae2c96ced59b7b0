#!/usr/bin/env python3
"""Issues 24 and 25's benchmark: brick structures and brick bounds, same run.

Structures (--structures, default bvh,kdtree,embree; the first is the base): for each scene, `outcore trace --repeat R` on 1M incoherent and 1M
camera rays (bench/make_rays.py) with a budget that holds the scene: run 1
is cold (every brick built: build seconds summed over threads, M triangles/s
per thread, resident bytes per triangle), runs 2..R warm (median trace
time). Ratios are against the bvh of the same run.

Bounds (--brick-bounds aabb, sphere, obb, default structure): on the tilted
city only (its flat layer of copies turned 30 degrees about x, so bricks are
oblique slabs), warm median time and the figures that show what a bound
saves: brick visits, visits without a hit, candidates turned away by the
bound. Proxies are off for this part so that the bound alone decides; with
--no-proxies the upper hierarchy's box is the only other test.

Scenes: the bunny; `tilted`, gen:city of 400 terrain patches tilted 30
degrees (~0.5 M triangles, thin oblique geometry, the rotated scene of the
issue); `stadium`, the teapot in a stadium packed as one brick, and
`terrain`, a 320 k-triangle height field (issue 25's grids); `city`, the
trace benchmark's 15 M-triangle city (not in the default set: ~10 minutes a
structure). The bounds part runs on `tilted` only.

Usage: .venv/bin/python bench/structure_bench.py [--runs 5] [--rays 1000000]
       [--scenes bunny,tilted] [--structures bvh,kdtree,embree] [--outcore build/client/outcore] [--work build/bench-structure]
       [--json rows.json] [--png chart.png]
The chart needs matplotlib (.venv-bench).
"""
import argparse
import json
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import OUTCORE, ROOT, make_rays, prepare_store, trace_repeated  # noqa: E402

SCENES = {
    "bunny": [os.path.join(ROOT, "tests", "data", "models", "stanford-bunny.obj")],
    "tilted": ["gen:city?of=(gen:terrain?n=24&size=2&height=0.1)&copies=400&spacing=3&tilt=30"],
    "city": ["gen:city?of=(gen:sphere?level=5)&copies=732"],
    # The teapot in a stadium (issue 25): a 1-unit sphere of 82k triangles
    # in a 2000-unit open box, packed as one brick so that one structure must
    # hold both scales.
    "stadium": ["gen:stadium?level=6"],
    # A 2.5D height field (the quadtree's and the grid's home ground).
    "terrain": ["gen:terrain?n=400&size=100&height=3"],
}
CACHE_MB = 8192
# Bricks of 4k triangles on the tilted city: ~110 oblique slabs, enough
# bricks for the bounds to matter (the default 32k makes 19).
PACK_OPTIONS = {"tilted": ("--brick-tris", "4096"), "stadium": ("--brick-tris", "1000000")}


def trace(store, rays_path, runs, extra):
    """(cold stats, warm median seconds, last warm stats) of `outcore trace --repeat runs`."""
    stats = trace_repeated(OUTCORE, store, rays_path, rays_path + ".hits.npy", runs, CACHE_MB, extra)
    return stats[0], statistics.median(s["seconds"]["total"] for s in stats[1:]), stats[-1]


def structure_rows(name, store, info, rays, runs, structures):
    rows = []
    with open(info) as f:
        triangles = json.load(f)["triangles"]
    for kind, path in rays.items():
        base = None
        for accel in structures:
            cold, warm, _ = trace(store, path, runs, ["--brick-accel", accel])
            build = cold["seconds"]["brick_builds_summed"]
            row = {"part": "structure", "scene": name, "rays": kind, "accel": accel,
                   "warm_s": warm, "build_s_summed": build,
                   "build_mtris_per_s_per_thread": triangles / build / 1e6 if build > 0 else None,
                   "bytes_per_triangle": cold["peak_bytes_resident"] / triangles}
            base = base or row
            row["warm_vs_bvh"] = warm / base["warm_s"]
            row["build_vs_bvh"] = build / base["build_s_summed"] if base["build_s_summed"] else None
            rows.append(row)
            print(f"{name:7s} {kind:10s} {accel:7s} warm {warm:.3f} s ({row['warm_vs_bvh']:.2f}x bvh)  "
                  f"build {build:.3f} s summed ({row['build_vs_bvh'] or 0:.2f}x bvh)  "
                  f"{row['bytes_per_triangle']:.0f} B/tri", flush=True)
    return rows


def bound_rows(name, store, rays, runs):
    rows = []
    for kind, path in rays.items():
        base = None
        for bound in ("aabb", "sphere", "obb"):
            _, warm, stats = trace(store, path, runs, ["--brick-bounds", bound, "--no-proxies"])
            row = {"part": "bounds", "scene": name, "rays": kind, "bound": bound, "warm_s": warm,
                   "brick_visits": stats["brick_visits"],
                   "brick_visits_without_hit": stats["brick_visits_without_hit"],
                   "bricks_skipped_by_bound": stats["bricks_skipped_by_bound"]}
            base = base or row
            row["warm_vs_aabb"] = warm / base["warm_s"]
            row["without_hit_vs_aabb"] = (row["brick_visits_without_hit"] / base["brick_visits_without_hit"]
                                          if base["brick_visits_without_hit"] else None)
            rows.append(row)
            print(f"{name:7s} {kind:10s} {bound:6s} warm {warm:.3f} s ({row['warm_vs_aabb']:.2f}x aabb)  "
                  f"visits {row['brick_visits']}  without hit {row['brick_visits_without_hit']} "
                  f"({row['without_hit_vs_aabb'] or 0:.2f}x aabb)  turned away {row['bricks_skipped_by_bound']}",
                  flush=True)
    return rows


def draw(rows, png):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    bounds = [r for r in rows if r["part"] == "bounds"]
    structures = [r for r in rows if r["part"] == "structure"]
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.8), gridspec_kw={"width_ratios": [3, 1]})
    # Grouped: one group per (scene, rays), one bar per structure.
    groups = list(dict.fromkeys((r["scene"], r["rays"]) for r in structures))
    accels = list(dict.fromkeys(r["accel"] for r in structures))
    width = 0.8 / max(1, len(accels))
    for i, accel in enumerate(accels):
        values = {(r["scene"], r["rays"]): r["warm_vs_bvh"] for r in structures if r["accel"] == accel}
        axes[0].bar([g + i * width for g in range(len(groups))], [values.get(k, 0) for k in groups], width,
                    label=accel)
    axes[0].set_xticks([g + 0.4 - width / 2 for g in range(len(groups))], [f"{s}\n{k}" for s, k in groups],
                       fontsize=8)
    axes[0].set_yscale("log")
    axes[0].axhline(1.0, color="grey", lw=0.8)
    axes[0].set_title("warm trace time, x the bvh's (log; lower is faster)")
    axes[0].legend(fontsize=7, ncol=len(accels))
    labels = [f"{r['rays']}\n{r['bound']}" for r in bounds]
    axes[1].bar(range(len(bounds)), [r["without_hit_vs_aabb"] or 0 for r in bounds], label="visits without a hit")
    axes[1].plot(range(len(bounds)), [r["warm_vs_aabb"] for r in bounds], "ro", label="warm time")
    axes[1].set_xticks(range(len(bounds)), labels, fontsize=7)
    axes[1].axhline(1.0, color="grey", lw=0.8)
    axes[1].set_title("brick bounds on the tilted city, x aabb")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def main():
    global OUTCORE, CACHE_MB
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--scenes", default="bunny,tilted")
    ap.add_argument("--structures", default="bvh,kdtree,embree", help="the first is the ratios' base")
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-structure"))
    ap.add_argument("--outcore", default=OUTCORE)
    ap.add_argument("--cache-mb", type=int, default=CACHE_MB)
    ap.add_argument("--json")
    ap.add_argument("--png")
    a = ap.parse_args()
    OUTCORE = os.path.abspath(a.outcore)
    CACHE_MB = a.cache_mb
    os.makedirs(a.work, exist_ok=True)
    rows = []
    for name in a.scenes.split(","):
        store, info = prepare_store(OUTCORE, a.work, name, SCENES[name], PACK_OPTIONS.get(name, ()))
        rays = {}
        for kind in ("incoherent", "camera"):
            path = os.path.join(a.work, f"{name}-{kind}-{a.rays}.npy")
            if not os.path.exists(path):
                make_rays(info, kind, a.rays, path)
            rays[kind] = path
        rows += structure_rows(name, store, info, rays, a.runs, a.structures.split(","))
        if name == "tilted":
            rows += bound_rows(name, store, rays, a.runs)
    load = os.getloadavg()[0]
    print(f"load average at the end: {load:.2f}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rows": rows, "load_end": load, "runs": a.runs, "rays": a.rays}, f, indent=1)
    if a.png:
        draw(rows, a.png)


if __name__ == "__main__":
    main()
