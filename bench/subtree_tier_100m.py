#!/usr/bin/env python3
"""Subtree tier at 100 M triangles: warm-batch throughput at a quarter of the
built size against the unlimited budget, rounds interleaved, medians.

Each round runs `outcore trace --brick-accel bvh --threads 2` (or the
--brick-accel given) processes on the
same store and rays:
  unlimited   --cache-mb 65536, no tier (the peer: heap-built bricks)
  tier        --cache-mb BUILT/4 --subtree-dir on a fresh directory (batch 1
              builds and writes every brick, later batches load evicted ones)
  restarted   the same budget and directory in a new process, once per
              policy (batch 1 checks every file in full, later batches trust
              them): a server restarted on a warm directory; in the first
              round also at other fractions of the built size (--sweep)
  unbatched   restarted lru with --subtree-release-batch-mb 0 (each evicted
              brick's pages released at once), with --compare-unbatched
  no tier     the same budget without the tier (first round only: slow)
A warm batch is any batch after the first; a run's figure is the median of
its warm batches, a row's the median over rounds of (run / unlimited run of
the same round). Every hits file is compared bitwise with the unlimited one.
Peak RSS is the process's (wait4). Unless --no-camera, the first round
also runs the camera rays (unlimited and restarted at a quarter of the
camera's own built size). Heavy runs are ordered so that the tier's files
stay in the page cache while tier runs are measured.

Usage: subtree_tier_100m.py WORK_DIR [--rounds 3] [--repeat 5] [--no-camera] [--compare-unbatched]
       [--brick-accel bvh|auto|...] [--policies lru,gdsf] [--sweep 0.0625,0.125,0.5,1]
The store (WORK_DIR/city4883.oc, `gen:city?of=(gen:sphere?level=5)&copies=4883`,
4.1 GiB) and the 1 M-ray files are made on first use.
"""
import argparse
import filecmp
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))
import common  # noqa: E402


BRICK_ACCEL = "bvh"


