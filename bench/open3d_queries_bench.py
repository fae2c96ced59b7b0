#!/usr/bin/env python3
"""Open3D's other RaycastingScene calls through `outcore serve` (issue 28):
count_intersections, list_intersections, compute_closest_points and
compute_distance with the Python client over loopback gRPC, against Open3D
0.20 in process (nthreads=2) on the triangles read back from the same store,
same points and rays, same run.

For each scene (bunny, city: trace_bench.SCENES): the server runs with
--threads 2 --cache-mb 8192, one warm-up call of each kind builds the bricks;
then the median wall time of R calls (numpy in and out, the wire included);
Open3D likewise (after a one-element call that builds its BVH). Rays: the
scene's incoherent rays (bench/make_rays.py); points: uniform in the scene's
box grown by 10 % of its size. Answers are checked: counts equal on >= 99.9 %
of rays (the rest: edge grazes, where float tests may rightly differ),
distances within 1e-5 of the scene's diagonal of Open3D's (Open3D
computes in float32).

Writes rows as JSON (--json) and a bar chart of the ratios as PNG (--png).
Usage: .venv-bench/bin/python bench/open3d_queries_bench.py [--runs 5] [--scenes bunny,city]
       [--rays 200000] [--points 100000] [--work build/bench-o3d] [--json rows.json] [--png chart.png]
"""
import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import OUTCORE, make_rays, open3d_scene, prepare_store, read_store_triangles  # noqa: E402
from remote_bench import Server  # noqa: E402
from trace_bench import SCENES  # noqa: E402


def timed(fn, runs):
    fn()  # warm-up: bricks built (ours), BVH built (Open3D)
    times, result = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def bench_scene(name, args):
    import open3d as o3d
    import outcore
    store, info_path = prepare_store(OUTCORE, args.work, name, SCENES[name])
    rays = make_rays(info_path, "incoherent", args.rays, os.path.join(args.work, f"{name}_o3d_rays.npy"))
    rays6 = np.ascontiguousarray(rays[:, :6])
    with open(info_path) as f:
        info = json.load(f)
    lo, hi = np.array(info["bounds"]["min"]), np.array(info["bounds"]["max"])
    grow = 0.1 * (hi - lo)
    points = np.random.default_rng(1).uniform(lo - grow, hi + grow, (args.points, 3)).astype(np.float32)
    tris, _ = read_store_triangles(store)
    scene = open3d_scene(tris)
    rays_t, points_t = o3d.core.Tensor(rays6), o3d.core.Tensor(points)
    server = Server(store)
    rows = []
    try:
        with outcore.SceneClient(server.address, timeout=600) as client:
            calls = {
                "count_intersections": (lambda: client.count_intersections(rays6),
                                        lambda: scene.count_intersections(rays_t, nthreads=2).numpy(), args.rays),
                "list_intersections": (lambda: client.list_intersections(rays6),
                                       lambda: scene.list_intersections(rays_t, nthreads=2), args.rays),
                "compute_closest_points": (lambda: client.compute_closest_points(points),
                                           lambda: scene.compute_closest_points(points_t, nthreads=2), args.points),
                "compute_distance": (lambda: client.compute_distance(points),
                                     lambda: scene.compute_distance(points_t, nthreads=2).numpy(), args.points),
            }
            for call, (ours, theirs, n) in calls.items():
                print(f"{name} {call}", flush=True)
                ours_s, ours_r = timed(ours, args.runs)
                theirs_s, theirs_r = timed(theirs, args.runs)
                check = check_answers(call, ours_r, theirs_r, float(np.linalg.norm(hi - lo)))
                rows.append({"scene": name, "call": call, "items": n, "outcore_s": ours_s, "open3d_s": theirs_s,
                             "ratio": theirs_s / ours_s, "check": check})
                print(f"  outcore {ours_s:.3f} s, open3d {theirs_s:.3f} s, ratio {theirs_s / ours_s:.2f} ({check})",
                      flush=True)
    finally:
        server.stop()
    return rows


def check_answers(call, ours, theirs, diagonal):
    if call == "count_intersections":
        same = float(np.mean(ours == theirs))
        if same < 0.999:
            sys.exit(f"{call}: only {same:.4%} of counts equal Open3D's")
        return f"counts equal on {same:.4%}"
    if call == "list_intersections":
        total, their_total = int(ours["ray_splits"][-1]), int(theirs["ray_splits"].numpy()[-1])
        if abs(total - their_total) > 0.001 * their_total:
            sys.exit(f"{call}: {total} hits, Open3D {their_total}")
        return f"{total} hits, Open3D {their_total}"
    if call == "compute_closest_points":
        d = np.linalg.norm(ours["points"] - theirs["points"].numpy(), axis=1)
        return f"closest points within {float(d.max()):.2e} of Open3D's"
    # Open3D works in float32: its distances are off by rounding at the
    # scene's scale, so the difference is judged against the scene's size.
    gap = float(np.max(np.abs(ours.astype(np.float64) - theirs)))
    if gap > 1e-5 * diagonal:
        sys.exit(f"{call}: distances differ from Open3D's by up to {gap:.2e} (scene diagonal {diagonal:.3g})")
    return f"max difference {gap:.2e} ({gap / diagonal:.1e} of the scene's diagonal)"


def draw(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    labels = [f"{r['scene']}\n{r['call'].replace('compute_', '').replace('_intersections', '')}" for r in rows]
    fig, ax = plt.subplots(figsize=(max(6, len(rows) * 0.9), 4))
    ax.bar(range(len(rows)), [r["ratio"] for r in rows], color="#3b528b")
    ax.axhline(0.8, color="#d62728", linestyle="--", label="target 0.8x")
    ax.axhline(1.0, color="gray", linewidth=0.8)
    ax.set_xticks(range(len(rows)), labels, fontsize=8)
    ax.set_ylabel("Open3D time / Outcore time (> 1: Outcore faster)")
    ax.set_title("Open3D's calls through outcore serve (Python client, loopback)\n"
                 "against Open3D 0.20 in process, same run", fontsize=10)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    global OUTCORE
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--scenes", default="bunny,city")
    ap.add_argument("--rays", type=int, default=200_000)
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--work", default=os.path.join("build", "bench-o3d"))
    ap.add_argument("--json")
    ap.add_argument("--png")
    args = ap.parse_args()
    os.makedirs(args.work, exist_ok=True)
    rows = []
    for name in args.scenes.split(","):
        rows += bench_scene(name, args)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)
    if args.png:
        draw(rows, args.png)


if __name__ == "__main__":
    main()
