#!/usr/bin/env python3
"""Trace benchmark: in-process `outcore trace` against Open3D's
RaycastingScene.cast_rays on the same triangles and the same rays, same run,
2 threads each. Scenes: the bunny, a generated city (~15 M triangles) and
`sparse`, 27 spaced copies of the Igea scan (7.25 M triangles, most of its box
empty: bench/sparse_scene.py; not in the default set).

For each scene and ray set (1M incoherent, 1M camera; bench/make_rays.py):
- outcore trace --repeat R: run 1 is cold (every brick built: time to first
  answer), runs 2..R warm (fully cached); the warm median is compared;
- the same with --no-reorder (warm median);
- Open3D 0.20 cast_rays, median of R runs, on the triangles read back from the
  store's brick file (so both trace bit-identical triangles);
- agreement: the fraction of rays whose hit/miss and (geometry, primitive) ids
  agree between the two;
- hit fraction: the fraction of rays that hit anything (outcore's answers).

Needs the bench venv: `bash scripts/install.sh --bench`.
Usage: .venv-bench/bin/python bench/trace_bench.py [--runs 6] [--rays 1000000] [--scenes bunny,city,sparse]
       [--outcore build/client/outcore] [--work build/bench-trace] [--cache-mb 8192] [--json rows.json] [--png chart.png]
"""
import argparse
import json
import os
import statistics
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import (OUTCORE, ROOT, make_rays, open3d_scene, open3d_timed_cast,  # noqa: E402,F401
                    prepare_store, read_store_triangles, run, trace_repeated)
from sparse_scene import write_sparse_scene  # noqa: E402

SCENES = {
    "bunny": [os.path.join(ROOT, "tests", "data", "models", "stanford-bunny.obj")],
    "city": ["gen:city?of=(gen:sphere?level=5)&copies=732"],  # 14.99 M triangles
    "sparse": None,  # written into the work directory by write_sparse_scene
}
CACHE_MB = 8192


def open3d_cast(tris, rays, runs):
    seconds, result = open3d_timed_cast(open3d_scene(tris), rays, runs)
    return seconds, result["primitive_ids"].numpy()


def outcore_trace(store, rays_path, out, runs, extra):
    stats = trace_repeated(OUTCORE, store, rays_path, out, runs, CACHE_MB, extra)
    return stats[0]["seconds"]["total"], statistics.median(s["seconds"]["total"] for s in stats[1:]), stats


def main():
    global OUTCORE, CACHE_MB
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--scenes", default="bunny,city")
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-trace"))
    ap.add_argument("--outcore", default=OUTCORE, help="the outcore binary to measure")
    ap.add_argument("--json", help="also write the rows as JSON to this file")
    ap.add_argument("--png", help="also draw a bar chart of the rows into this PNG (needs matplotlib)")
    ap.add_argument("--cache-mb", type=int, default=CACHE_MB,
                    help="outcore's brick cache budget: large enough that the warm runs are fully cached "
                         "(the city's 732 bricks take about 1.9 GiB); the script fails if a warm run builds")
    a = ap.parse_args()
    OUTCORE = os.path.abspath(a.outcore)
    CACHE_MB = a.cache_mb
    load_before = os.getloadavg()[0]
    os.makedirs(a.work, exist_ok=True)
    rows = []
    for name in a.scenes.split(","):
        inputs = SCENES[name] if SCENES[name] is not None else [write_sparse_scene(OUTCORE, a.work)]
        store, info = prepare_store(OUTCORE, a.work, name, inputs)
        with open(info) as f:
            bricks = json.load(f)["bricks"]
        tris, ids = read_store_triangles(store)
        for kind in ["incoherent", "camera"]:
            rays_path = os.path.join(a.work, f"{name}-{kind}.npy")
            rays = make_rays(info, kind, a.rays, rays_path)
            out = os.path.join(a.work, f"{name}-{kind}-hits.npy")
            cold, warm, warm_stats = outcore_trace(store, rays_path, out, a.runs, [])
            _, warm_noreorder, _ = outcore_trace(store, rays_path, out + ".noreorder.npy", min(a.runs, 3),
                                                 ["--no-reorder"])
            o3d_s, o3d_prims = open3d_cast(tris, rays, a.runs)
            hits = np.load(out)
            o3d_hit = o3d_prims != 0xFFFFFFFF
            ours_hit = hits["primitive_id"] != 0xFFFFFFFF
            mapped = np.where(o3d_hit, ids[np.minimum(o3d_prims, len(ids) - 1), 1], 0xFFFFFFFF)
            mapped_g = np.where(o3d_hit, ids[np.minimum(o3d_prims, len(ids) - 1), 0], 0xFFFFFFFF)
            agree = np.mean((o3d_hit == ours_hit) & (~ours_hit | ((mapped == hits["primitive_id"]) &
                                                                  (mapped_g == hits["geometry_id"]))))
            n = len(rays)
            row = dict(scene=name, triangles=len(tris), bricks=bricks, rays=kind,
                       outcore_warm_Mrays=n / warm / 1e6, open3d_Mrays=n / o3d_s / 1e6, ratio=o3d_s / warm,
                       noreorder_Mrays=n / warm_noreorder / 1e6, reorder_gain=warm_noreorder / warm,
                       cold_s=cold, agreement=agree, hit_fraction=float(np.mean(ours_hit)),
                       load_avg=os.getloadavg()[0])
            rows.append(row)
            print(json.dumps(row), flush=True)
    print(f"\nload average (1 min) at start {load_before:.1f}, at end {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print("\n| scene | triangles | bricks | rays | outcore warm M rays/s | Open3D M rays/s | ratio vs Open3D | no-reorder M rays/s "
          "| reorder gain | cold run s (first answer) | agreement | rays hitting |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['triangles']:,} | {r['bricks']} | {r['rays']} | {r['outcore_warm_Mrays']:.2f} | "
              f"{r['open3d_Mrays']:.2f} | {r['ratio']:.2f} | {r['noreorder_Mrays']:.2f} | {r['reorder_gain']:.2f} | "
              f"{r['cold_s']:.2f} | {r['agreement'] * 100:.3f} % | {r['hit_fraction'] * 100:.1f} % |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    if a.png:
        draw_chart(rows, a.png)


def draw_chart(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    labels = [f"{r['scene']}\n{r['rays']}" for r in rows]
    series = [("outcore (reorder)", "outcore_warm_Mrays"), ("outcore --no-reorder", "noreorder_Mrays"),
              ("Open3D 0.20", "open3d_Mrays")]
    width = 0.8 / len(series)
    fig, ax = plt.subplots(figsize=(2.2 * len(rows) + 2, 4))
    for s, (name, key) in enumerate(series):
        xs = [i + (s - (len(series) - 1) / 2) * width for i in range(len(rows))]
        ax.bar(xs, [r[key] for r in rows], width, label=name)
    for i, r in enumerate(rows):
        ax.annotate(f"{r['ratio']:.2f}x", (i, max(r["outcore_warm_Mrays"], r["open3d_Mrays"])), ha="center",
                    va="bottom", fontsize=9)
    ax.set_xticks(range(len(rows)))
    ax.set_xticklabels(labels)
    ax.set_ylabel("M rays/s (2 threads, warm, median)")
    ax.set_title("outcore trace vs Open3D RaycastingScene.cast_rays (label: ratio)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
