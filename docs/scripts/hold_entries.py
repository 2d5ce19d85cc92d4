#!/usr/bin/env python3
"""Where off-model runs lose their time (docs/decisions.md, "Identifying
the factors before the first entry").

The mismatch grid's 24 targets x seeds 1..N (default 8), paper
disturbance, 6 s, one sampling (default variable), on the model and three
plants off it. Per plant: the median of the first entry into the terminal
hold and of the strict settle, the runs that enter the hold more than
once, and the true relative speed of the two capsules at the first entry
(median and 90th percentile).

    cargo build --release
    python3 docs/scripts/hold_entries.py target/release/capsule-mpc [N] [constant|variable]
"""
import statistics
import sys
from concurrent.futures import ThreadPoolExecutor

from grid_runs import NEVER_S, TARGETS, simulate

PLANTS = [
    ("model", []),
    ("drag x1.2", ["--plant-drag-scale", "1.2"]),
    ("gain x1.1", ["--plant-gain-scale", "1.1"]),
    ("drag (x1.2, x0.8)", ["--plant-drag-scale", "1.2,0.8"]),
]


def run(binary, sampling, extra, target, seed):
    """(first hold entry s, strict settle s, hold entries, |v1 - v2| mm/s at the first)."""
    d = simulate(binary, sampling, extra, target, seed)
    holds = [m["t_s"] for m in d["modes"] if m["mode"] == "hold"]
    settle = d["metrics"]["settle_time_s"] or NEVER_S
    if not holds:
        return NEVER_S, settle, 0, None
    k = min(range(len(d["t"])), key=lambda j: abs(d["t"][j] - holds[0]))
    x = d["x"][k]
    return holds[0], settle, len(holds), abs(x[1] - x[3]) * 1e3


def main():
    binary = sys.argv[1]
    seeds = range(1, int(sys.argv[2]) + 1) if len(sys.argv) > 2 else range(1, 9)
    sampling = sys.argv[3] if len(sys.argv) > 3 else "variable"
    for name, extra in PLANTS:
        jobs = [(binary, sampling, extra, t, s) for t in TARGETS for s in seeds]
        with ThreadPoolExecutor(2) as ex:
            res = list(ex.map(lambda a: run(*a), jobs))
        rel = sorted(r[3] for r in res if r[3] is not None)
        print(f"{sampling:8s} {name:18s} first hold {statistics.median(r[0] for r in res):.2f} s, "
              f"settle {statistics.median(r[1] for r in res):.2f} s | more than one hold "
              f"{sum(r[2] > 1 for r in res)}/{len(res)} | relative speed at the first: median "
              f"{statistics.median(rel):.2f}, p90 {rel[int(0.9 * len(rel))]:.2f} mm/s", flush=True)


if __name__ == "__main__":
    main()
