#!/usr/bin/env python3
"""Out-of-core benchmark (issue 6): a generated city traced under cache budgets
that are fractions of its built size, for every eviction policy, next to
Belady's OPT replayed on the same request sequence, with peak RSS.

Steps:
1. pack `gen:city?of=(gen:sphere?level=5)&copies=C` (20,480 triangles a copy);
2. 1M incoherent and 1M camera rays (bench/make_rays.py);
3. unlimited budget (`--cache-mb` 65536), `--repeat 2`: the built size (peak
   accounted bytes), cold and warm seconds, peak RSS;
4. for each budget fraction F and policy P: `outcore trace --cache-mb F*built
   --policy P --repeat 2 --trace-out`: builds, bytes built and seconds of each
   run (cold, then warm: steady state), peak accounted bytes and peak RSS
   (wait4 of the process), bytes built (its own access trace's misses); the
   accounted peak must not exceed the budget;
5. OPT: `outcore cache-sim` of the LRU trace at the same budget (Belady,
   size-aware) — the fewest builds any policy could have had on that request
   sequence; each policy's builds are reported against it;
6. trace-ahead off (`--no-trace-ahead`) and proxies off (`--no-proxies`)
   for LRU at each budget below 1;
7. reorder off (`--no-reorder`) for LRU at each budget on a random subset of
   --noreorder-rays rays (rays one by one: far slower, so a subset).

Throughput is given two ways: cold (one batch from an empty cache: a scene
larger than memory served once) and warm (the second batch: steady state
under that budget), each against the unlimited run's cold and warm.

Every answer is compared with the unlimited run's hits file: any difference
is reported (there must be none).

Usage: .venv/bin/python bench/outofcore_bench.py [--copies 400] [--rays 1000000]
       [--fractions 0.0625,0.125,0.25,0.5,1] [--policies all] [--kinds incoherent,camera]
       [--no-compare-trace-ahead] [--no-compare-proxies]
       [--outcore build/client/outcore] [--work build/bench-ooc] [--json rows.json]
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUTCORE = os.path.join(ROOT, "build", "client", "outcore")
POLICIES = ["lru", "clock", "lfu", "arc", "s3fifo", "gdsf", "schedule"]


def run(cmd):
    """Runs cmd; returns (stdout, seconds)."""
    t0 = time.monotonic()
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{r.stderr}")
    return r.stdout, time.monotonic() - t0


def run_rss(cmd):
    """Runs cmd; returns (stdout, peak RSS MiB) using wait4."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"failed ({os.waitstatus_to_exitcode(status)}): {' '.join(cmd)}")
    return out.decode(), usage.ru_maxrss / 1024.0


def trace(store, rays, out, cache_mb, policy, extra=(), trace_out=None):
    stats_path = out + ".stats.json"
    cmd = [OUTCORE, "trace", store, "--rays", rays, "-o", out, "--threads", "2", "--cache-mb", str(cache_mb),
           "--policy", policy, "--repeat", "2", "--stats-json", stats_path, *extra]
    if trace_out:
        cmd += ["--trace-out", trace_out]
    _, rss = run_rss(cmd)
    with open(stats_path) as f:
        stats = json.load(f)
    return stats, rss


def bytes_built_mib(trace_path):
    """MiB of bricks built (misses) in an access trace."""
    total = 0
    with open(trace_path) as f:
        for line in f:
            if line.startswith("#") or line.startswith("seq"):
                continue
            fields = line.rstrip("\n").split(",")
            if fields[5] == "miss":
                total += int(fields[2])
    return total / 2**20


def same_file(a, b):
    with open(a, "rb") as fa, open(b, "rb") as fb:
        return fa.read() == fb.read()


