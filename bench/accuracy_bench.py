#!/usr/bin/env python3
"""Run time against error, per brick-structure configuration (issues 5, 23, 24, 25).

For each configuration (default, embree, embree-robust, bvh-mt,
bvh-watertight, bvh-double, kdtree, bsp, grid, hgrid, octree, quadtree;
--configs picks some) and Open3D 0.20's RaycastingScene as a reference point, all in
the same run, 2 threads each:
- speed: M rays/s on N incoherent rays (bench/make_rays.py) per scene, the
  median of the warm runs of `outcore trace --repeat R` (engine time), and of
  R runs of Open3D's cast_rays;
- disagreement with the float64 reference (`outcore trace --reference`) on
  the first K of those rays: hit/miss or triangle differs, except true ties
  (both triangles at a t within 1e-6 relative of each other, as computed by
  the reference rule); and the max relative t error where the triangle agrees;
- leak rate on aimed rays: rays from an interior point of a closed mesh
  (icosphere, torus, and both moved to offsets of 1e5 and 1e6) aimed exactly at every
  vertex and edge midpoint (direction = target - origin in float32, as the
  stress suite does); any miss is a leak.

Prints one table (markdown), writes rows as JSON (--json) and a PNG of speed
against error with each panel's Pareto front (--png).

Needs the bench venv: `bash scripts/install.sh --bench`.
Usage: .venv-bench/bin/python bench/accuracy_bench.py [--runs 5] [--rays 1000000] [--checked 20000] [--configs a,b]
       [--outcore build/client/outcore] [--work build/bench-accuracy] [--json rows.json] [--png plot.png]
"""
import argparse
import json
import os
import statistics
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import HIT_DTYPE, OUTCORE, ROOT, open3d_scene, open3d_timed_cast, read_store_triangles, run  # noqa: E402,F401

MODELS = os.path.join(ROOT, "tests", "data", "models")
CONFIGS = {
    "default": [],  # no structure option: what a user gets (bvh, watertight, since issue 23)
    "embree": ["--brick-accel", "embree"],
    "embree-robust": ["--brick-accel", "embree", "--accel-opt", "robust=1"],
    "bvh-mt": ["--brick-accel", "bvh", "--triangle-test", "mt"],
    "bvh-watertight": ["--brick-accel", "bvh", "--triangle-test", "watertight"],
    "bvh-double": ["--brick-accel", "bvh", "--triangle-test", "double"],
    "kdtree": ["--brick-accel", "kdtree"],  # watertight, as the default (issue 24)
    "bsp": ["--brick-accel", "bsp"],
    "grid": ["--brick-accel", "grid"],  # watertight (issue 25)
    "hgrid": ["--brick-accel", "hgrid"],
    "octree": ["--brick-accel", "octree"],
    "quadtree": ["--brick-accel", "quadtree"],
}
SPEED_SCENES = {
    "bunny": [os.path.join(MODELS, "stanford-bunny.obj")],
    "homer": [os.path.join(MODELS, "homer.obj")],
    "sphere-l7": ["gen:sphere?level=7"],
    "city": ["gen:city?of=(gen:sphere?level=3)&copies=400"],
    "sphere-l7 +1e6": ["gen:sphere?level=7&cx=1e6&cy=-1e6&cz=1e6"],
}
# Closed meshes and an interior point of each.
AIMED_SCENES = {
    "sphere": ("gen:sphere?level=5", (0.0, 0.0, 0.0)),
    "torus": ("gen:torus", (1.0, 0.0, 0.0)),
    "sphere +1e5": ("gen:sphere?level=5&cx=1e5&cy=1e5&cz=1e5", (1e5, 1e5, 1e5)),
    "sphere +1e6": ("gen:sphere?level=5&cx=1e6&cy=-1e6&cz=1e6", (1e6, -1e6, 1e6)),
    "torus +1e6": ("gen:torus?cx=1e6&cy=1e6&cz=-1e6", (1e6 + 1.0, 1e6, -1e6)),
}
TIE = 1e-6
def pack(work, name, inputs, brick_tris):
    store = os.path.join(work, name.replace(" ", "_") + ".oc")
    if not os.path.isdir(store):
        print(f"packing {name}", flush=True)
        run([OUTCORE, "pack", *inputs, "-o", store, "-q", "--brick-tris", str(brick_tris)])
    return store


def trace(store, rays_path, out, extra, runs=1):
    stats_path = out + ".stats.json"
    run([OUTCORE, "trace", store, "--rays", rays_path, "-o", out, "--threads", "2", "--repeat", str(runs),
         "--stats-json", stats_path, *extra])
    with open(stats_path) as f:
        stats = json.load(f)
    stats = stats if isinstance(stats, list) else [stats]
    warm = [s["seconds"]["total"] for s in (stats[1:] if len(stats) > 1 else stats)]
    return np.load(out), statistics.median(warm)


