#!/usr/bin/env python3
"""Compares two output folders of bench/engine_matrix.sh: every .npy must be
byte-identical; statistics JSON counters are listed where they differ
(seconds, rates and peak_bytes_resident are skipped: they depend on timing,
as do a few trace-ahead and cache-hit counts under small budgets).
Exit status 1 when an .npy differs or is missing.

Usage: python3 bench/compare_outputs.py BEFORE_DIR AFTER_DIR
"""
import json, glob, os, sys, filecmp
a, b = sys.argv[1], sys.argv[2]
skip = {"seconds", "rays_per_second", "peak_bytes_resident"}
bad = 0
for f in sorted(glob.glob(os.path.join(a, "*"))):
    g = os.path.join(b, os.path.basename(f))
    if f.endswith(".err"): continue
    if not os.path.exists(g): print("missing", g); bad += 1; continue
    if f.endswith(".npy"):
        if not filecmp.cmp(f, g, shallow=False): print("DIFF", os.path.basename(f)); bad += 1
    elif f.endswith(".json"):
        x, y = json.load(open(f)), json.load(open(g))
        x = x if isinstance(x, list) else [x]; y = y if isinstance(y, list) else [y]
        for i, (p, q) in enumerate(zip(x, y)):
            d = {k: (p.get(k), q.get(k)) for k in set(p) | set(q) if k not in skip and p.get(k) != q.get(k)}
            if d: print("STATS", os.path.basename(f), i, d)
print("bad", bad)
sys.exit(1 if bad else 0)
