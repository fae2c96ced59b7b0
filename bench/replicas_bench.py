#!/usr/bin/env python3
"""Replicas with cache-affinity routing (issue 30): brick builds and
throughput of 4 replicas at budget B each on a scene of about 4 B, routed by
brick (outcore.SceneClient([...]), the default: each replica owns a part of
the bricks and traces every ray in it) or by ray (routing="rays": each ray to
one replica by its entry cell), against one server at budget 4 B and
against round-robin over the same replicas (each batch whole to the next
replica, as a per-connection load balancer does); throughput with 1, 2 and 4
replicas; the share of keys (bricks, or rays' cells) that move when a
replica joins, and the peak load per replica (triangles owned, or rays).

For each ray kind (incoherent, camera; bench/make_rays.py with a new seed per
batch: a camera elsewhere on the sphere each time), fresh servers, then
--batches batches of 1 M rays; builds are the sum over the servers of
GetStats brick_builds, per batch after the first (the cold one is reported
apart). Answers of every configuration are checked equal to the one-server
run's. The machine has 2 cores: every replica shares them, so throughput
does not scale here; the build counts are the portable figure.

Usage: .venv-bench/bin/python bench/replicas_bench.py [--batches 4] [--rays 1000000]
       [--json docs/data/replicas_bench.json]
"""
import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import remote_bench  # noqa: E402
from common import OUTCORE, ROOT, prepare_store, run  # noqa: E402

SCENE = "gen:city?copies=400"
# The city of 400 copies builds to 36.3 MiB with bvh bricks of 8,192
# triangles (81 bricks), to 37.0 MiB with bricks of 2,048 (326): 4.0x and
# 4.1x this.
BUDGET_MB = 9


def builds(clients):
    return sum(c.stats()["brick_builds"] for c in clients)


def run_config(name, store, batches, budget_mb, replicas, mode, route_cells):
    import outcore
    servers = [remote_bench.Server(store, ["--cache-mb", str(budget_mb)]) for _ in range(replicas)]
    addresses = [s.address for s in servers]
    singles = [outcore.SceneClient(a, timeout=3600) for a in addresses]
    routed = (outcore.SceneClient(addresses, timeout=3600, routing=mode, route_cells=route_cells)
              if mode in ("bricks", "rays") else None)
    per_batch, seconds, answers = [], [], []
    try:
        for k, rays in enumerate(batches):
            before = builds(singles)
            t0 = time.perf_counter()
            if routed is not None:
                hits = routed.cast_rays(rays)
            else:  # round-robin: the whole batch to the next replica
                hits = singles[k % replicas].cast_rays(rays)
            seconds.append(time.perf_counter() - t0)
            per_batch.append(builds(singles) - before)
            answers.append(np.array(hits["t_hit"]).view(np.uint32))
        peak_resident = max(c.stats()["peak_resident_bytes"] for c in singles)
        load = None
        if mode == "rays":
            _, replica_of_ray, _ = routed._router.plan(batches[-1])
            counts = np.bincount(replica_of_ray, minlength=replicas)
            load = float(counts.max() / counts.mean())
        elif mode == "bricks":
            bricks = routed.scene_info()["bricks"]
            owned = [sum(bricks[b]["triangle_count"] for b in part)
                     for part in routed._router.plan_bricks().values()]
            load = float(max(owned) / (sum(owned) / replicas))
    finally:
        for c in singles + ([routed] if routed else []):
            c.close()
        for s in servers:
            s.stop()
    row = dict(config=name, replicas=replicas, budget_mb=budget_mb, mode=mode, cold_builds=per_batch[0],
               builds_per_batch=float(np.mean(per_batch[1:])), batch_builds=per_batch,
               total_builds=int(sum(per_batch)), peak_resident_mib=peak_resident / 2**20,
               Mrays_per_s=float(np.median([len(b) / s for b, s in zip(batches[1:], seconds[1:])]) / 1e6),
               peak_load_vs_mean=load)
    print(json.dumps(row), flush=True)
    return row, answers