def open3d_cast(scene, rays, ids, runs):
    seconds, result = open3d_timed_cast(scene, rays, runs)
    prims = result["primitive_ids"].numpy()
    hit = prims != 0xFFFFFFFF
    safe = np.minimum(prims, len(ids) - 1)
    hits = np.zeros(len(rays), HIT_DTYPE)
    hits["t_hit"] = result["t_hit"].numpy()
    hits["geometry_id"] = np.where(hit, ids[safe, 0], 0xFFFFFFFF)
    hits["primitive_id"] = np.where(hit, ids[safe, 1], 0xFFFFFFFF)
    return hits, seconds


def compare(hits, ref):
    """(disagreements excluding ties, ties, max relative t error where the triangle agrees)."""
    hit, ref_hit = hits["primitive_id"] != 0xFFFFFFFF, ref["primitive_id"] != 0xFFFFFFFF
    same_tri = hit & ref_hit & (hits["primitive_id"] == ref["primitive_id"]) & (hits["geometry_id"] == ref["geometry_id"])
    differ = (hit != ref_hit) | (hit & ref_hit & ~same_tri)
    both = hit & ref_hit
    rel = np.zeros(len(hits))
    rel[both] = np.abs(hits["t_hit"][both].astype(np.float64) - ref["t_hit"][both]) / np.maximum(
        np.abs(ref["t_hit"][both].astype(np.float64)), 1e-30)
    ties = differ & both & (rel <= TIE)
    max_rel = float(rel[same_tri].max()) if same_tri.any() else 0.0
    return int((differ & ~ties).sum()), int(ties.sum()), max_rel


def aimed_rays(tris, interior):
    """Rays from `interior` aimed exactly at every distinct vertex and edge midpoint (float32)."""
    v = tris.reshape(-1, 3, 3)
    verts = np.unique(v.reshape(-1, 3), axis=0)
    # (a + b) / 2 is symmetric in float64, so a shared edge gives one midpoint.
    mids = np.concatenate([(v[:, a].astype(np.float64) + v[:, b]) / 2 for a, b in ((0, 1), (1, 2), (2, 0))])
    mids = np.unique(mids.astype(np.float32), axis=0)
    targets = np.concatenate([verts, mids])
    origin = np.array(interior, np.float32)
    dirs = (targets - origin).astype(np.float32)
    return np.hstack([np.broadcast_to(origin, dirs.shape), dirs]).astype(np.float32)


