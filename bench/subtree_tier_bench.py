#!/usr/bin/env python3
"""Subtree tier benchmark (issue 6 item 5): the cost of a brick miss with and
without the serialised-subtree tier, and trace throughput at a small budget
with and without it against an unlimited budget, all with `--brick-accel bvh`.

Steps:
1. pack `gen:city?of=(gen:sphere?level=5)&copies=C` and make N incoherent
   rays (bench/make_rays.py);
2. each round runs, one after another (so every ratio compares runs made
   under the same machine load):
   - unlimited (`--cache-mb 65536`), `--repeat 2`;
   - budget F * built size without the tier, `--repeat 2 --trace-out`;
   - the same budget with `--subtree-dir` (a fresh directory each round, so
     run 1 builds and writes every brick, run 2 loads what was evicted),
     `--repeat 2 --trace-out`;
   the warm run (run 2) of each is the steady state under that budget;
3. per-miss cost from the access traces: build_seconds of "miss" records
   (store load + bvh build) against "load" records (map + checksum +
   deserialise the subtree file), medians over all misses of all rounds;
4. the median over rounds of each throughput and ratio.

Every answer is compared bitwise with the unlimited run's hits file.

Usage: .venv/bin/python bench/subtree_tier_bench.py [--copies 200] [--rays 500000]
       [--fraction 0.25] [--rounds 3] [--outcore build/client/outcore]
       [--work build/bench-subtree] [--json rows.json]
"""
import argparse
import csv
import json
import os
import shutil
import statistics
import sys

from trace_bench import run  # runs a command, exits with its stderr on failure

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def read_trace(path):
    """{outcome: [build_seconds]} of an access trace CSV."""
    by_outcome = {}
    with open(path) as f:
        rows = csv.DictReader(line for line in f if not line.startswith("#"))
        for row in rows:
            by_outcome.setdefault(row["outcome"], []).append(float(row["build_seconds"]))
    return by_outcome


def same_file(a, b):
    with open(a, "rb") as fa, open(b, "rb") as fb:
        return fa.read() == fb.read()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--copies", type=int, default=200)
    ap.add_argument("--rays", type=int, default=500000)
    ap.add_argument("--fraction", type=float, default=0.25)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--outcore", default=os.path.join(ROOT, "build", "client", "outcore"))
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-subtree"))
    ap.add_argument("--json")
    a = ap.parse_args()
    outcore = a.outcore
    os.makedirs(a.work, exist_ok=True)
    spec = f"gen:city?of=(gen:sphere?level=5)&copies={a.copies}"
    store = os.path.join(a.work, f"city{a.copies}")
    if not os.path.exists(os.path.join(store, "manifest.bin")):
        print(f"packing {spec}", flush=True)
        run([outcore, "pack", spec, "-o", store, "-q"])
    info = os.path.join(a.work, "info.json")
    with open(info, "w") as f:
        f.write(run([outcore, "info", store, "--json"]))
    rays = os.path.join(a.work, f"incoherent-{a.rays}.npy")
    if not os.path.exists(rays):
        run([sys.executable, os.path.join(ROOT, "bench", "make_rays.py"), info, "incoherent", str(a.rays), rays])

    def trace(name, cache_mb, extra=()):
        out = os.path.join(a.work, name + ".npy")
        stats_path = out + ".json"
        run([outcore, "trace", store, "--rays", rays, "-o", out, "--threads", str(a.threads), "--brick-accel",
             "bvh", "--cache-mb", str(cache_mb), "--repeat", "2", "--stats-json", stats_path, *extra])
        with open(stats_path) as f:
            return json.load(f), out

    rounds = []
    miss_costs, load_costs = [], []
    budget_mb = None
    for r in range(a.rounds):
        unlimited, reference = trace("unlimited", 65536)
        built_mb = unlimited[0]["peak_bytes_resident"] / 2**20
        budget_mb = budget_mb or max(1, int(a.fraction * built_mb))
        trace_plain = os.path.join(a.work, "plain.csv")
        plain, plain_out = trace("plain", budget_mb, ["--trace-out", trace_plain])
        tier_dir = os.path.join(a.work, "subtrees")
        shutil.rmtree(tier_dir, ignore_errors=True)
        trace_tier = os.path.join(a.work, "tier.csv")
        tier, tier_out = trace("tier", budget_mb, ["--subtree-dir", tier_dir, "--trace-out", trace_tier])
        miss_costs += read_trace(trace_plain).get("miss", [])
        load_costs += read_trace(trace_tier).get("load", [])
        warm = lambda s: s[1]["rays_per_second"] / 1e6
        row = {
            "round": r + 1,
            "built_mb": built_mb,
            "budget_mb": budget_mb,
            "unlimited_warm_mrays": warm(unlimited),
            "plain_warm_mrays": warm(plain),
            "tier_warm_mrays": warm(tier),
            "plain_vs_unlimited": warm(plain) / warm(unlimited),
            "tier_vs_unlimited": warm(tier) / warm(unlimited),
            "tier_vs_plain": warm(tier) / warm(plain),
            "plain_cold_s": plain[0]["seconds"]["total"],
            "tier_cold_s": tier[0]["seconds"]["total"],
            "plain_warm_builds": plain[1]["brick_builds"],
            "tier_warm_builds": tier[1]["brick_builds"],
            "tier_warm_loads": tier[1]["subtree_loads"],
            # Loads that mapped nothing: the brick's own copy still populated
            # (kept) or another evicted brick's queued copy (recycled).
            "tier_warm_loads_kept": tier[1].get("subtree_loads_kept", 0),
            "tier_warm_loads_recycled": tier[1].get("subtree_loads_recycled", 0),
            "tier_cold_writes": tier[0]["subtree_writes"],
            "tier_mb_written": tier[0]["subtree_bytes_written"] / 2**20,
            "answers_equal": same_file(plain_out, reference) and same_file(tier_out, reference),
        }
        rounds.append(row)
        print(json.dumps(row), flush=True)

    med = lambda key: statistics.median(row[key] for row in rounds)
    summary = {
        "scene": spec,
        "rays": a.rays,
        "budget_mb": budget_mb,
        "built_mb": med("built_mb"),
        "median_miss_build_ms": 1e3 * statistics.median(miss_costs) if miss_costs else None,
        "median_miss_load_ms": 1e3 * statistics.median(load_costs) if load_costs else None,
        "misses_measured": len(miss_costs),
        "loads_measured": len(load_costs),
        **{f"median_{k}": med(k) for k in ["unlimited_warm_mrays", "plain_warm_mrays", "tier_warm_mrays",
                                           "plain_vs_unlimited", "tier_vs_unlimited", "tier_vs_plain",
                                           "plain_cold_s", "tier_cold_s"]},
        "all_answers_equal": all(row["answers_equal"] for row in rounds),
    }
    print(json.dumps(summary, indent=1))
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"rounds": rounds, "summary": summary}, f, indent=1)


if __name__ == "__main__":
    main()