def main():
    global OUTCORE
    ap = argparse.ArgumentParser()
    ap.add_argument("--copies", type=int, default=400)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--fractions", default="0.0625,0.125,0.25,0.5,1")
    ap.add_argument("--policies", default="all")
    ap.add_argument("--kinds", default="incoherent,camera")
    ap.add_argument("--noreorder-rays", type=int, default=20000)
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-ooc"))
    ap.add_argument("--outcore", default=OUTCORE)
    ap.add_argument("--json")
    ap.add_argument("--no-compare-trace-ahead", action="store_true")
    ap.add_argument("--no-compare-proxies", action="store_true")
    a = ap.parse_args()
    OUTCORE = os.path.abspath(a.outcore)
    policies = POLICIES if a.policies == "all" else a.policies.split(",")
    fractions = [float(f) for f in a.fractions.split(",")]
    os.makedirs(a.work, exist_ok=True)
    load_before = os.getloadavg()[0]
    spec = f"gen:city?of=(gen:sphere?level=5)&copies={a.copies}"
    store = os.path.join(a.work, f"city{a.copies}.oc")
    if not os.path.isdir(store):
        print(f"packing {spec}", flush=True)
        run([OUTCORE, "pack", spec, "-o", store, "-q"])
    info_path = os.path.join(a.work, f"city{a.copies}.json")
    with open(info_path, "w") as f:
        f.write(run([OUTCORE, "info", store, "--json"])[0])
    with open(info_path) as f:
        info = json.load(f)
    rows = []
    for kind in a.kinds.split(","):
        rays = os.path.join(a.work, f"{kind}.npy")
        run([sys.executable, os.path.join(ROOT, "bench", "make_rays.py"), info_path, kind, str(a.rays), rays])
        ref_out = os.path.join(a.work, f"{kind}-unlimited.npy")
        stats, rss = trace(store, rays, ref_out, 65536, "lru")
        built = stats[0]["peak_bytes_resident"]
        unlimited = dict(kind=kind, fraction="unlimited", policy="lru", budget_mib=65536,
                         builds_cold=stats[0]["brick_builds"], builds_warm=stats[1]["brick_builds"],
                         seconds_cold=stats[0]["seconds"]["total"], seconds_warm=stats[1]["seconds"]["total"],
                         peak_accounted_mib=built / 2**20, peak_rss_mib=rss, same_answers=True)
        rows.append(unlimited)
        print(json.dumps(unlimited), flush=True)
        subset = os.path.join(a.work, f"{kind}-subset.npy")
        # A random subset: the first rays of a camera batch are one corner of
        # the image (which may miss everything).
        all_rays = np.load(rays)
        picked = np.sort(np.random.default_rng(7).choice(len(all_rays), size=min(len(all_rays), a.noreorder_rays),
                                                         replace=False))
        np.save(subset, all_rays[picked])
        for fraction in fractions:
            budget_mib = max(1, int(built * fraction / 2**20))
            lru_trace = os.path.join(a.work, f"{kind}-{fraction}-lru.csv")
            for policy in policies:
                out = os.path.join(a.work, f"{kind}-{fraction}-{policy}.npy")
                run_trace = lru_trace if policy == "lru" else os.path.join(a.work, f"{kind}-{fraction}-{policy}.csv")
                stats, rss = trace(store, rays, out, budget_mib, policy, trace_out=run_trace)
                row = dict(kind=kind, fraction=fraction, policy=policy, budget_mib=budget_mib,
                           builds_cold=stats[0]["brick_builds"], builds_warm=stats[1]["brick_builds"],
                           seconds_cold=stats[0]["seconds"]["total"], seconds_warm=stats[1]["seconds"]["total"],
                           peak_accounted_mib=max(s["peak_bytes_resident"] for s in stats) / 2**20,
                           peak_rss_mib=rss, same_answers=same_file(out, ref_out),
                           bytes_built_mib=bytes_built_mib(run_trace))
                rows.append(row)
                print(json.dumps(row), flush=True)
            sim = json.loads(run([OUTCORE, "cache-sim", lru_trace, "--policy", "lru", "--budget-mb", str(budget_mib),
                                  "--json"])[0])
            opt = next(r for r in sim["results"] if r["policy"] == "opt")
            rows.append(dict(kind=kind, fraction=fraction, policy="opt (replay of the lru trace)",
                             budget_mib=budget_mib, builds_total=opt["misses"],
                             bytes_built_mib=opt["bytes_built"] / 2**20))
            print(json.dumps(rows[-1]), flush=True)
            comparisons = []
            if fraction < 1 and not a.no_compare_trace_ahead:
                comparisons.append(("noahead", "--no-trace-ahead"))
            if fraction < 1 and not a.no_compare_proxies:
                comparisons.append(("noproxies", "--no-proxies"))
            for tag, flag in comparisons:
                out = os.path.join(a.work, f"{kind}-{fraction}-{tag}.npy")
                run_trace = os.path.join(a.work, f"{kind}-{fraction}-{tag}.csv")
                stats, rss = trace(store, rays, out, budget_mib, "lru", extra=[flag], trace_out=run_trace)
                rows.append(dict(kind=kind, fraction=fraction, policy=f"lru {flag}", budget_mib=budget_mib,
                                 builds_cold=stats[0]["brick_builds"], builds_warm=stats[1]["brick_builds"],
                                 seconds_cold=stats[0]["seconds"]["total"],
                                 seconds_warm=stats[1]["seconds"]["total"],
                                 peak_accounted_mib=max(s["peak_bytes_resident"] for s in stats) / 2**20,
                                 peak_rss_mib=rss, same_answers=same_file(out, ref_out),
                                 bytes_built_mib=bytes_built_mib(run_trace)))
                print(json.dumps(rows[-1]), flush=True)
            out = os.path.join(a.work, f"{kind}-{fraction}-noreorder.npy")
            stats, rss = trace(store, subset, out, budget_mib, "lru", extra=["--no-reorder"])
            rows.append(dict(kind=kind, fraction=fraction, policy="lru --no-reorder", rays=a.noreorder_rays,
                             budget_mib=budget_mib, builds_cold=stats[0]["brick_builds"],
                             builds_warm=stats[1]["brick_builds"], seconds_cold=stats[0]["seconds"]["total"],
                             seconds_warm=stats[1]["seconds"]["total"], peak_rss_mib=rss,
                             same_answers=np.load(out).tobytes() == np.load(ref_out)[picked].tobytes()))
            print(json.dumps(rows[-1]), flush=True)
    print(f"\nscene {spec}: {info['triangles']:,} triangles, {info['bricks']} bricks; load average "
          f"{load_before:.1f} before, {os.getloadavg()[0]:.1f} after, {os.cpu_count()} cores")
    print("\n| rays | budget | policy | builds (cold + warm) | vs OPT | MiB built | cold M rays/s | cold vs unlimited "
          "| warm M rays/s | warm vs unlimited | peak accounted MiB | peak RSS MiB | answers = unlimited |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    by_key = {}
    for r in rows:
        by_key[(r["kind"], r["fraction"], r["policy"])] = r
    for r in rows:
        if r["policy"].startswith("opt"):
            continue
        kind, frac = r["kind"], r["fraction"]
        unl = by_key[(kind, "unlimited", "lru")]
        n = r.get("rays", a.rays)
        builds = r["builds_cold"] + r["builds_warm"]
        opt = by_key.get((kind, frac, "opt (replay of the lru trace)"))
        vs_opt = f"{builds / opt['builds_total']:.2f}x" if opt and "rays" not in r else ""
        cold = n / r["seconds_cold"] / 1e6
        warm = n / r["seconds_warm"] / 1e6
        vs_cold = "" if "rays" in r else f"{unl['seconds_cold'] / r['seconds_cold']:.2f}x"
        vs = "" if "rays" in r else f"{unl['seconds_warm'] / r['seconds_warm']:.2f}x"
        budget = "unlimited" if frac == "unlimited" else f"{frac:g} ({r['budget_mib']} MiB)"
        built_mib = f"{r['bytes_built_mib']:.0f}" if "bytes_built_mib" in r else ""
        print(f"| {kind} | {budget} | {r['policy']} | {builds} | {vs_opt} | {built_mib} | {cold:.2f} | {vs_cold} | "
              f"{warm:.2f} | {vs} | "
              f"{r.get('peak_accounted_mib', float('nan')):.0f} | {r['peak_rss_mib']:.0f} | "
              f"{'yes' if r.get('same_answers', True) else 'NO'} |")
    for r in rows:
        if r["policy"].startswith("opt"):
            print(f"OPT at {r['kind']} {r['fraction']:g} ({r['budget_mib']} MiB): {r['builds_total']} builds, "
                  f"{r['bytes_built_mib']:.0f} MiB built")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
