#!/usr/bin/env python3
"""Camera rays at a quarter budget on the 100 M-triangle city, many short
interleaved rounds, with the host's steal time next to every run.

Camera rays at a quarter budget swing between ~0.3x and ~0.8x of unlimited
from one run to the next minutes apart (docs/BENCHMARKS.md); this driver
measures that spread so that the median means something, and records what
the hypervisor took from the guest during each run (the `steal` column of
/proc/stat) so that a slow run can be told apart from a slow code path.

Round 0: the unlimited peer with heap-built bricks (no tier; 1-2 minutes of
builds): the reference hits file and the camera's built size. Each round
after it runs, back to back, on one subtree directory holding every brick
the camera rays touch (written by the first quarter run if missing):
  mapped      --cache-mb 65536 --subtree-dir DIR: every brick loaded from
              the tier and kept (the unlimited peer of this round; as fast
              as heap bricks, see BENCHMARKS)
  quarter     --cache-mb CAMERA_BUILT/4 --subtree-dir DIR (a quarter of the
              bricks the camera touches)
  scene-quarter  --cache-mb SCENE_BUILT/4 (a quarter of the whole scene's
              built size, the budget of the incoherent rows), if given
  quarter-unbatched  quarter with --subtree-release-batch-mb 0 (each evicted
              brick's pages released at once), with --compare-unbatched
A run's figure is the median of its warm batches (every batch after the
first); a round's ratio is mapped / quarter; the table gives medians and
ranges over rounds. Every hits file is compared bitwise with round 0's.

Usage: camera_quarter_100m.py WORK_DIR [--rounds 6] [--repeat 5] [--tier camera-tier]
       [--scene-built-mib 9017] [--compare-unbatched] [--outcore build/client/outcore]
WORK_DIR is subtree_tier_100m.py's (city4883.oc and camera.npy in it).
"""
import argparse
import filecmp
import json
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))
from subtree_tier_100m import run_trace  # noqa: E402

USER_HZ = 100  # /proc/stat's unit on Linux


def steal_seconds():
    fields = Path("/proc/stat").read_text().splitlines()[0].split()
    return int(fields[8]) / USER_HZ


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("work", type=Path)
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--tier", default="camera-tier", help="subtree directory inside WORK_DIR")
    ap.add_argument("--scene-built-mib", type=int, default=0,
                    help="also run at a quarter of this (the whole scene's built size)")
    ap.add_argument("--compare-unbatched", action="store_true",
                    help="also run the quarter budget with --subtree-release-batch-mb 0")
    ap.add_argument("--outcore", type=Path, default=ROOT / "build/client/outcore")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    work = args.work.resolve()
    log = lambda s: print(s, flush=True)
    rows = {}

    def measured(name, budget_mb, extra):
        before = steal_seconds()
        row = run_trace(args.outcore, work, "camera.npy", name, budget_mb, args.repeat, extra, log)
        row["steal_s"] = steal_seconds() - before
        row["same"] = filecmp.cmp(work / (name + ".npy"), work / "camera-heap.npy", shallow=False)
        if not row["same"]:
            sys.exit(f"{name}: hits differ from the unlimited heap run's")
        log(f"  {'':<22} steal {row['steal_s']:.2f} s")
        rows.setdefault(name, []).append(row)
        return row

    heap = measured("camera-heap", 65536, [])
    quarter_mb = int(heap["built_mib"] / 4)
    tier = ["--subtree-dir", args.tier]
    for r in range(args.rounds):
        log(f"round {r + 1}/{args.rounds}")
        mapped = measured("camera-mapped", 65536, tier)
        quarter = measured("camera-quarter", quarter_mb, tier)
        quarter["ratio"] = mapped["warm"] / quarter["warm"]
        if args.compare_unbatched:
            unbatched = measured("camera-quarter-unbatched", quarter_mb, tier + ["--subtree-release-batch-mb", "0"])
            unbatched["ratio"] = mapped["warm"] / unbatched["warm"]
        if args.scene_built_mib:
            scene = measured("camera-scene-quarter", args.scene_built_mib // 4, tier)
            scene["ratio"] = mapped["warm"] / scene["warm"]

    log(f"\nheap unlimited warm {heap['warm']:.3f} s, built {heap['built_mib']:.0f} MiB, quarter {quarter_mb} MiB")
    log("run                    warm s median (range)       vs mapped, median (range)   loads/warm batch  steal s  RSS MiB")
    for name, runs in rows.items():
        warms = [x["warm"] for x in runs]
        ratios = [x["ratio"] for x in runs if "ratio" in x]
        ratio = f"{statistics.median(ratios):.2f}x ({min(ratios):.2f}-{max(ratios):.2f})" if ratios else "-"
        loads = statistics.median(v for x in runs for v in x["loads"][1:])
        log(f"{name:<22} {statistics.median(warms):.3f} ({min(warms):.3f}-{max(warms):.3f})   {ratio:<27} "
            f"{loads:>8.0f}        {statistics.median(x['steal_s'] for x in runs):5.2f}  "
            f"{max(x['rss_mib'] for x in runs):7.0f}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
