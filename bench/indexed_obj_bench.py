#!/usr/bin/env python3
"""Indexed OBJ pack benchmark: `outcore pack` of one large indexed OBJ with the
reader holding every vertex position in memory vs resolving its faces out of
core (core/io/indexed_mesh.h), at the same --mem-mb, measured in the same run.

The OBJ is an n x n heightfield grid (n^2 vertices, then 2 (n-1)^2 triangles,
row by row), written with awk because Python is too slow for tens of millions
of lines. The two modes differ only in --vertex-mem-mb: large enough for the
vertices (in memory) or 0 (an eighth of --mem-mb, which the vertices exceed:
out of core). Runs alternate between the modes; medians over --runs.
Reports pack seconds and peak RSS (wait4) per mode and their ratios.

Usage: .venv/bin/python bench/indexed_obj_bench.py [--n 3900] [--runs 3] [--mem-mb 1024]
"""
import argparse
import os
import shutil
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pack_bench import ROOT, run_pack  # noqa: E402

# Vertices first, then two triangles per grid cell; 1-based indices.
AWK_GRID_OBJ = r"""BEGIN {
  for (r = 0; r < n; r++) for (c = 0; c < n; c++)
    printf "v %d %.4f %d\n", c, 40 * sin(c * 0.0123) * cos(r * 0.0171) + 3 * sin(c * r * 1e-5), r
  for (r = 0; r + 1 < n; r++) for (c = 0; c + 1 < n; c++) {
    i = r * n + c + 1
    printf "f %d %d %d\nf %d %d %d\n", i, i + 1, i + n, i + 1, i + n + 1, i + n
  }
}"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=3900, help="grid side: n^2 vertices, 2 (n-1)^2 triangles")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--mem-mb", type=int, default=1024)
    ap.add_argument("--brick-tris", type=int, default=32768)
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-indexed-obj"))
    ap.add_argument("--binary", default=os.path.join(ROOT, "build", "client", "outcore"))
    args = ap.parse_args()
    os.makedirs(args.work, exist_ok=True)
    obj = os.path.join(args.work, f"grid-{args.n}.obj")
    vertex_mib = args.n * args.n * 12 / 2**20
    # In memory: room for every vertex (the option allows up to half of --mem-mb).
    in_memory_mb = int(vertex_mib) + 1
    if in_memory_mb > args.mem_mb // 2 or vertex_mib <= args.mem_mb / 8:
        sys.exit(f"{vertex_mib:.0f} MiB of vertices must lie between --mem-mb/8 and --mem-mb/2")
    with open(obj, "w") as f:
        subprocess.run(["awk", "-v", f"n={args.n}", AWK_GRID_OBJ], stdout=f, check=True)
    print(f"{obj}: {os.path.getsize(obj) / 2**30:.2f} GiB, {args.n**2} vertices ({vertex_mib:.0f} MiB), "
          f"{2 * (args.n - 1)**2} triangles", flush=True)
    print(f"load average before: {os.getloadavg()}", flush=True)
    modes = {"in memory": in_memory_mb, "out of core": 0}
    results = {mode: [] for mode in modes}
    out = os.path.join(args.work, "grid.oc")
    try:
        for run in range(args.runs):
            for mode, vertex_mb in modes.items():
                pack = run_pack(args.binary, obj, out, args.mem_mb, args.brick_tris,
                                extra_args=["--vertex-mem-mb", str(vertex_mb), "--no-sync", "-q"])
                results[mode].append(pack)
                print(f"run {run + 1}/{args.runs} {mode}: {pack['seconds']:.1f} s, peak RSS "
                      f"{pack['peak_rss'] / 2**20:.0f} MiB, phases {pack['phases']}", flush=True)
    finally:
        shutil.rmtree(out, ignore_errors=True)
        os.remove(obj)
    print(f"load average after: {os.getloadavg()}")
    median = {mode: (statistics.median(p["seconds"] for p in packs),
                     statistics.median(p["peak_rss"] for p in packs) / 2**20) for mode, packs in results.items()}
    print("| mode | --vertex-mem-mb | pack s | peak RSS MiB |")
    print("|---|---|---|---|")
    for mode, (seconds, rss) in median.items():
        print(f"| {mode} | {modes[mode]} | {seconds:.1f} | {rss:.0f} |")
    (s_mem, r_mem), (s_ooc, r_ooc) = median["in memory"], median["out of core"]
    print(f"out of core / in memory: time {s_ooc / s_mem:.2f}x, peak RSS {r_ooc / r_mem:.2f}x")


if __name__ == "__main__":
    main()
