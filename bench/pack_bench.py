#!/usr/bin/env python3
"""Pack benchmark: `outcore pack` on a large generated city against the
machine's sequential write speed, measured in the same run.

For each run: a `dd` sequential write of --dd-gib GiB with fdatasync (the peer),
then `outcore pack` of the scene (which also fsyncs its store before the
rename). Reports M tris/s, peak RSS (wait4), bytes on disk, and the ratio
pack write throughput (store bytes / pack seconds) / dd write throughput.
Medians over --runs runs.

Usage: .venv/bin/python bench/pack_bench.py [--copies 9766] [--runs 3] [--mem-mb 2048]
"""
import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_dd(path, gib):
    t0 = time.monotonic()
    subprocess.run(["dd", "if=/dev/zero", f"of={path}", "bs=1M", f"count={gib * 1024}", "conv=fdatasync"],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    seconds = time.monotonic() - t0
    os.remove(path)
    return gib * 1024**3 / seconds


def run_pack(binary, spec, out, mem_mb, brick_tris, extra_args=()):
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.monotonic()
    proc = subprocess.Popen([binary, "pack", spec, "-o", out, "--mem-mb", str(mem_mb), "--brick-tris",
                             str(brick_tris), *extra_args], stdout=subprocess.PIPE, stderr=None, text=True)
    stdout = proc.stdout.read()
    _, status, rusage = os.wait4(proc.pid, 0)
    seconds = time.monotonic() - t0
    if status != 0:
        sys.exit(f"pack failed:\n{stdout}")
    tris = int(re.search(r"packed (\d+) triangles", stdout).group(1))
    store_bytes = sum(os.path.getsize(os.path.join(out, f)) for f in os.listdir(out))
    phases = {name: float(value) for name, value in re.findall(r"(scan|histogram|fill|bricks|disk|finish) ([\d.]+) s",
                                                               stdout)}
    return {"seconds": seconds, "triangles": tris, "bytes": store_bytes, "peak_rss": rusage.ru_maxrss * 1024,
            "stdout": stdout, "phases": phases}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--copies", type=int, default=9766, help="city copies of a 20,480-triangle sphere")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--mem-mb", type=int, default=2048)
    ap.add_argument("--brick-tris", type=int, default=32768)
    ap.add_argument("--dd-gib", type=int, default=8)
    ap.add_argument("--work", default=os.path.join(ROOT, "build", "bench-pack"))
    ap.add_argument("--binary", default=os.path.join(ROOT, "build", "client", "outcore"))
    args = ap.parse_args()
    os.makedirs(args.work, exist_ok=True)
    spec = f"gen:city?of=(gen:sphere?level=5)&copies={args.copies}"
    out = os.path.join(args.work, "city.oc")
    rows = []
    phase_rows = []
    print(f"load average before: {os.getloadavg()}", flush=True)
    for run in range(args.runs):
        dd = run_dd(os.path.join(args.work, "dd.bin"), args.dd_gib)
        pack = run_pack(args.binary, spec, out, args.mem_mb, args.brick_tris)
        write_rate = pack["bytes"] / pack["seconds"]
        row = {"dd_MBps": dd / 1e6, "pack_s": pack["seconds"], "Mtris_s": pack["triangles"] / pack["seconds"] / 1e6,
               "pack_write_MBps": write_rate / 1e6, "ratio": write_rate / dd, "peak_rss_MiB": pack["peak_rss"] / 2**20,
               "store_GiB": pack["bytes"] / 2**30, "triangles": pack["triangles"]}
        rows.append(row)
        phase_rows.append(pack["phases"])
        print(f"run {run + 1}/{args.runs}: " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                                                        for k, v in row.items()), flush=True)
        print(pack["stdout"], flush=True)
    shutil.rmtree(out, ignore_errors=True)
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    print(f"\nscene: {spec} ({med['triangles']:.0f} triangles), --mem-mb {args.mem_mb}, "
          f"--brick-tris {args.brick_tris}, medians of {args.runs} runs")
    print("| M tris/s | pack s | peak RSS MiB | store GiB | pack write MB/s | dd write MB/s | ratio |")
    print("|---|---|---|---|---|---|---|")
    print(f"| {med['Mtris_s']:.2f} | {med['pack_s']:.1f} | {med['peak_rss_MiB']:.0f} | {med['store_GiB']:.2f} | "
          f"{med['pack_write_MBps']:.0f} | {med['dd_MBps']:.0f} | {med['ratio']:.2f} |")
    if phase_rows and phase_rows[0]:
        names = list(phase_rows[0])
        print("\nphase medians, s (disk = part of bricks spent waiting for the writer):")
        print("| " + " | ".join(names) + " |")
        print("|" + "---|" * len(names))
        print("| " + " | ".join(f"{statistics.median(p.get(n, 0.0) for p in phase_rows):.1f}" for n in names) + " |")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