def moved_keys(batches, bounds, before, after, cells, bricks=None, load_factor=1.25, nodes=4):
    """Shares of the keys and of their load that change replica when one
    joins: the batches' cells weighed by rays, or the bricks by triangles."""
    from outcore import _routing
    if bricks is not None:
        positions = _routing.brick_positions(bricks, *bounds)
        load = {int(p): b["triangle_count"] for p, b in zip(positions, bricks)}
    else:
        keys = np.concatenate([_routing.ray_keys(b, *bounds, cells=cells) for b in batches])
        unique, counts = np.unique(keys, return_counts=True)
        load = {int(k): int(c) for k, c in zip(unique, counts)}
    ring_a = _routing.HashRing([f"r{i}:1" for i in range(before)], nodes).assign(load, load_factor)
    ring_b = _routing.HashRing([f"r{i}:1" for i in range(after)], nodes).assign(load, load_factor)
    moved = [k for k in load if ring_a[k] != ring_b[k]]
    return len(moved) / len(load), sum(load[k] for k in moved) / sum(load.values())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--batches", type=int, default=4)
    ap.add_argument("--rays", type=int, default=1_000_000)
    ap.add_argument("--kinds", default="incoherent,camera")
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-replicas"))
    ap.add_argument("--route-cells", type=int, default=8, help="SceneClient(route_cells=): the key grid's side")
    ap.add_argument("--configs", help="semicolon-separated configuration names to run (default: all)")
    ap.add_argument("--budget-mb", type=int, default=BUDGET_MB, help="B, each replica's --cache-mb")
    ap.add_argument("--brick-tris", type=int, default=8192,
                    help="pack --brick-tris (smaller bricks: a replica's build headroom is a smaller share of B)")
    ap.add_argument("--json")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    name = "city400" if a.brick_tris == 8192 else f"city400-b{a.brick_tris}"
    store, info = prepare_store(OUTCORE, a.work, name, [SCENE], ["--brick-tris", str(a.brick_tris)])
    with open(info) as f:
        bounds_info = json.load(f)["bounds"]
    bounds = (bounds_info["min"], bounds_info["max"])
    rows, moves = [], {}
    for kind in a.kinds.split(","):
        batches = []
        for k in range(a.batches):
            path = os.path.join(a.work, f"{kind}-{k}.npy")
            run([sys.executable, os.path.join(ROOT, "bench", "make_rays.py"), info, kind, str(a.rays), path,
                 "--seed", str(100 + k)])
            batches.append(np.load(path))
        reference = None
        b = a.budget_mb
        for name, replicas, budget, mode in (("one server, 4B", 1, 4 * b, "single"),
                                             ("4 replicas, by brick", 4, b, "bricks"),
                                             ("4 replicas, by ray", 4, b, "rays"),
                                             ("4 replicas, round-robin", 4, b, "round-robin"),
                                             ("2 replicas, by brick", 2, b, "bricks"),
                                             ("1 replica, B", 1, b, "single")):
            if a.configs and name not in a.configs.split(";") and name != "one server, 4B":
                continue
            row, answers = run_config(name, store, batches, budget, replicas, mode, a.route_cells)
            row["kind"] = kind
            if reference is None:
                reference = answers
            row["same_answers"] = all(np.array_equal(x, y) for x, y in zip(answers, reference))
            rows.append(row)
        moves[kind] = {f"{n}->{n + 1}": moved_keys(batches, bounds, n, n + 1, a.route_cells) for n in (3, 4)}
    import outcore
    probe = remote_bench.Server(store, [])
    try:
        with outcore.SceneClient(probe.address) as client:
            bricks = client.scene_info()["bricks"]
    finally:
        probe.stop()
    from outcore import _routing
    moves["bricks"] = {f"{n}->{n + 1}": moved_keys(None, bounds, n, n + 1, a.route_cells, bricks,
                                                   _routing.BRICK_LOAD_FACTOR, _routing.BRICK_VIRTUAL_NODES)
                       for n in (3, 4)}
    print(f"\nscene {SCENE}, bricks of {a.brick_tris} triangles (bvh), B = {a.budget_mb} MiB; {a.batches} batches "
          f"of {a.rays:,} rays a kind; builds summed over the replicas; {os.cpu_count()} cores shared by all\n")
    print("| rays | configuration | builds: first batch / each later (mean) / all | all vs one server 4B | "
          "M rays/s (later batches) | peak load / mean | peak resident MiB (one server) | answers = one server |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        base = next(x for x in rows if x["kind"] == r["kind"] and x["config"] == "one server, 4B")
        load = f"{r['peak_load_vs_mean']:.2f}" if r["peak_load_vs_mean"] and r["replicas"] > 1 else "—"
        print(f"| {r['kind']} | {r['config']} | {r['cold_builds']} / {r['builds_per_batch']:.1f} / "
              f"{r['total_builds']} | {r['total_builds'] / base['total_builds']:.2f}x | {r['Mrays_per_s']:.2f} | "
              f"{load} | {r['peak_resident_mib']:.1f} | {'yes' if r['same_answers'] else 'NO'} |")
    for kind, m in moves.items():
        for step, (keys, rays) in m.items():
            weight = "triangles" if kind == "bricks" else "rays"
            print(f"{kind}: {step} replicas moves {keys:.3f} of the keys ({rays:.3f} of the {weight})")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(dict(rows=rows, moved=moves), f, indent=1)


if __name__ == "__main__":
    main()