def run_trace(outcore, work, rays, out, budget_mb, repeat, extra, log):
    stats = work / (out + ".json")
    cmd = [str(outcore), "trace", "city4883.oc", "--rays", rays, "-o", out + ".npy", "--brick-accel", BRICK_ACCEL,
           "--cache-mb", str(budget_mb), "--threads", "2", "--repeat", str(repeat), "--stats-json",
           stats.name] + extra
    start = time.time()
    with open(work / (out + ".log"), "w") as f:
        proc = subprocess.Popen(cmd, cwd=work, stdout=f, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"failed: {' '.join(cmd)} (see {work / (out + '.log')})")
    runs = json.loads(stats.read_text())
    row = {
        "batches": [r["seconds"]["total"] for r in runs],
        "warm": statistics.median(r["seconds"]["total"] for r in runs[1:]),
        "builds": [r["brick_builds"] for r in runs],
        "loads": [r.get("subtree_loads", 0) for r in runs],
        "checked": [r.get("subtree_loads_checked", 0) for r in runs],
        "built_mib": runs[0]["peak_bytes_resident"] / 2**20,
        "rss_mib": usage.ru_maxrss / 1024,
        "builds_by_structure": {k: sum(r.get("brick_builds_by_structure", {}).get(k, 0) for r in runs)
                                for k in runs[0].get("brick_builds_by_structure", {})},
        "rebuilds": sum(r.get("brick_rebuilds", 0) for r in runs),
        "wall": time.time() - start,
    }
    log(f"  {out:<22} warm {row['warm']:.3f} s  batches {[round(b, 3) for b in row['batches']]}  "
        f"builds {row['builds']}  loads {row['loads']}  RSS {row['rss_mib']:.0f} MiB  ({row['wall']:.0f} s)"
        + (f"  by structure {row['builds_by_structure']} rebuilds {row['rebuilds']}" if BRICK_ACCEL == "auto" else ""))
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("work", type=Path)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--policies", default="lru,gdsf")
    ap.add_argument("--outcore", type=Path, default=ROOT / "build/client/outcore")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--no-camera", action="store_true")
    ap.add_argument("--brick-accel", default="bvh", help="the structure every run uses (bvh, auto, ...)")
    ap.add_argument("--compare-unbatched", action="store_true",
                    help="also a restarted lru run with --subtree-release-batch-mb 0 in every round")
    ap.add_argument("--sweep", default="0.0625,0.125,0.5,1",
                    help="first round only: restarted lru runs at these fractions of the built size")
    args = ap.parse_args()
    global BRICK_ACCEL
    BRICK_ACCEL = args.brick_accel
    args.outcore = args.outcore.resolve()  # the runs' working directory is WORK_DIR
    work = args.work.resolve()
    work.mkdir(parents=True, exist_ok=True)
    _, info = common.prepare_store(str(args.outcore), str(work), "city4883",
                                   ["gen:city?of=(gen:sphere?level=5)&copies=4883"])
    kinds = ["incoherent"] + ([] if args.no_camera else ["camera"])
    for kind in kinds:
        if not (work / f"{kind}.npy").exists():
            common.make_rays(info, kind, 1_000_000, str(work / f"{kind}.npy"))
    log = lambda s: print(s, flush=True)
    policies = args.policies.split(",")
    rows = {}
    camera = not args.no_camera

    def add(name, row, peer):
        row["same"] = filecmp.cmp(work / (name + ".npy"), work / (peer + ".npy"), shallow=False)
        if not row["same"]:
            sys.exit(f"{name}: hits differ from {peer}")
        rows.setdefault(name, []).append(row)

    # The heavy runs (unlimited heaps of 8-9 GiB, the slow no-tier run) come
    # before the tier directory is written or after every tier run: between
    # them they would push its files out of the page cache, and the tier's
    # loads would then be measured from the disk.
    for r in range(args.rounds):
        log(f"round {r + 1}/{args.rounds} ({os.getloadavg()[0]:.2f} load)")
        first = r == 0
        unl = run_trace(args.outcore, work, "incoherent.npy", "unlimited", 65536, args.repeat, [], log)
        add("unlimited", unl, "unlimited")
        quarter = int(unl["built_mib"] / 4)
        cam = None
        if first and camera:
            cam = run_trace(args.outcore, work, "camera.npy", "camera-unlimited", 65536, args.repeat, [], log)
            add("camera-unlimited", cam, "camera-unlimited")
        tier = work / "tier"
        shutil.rmtree(tier, ignore_errors=True)
        row = run_trace(args.outcore, work, "incoherent.npy", "tier", quarter, args.repeat,
                        ["--subtree-dir", "tier"], log)
        row["ratio"] = unl["warm"] / row["warm"]
        add("tier", row, "unlimited")
        for policy in policies:
            name = f"restarted-{policy}"
            row = run_trace(args.outcore, work, "incoherent.npy", name, quarter, args.repeat,
                            ["--subtree-dir", "tier", "--policy", policy], log)
            row["ratio"] = unl["warm"] / row["warm"]
            add(name, row, "unlimited")
        if args.compare_unbatched:
            row = run_trace(args.outcore, work, "incoherent.npy", "restarted-lru-unbatched", quarter, args.repeat,
                            ["--subtree-dir", "tier", "--subtree-release-batch-mb", "0"], log)
            row["ratio"] = unl["warm"] / row["warm"]
            add("restarted-lru-unbatched", row, "unlimited")
        if first:
            for fraction in [float(f) for f in args.sweep.split(",") if f]:
                name = f"restarted-lru-{fraction:g}"
                row = run_trace(args.outcore, work, "incoherent.npy", name, int(unl["built_mib"] * fraction),
                                args.repeat, ["--subtree-dir", "tier"], log)
                row["ratio"] = unl["warm"] / row["warm"]
                add(name, row, "unlimited")
            if cam is not None:
                row = run_trace(args.outcore, work, "camera.npy", "camera-restarted-lru", int(cam["built_mib"] / 4),
                                args.repeat, ["--subtree-dir", "tier"], log)
                row["ratio"] = cam["warm"] / row["warm"]
                add("camera-restarted-lru", row, "camera-unlimited")
            shutil.rmtree(tier, ignore_errors=True)
            row = run_trace(args.outcore, work, "incoherent.npy", "no-tier", quarter, 2, [], log)
            row["ratio"] = unl["warm"] / row["warm"]
            add("no-tier", row, "unlimited")
        shutil.rmtree(tier, ignore_errors=True)

    log("\nrun                    warm s (median)  vs unlimited (median; range)  loads/warm batch  peak RSS MiB")
    for name, runs in rows.items():
        warm = statistics.median(x["warm"] for x in runs)
        ratios = [x["ratio"] for x in runs if "ratio" in x]
        ratio = (f"{statistics.median(ratios):.2f}x ({min(ratios):.2f}-{max(ratios):.2f})" if ratios else "1.00x")
        loads = statistics.median(l for x in runs for l in x["loads"][1:])
        rss = max(x["rss_mib"] for x in runs)
        log(f"{name:<22} {warm:>8.3f}         {ratio:<29} {loads:>8.0f}        {rss:>8.0f}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