def main():
    global OUTCORE
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--checked", type=int, default=20000, help="rays per scene checked against float64")
    ap.add_argument("--scenes", default=",".join(SPEED_SCENES))
    ap.add_argument("--configs", default=",".join(CONFIGS), help="a subset of: " + ",".join(CONFIGS))
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-accuracy"))
    ap.add_argument("--outcore", default=OUTCORE)
    ap.add_argument("--json")
    ap.add_argument("--png")
    a = ap.parse_args()
    OUTCORE = os.path.abspath(a.outcore)
    os.makedirs(a.work, exist_ok=True)
    unknown = set(a.configs.split(",")) - set(CONFIGS)
    if unknown:
        sys.exit(f"unknown --configs {sorted(unknown)} (known: {', '.join(CONFIGS)})")
    for name in list(CONFIGS):
        if name not in a.configs.split(","):
            del CONFIGS[name]
    load_before = os.getloadavg()[0]
    names = list(CONFIGS) + ["open3d"]
    speed = {c: {} for c in names}
    wrong = {c: [0, 0, 0.0] for c in names}  # disagreements, ties, max rel t
    checked_total = 0
    for scene in a.scenes.split(","):
        store = pack(a.work, scene, SPEED_SCENES[scene], 8192)
        info = os.path.join(a.work, scene + ".json")
        with open(info, "w") as f:
            f.write(run([OUTCORE, "info", store, "--json"]))
        rays_path = os.path.join(a.work, f"{scene}-incoherent.npy")
        run([sys.executable, os.path.join(ROOT, "bench", "make_rays.py"), info, "incoherent", str(a.rays), rays_path])
        rays = np.load(rays_path)
        k = min(a.checked, len(rays))
        subset = os.path.join(a.work, f"{scene}-checked.npy")
        np.save(subset, rays[:k])
        print(f"{scene}: float64 reference on {k} rays", flush=True)
        ref, _ = trace(store, subset, os.path.join(a.work, f"{scene}-ref.npy"), ["--reference"])
        checked_total += k
        for config, extra in CONFIGS.items():
            hits, seconds = trace(store, rays_path, os.path.join(a.work, f"{scene}-{config}.npy"), extra, a.runs + 1)
            speed[config][scene] = len(rays) / seconds / 1e6
            d, t, m = compare(hits[:k], ref)
            wrong[config][0] += d
            wrong[config][1] += t
            wrong[config][2] = max(wrong[config][2], m)
            print(f"  {config:15s} {speed[config][scene]:6.2f} M rays/s, {d} wrong, {t} ties of {k}", flush=True)
        tris, ids = read_store_triangles(store)
        o3d = open3d_scene(tris)
        hits, seconds = open3d_cast(o3d, rays, ids, a.runs)
        speed["open3d"][scene] = len(rays) / seconds / 1e6
        d, t, m = compare(hits[:k], ref)
        wrong["open3d"][0] += d
        wrong["open3d"][1] += t
        wrong["open3d"][2] = max(wrong["open3d"][2], m)
        print(f"  {'open3d':15s} {speed['open3d'][scene]:6.2f} M rays/s, {d} wrong, {t} ties of {k}", flush=True)

    leaks = {c: 0 for c in names}
    aimed_total = 0
    for scene, (spec, interior) in AIMED_SCENES.items():
        store = pack(a.work, "aimed " + scene, [spec], 8192)
        tris, ids = read_store_triangles(store)
        rays = aimed_rays(tris, interior)
        rays_path = os.path.join(a.work, f"aimed-{scene.replace(' ', '_')}.npy")
        np.save(rays_path, rays)
        aimed_total += len(rays)
        for config, extra in CONFIGS.items():
            hits, _ = trace(store, rays_path, rays_path + f".{config}.hits.npy", extra)
            leaks[config] += int((hits["primitive_id"] == 0xFFFFFFFF).sum())
        hits, _ = open3d_cast(open3d_scene(tris), rays, ids, 1)
        leaks["open3d"] += int((hits["primitive_id"] == 0xFFFFFFFF).sum())
        print(f"aimed {scene}: {len(rays)} rays, leaks " + ", ".join(f"{c} {leaks[c]}" for c in names), flush=True)

    scenes = a.scenes.split(",")
    rows = []
    for c in names:
        geo = float(np.exp(np.mean(np.log([speed[c][s] for s in scenes]))))
        rows.append(dict(config=c, Mrays={s: speed[c][s] for s in scenes}, Mrays_geomean=geo,
                         leaks=leaks[c], aimed_rays=aimed_total, leak_rate=leaks[c] / aimed_total,
                         wrong=wrong[c][0], ties=wrong[c][1], checked=checked_total,
                         wrong_rate=wrong[c][0] / checked_total, max_rel_t=wrong[c][2]))
    by = {r["config"]: r for r in rows}
    print(f"\nload average (1 min) at start {load_before:.1f}, at end {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"{a.rays:,} incoherent rays per scene, {a.runs} warm runs (median), 2 threads; "
          f"{checked_total:,} rays checked against float64; {aimed_total:,} aimed rays\n")
    print("| configuration | " + " | ".join(f"{s} M rays/s" for s in scenes) +
          " | geomean | vs Open3D | leaks on aimed rays | wrong vs float64 (ties) | max rel t error |")
    print("|---|" + "---|" * (len(scenes) + 5))
    for r in rows:
        print(f"| {r['config']} | " + " | ".join(f"{r['Mrays'][s]:.2f}" for s in scenes) +
              f" | {r['Mrays_geomean']:.2f} | {r['Mrays_geomean'] / by['open3d']['Mrays_geomean']:.2f}x | "
              f"{r['leaks']} ({r['leak_rate'] * 100:.3f} %) | {r['wrong']} ({r['ties']}) | {r['max_rel_t']:.2g} |")
    if "bvh-mt" in by and "bvh-watertight" in by:
        ratio = by["bvh-mt"]["Mrays_geomean"] / by["bvh-watertight"]["Mrays_geomean"]
        print(f"\nwatertight cost: bvh-mt / bvh-watertight speed = {ratio:.2f}x (target <= 1.3x)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(dict(rows=rows, load_before=load_before, load_after=os.getloadavg()[0]), f, indent=1)
    if a.png:
        draw(rows, a.png)


def draw(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    floor = 1e-6
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    panels = [("leak_rate", "leak rate on aimed rays (closed meshes)"),
              ("wrong_rate", "disagreement with float64 on incoherent rays")]
    for ax, (key, title) in zip(axes, panels):
        pts = [(r["Mrays_geomean"], max(r[key], floor), r["config"]) for r in rows]
        for i, (x, y, name) in enumerate(pts):
            marker = "s" if name == "open3d" else "o"
            ax.scatter([x], [y], marker=marker, s=50)
            # Staggered labels: several configurations share the zero line.
            ax.annotate(name, (x, y), textcoords="offset points", xytext=(5, 5 + 11 * (i % 3)), fontsize=8)
        # Pareto front: faster and with less error is better.
        front, best = [], float("inf")
        for x, y, _ in sorted(pts, key=lambda p: -p[0]):
            if y < best:
                front.append((x, y))
                best = y
        ax.plot([p[0] for p in front], [p[1] for p in front], "--", color="gray", lw=1, label="Pareto front")
        ax.set_yscale("log")
        ax.set_ylim(floor / 2, 1)
        ax.axhline(floor, color="lightgray", lw=0.8)
        ax.text(ax.get_xlim()[0], floor * 1.15, " 0 (plotted at 1e-6)", fontsize=7, color="gray")
        ax.set_xlabel("M rays/s (geometric mean over scenes, 2 threads, warm)")
        ax.set_ylabel(title)
        ax.legend(fontsize=8)
    fig.suptitle("Outcore brick configurations: speed against error (Open3D 0.20 as a reference point)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
