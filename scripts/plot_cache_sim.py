#!/usr/bin/env python3
"""Miss ratio against cache budget from `outcore cache-sim --json`, drawn with
matplotlib: one line per policy, OPT dashed in black, the budget on a log
axis. The same figure `cache-sim --png` draws from the binary alone (no
Python needed there); this one is for reports (vector output, styling).

Usage: python3 scripts/plot_cache_sim.py results.json -o miss_ratio.png|.svg|.pdf [--title TEXT]
  (outcore cache-sim TRACE --budget-fractions 0.125,0.25,0.5,1 --json > results.json)
Needs matplotlib (pip install matplotlib; the bench venv has it).
"""
import argparse
import json
import sys
from collections import defaultdict


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("json", help="cache-sim --json output")
    ap.add_argument("-o", "--output", required=True, help="picture to write (.png, .svg, .pdf)")
    ap.add_argument("--title", default="Brick cache: miss ratio against budget")
    args = ap.parse_args()
    try:
        with open(args.json) as f:
            data = json.load(f)
        results = data["results"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        sys.exit(f"{args.json}: not cache-sim --json output ({e})")
    lines = defaultdict(list)
    for row in results:
        try:
            lines[row["policy"]].append((row["budget_bytes"] / 2**20, row["miss_ratio"]))
        except (KeyError, TypeError) as e:
            sys.exit(f"{args.json}: a result lacks {e}")
    if not lines:
        sys.exit(f"{args.json}: no results")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for policy in sorted(lines, key=lambda p: (p == "opt", p)):
        points = sorted(lines[policy])
        style = dict(color="black", linestyle="--") if policy == "opt" else {}
        ax.plot([b for b, _ in points], [m for _, m in points], marker="o", label=policy, **style)
    ax.set_xscale("log")
    ax.set_xlabel("cache budget (MiB)")
    ax.set_ylabel("miss ratio (builds / requests)")
    ax.set_title(args.title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.output, dpi=120)


if __name__ == "__main__":
    main()
