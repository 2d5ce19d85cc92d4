#!/usr/bin/env python3
"""The end-game grid of docs/decisions.md ("The end game near rest").

24 targets (+-4 cm, 2 cm steps) x seeds 1-2, paper disturbance, 6 s runs,
both scanner samplings, on the model and three plants off it. Per row:
first entry into the settle band and strict settle (median / worst; 9.00
stands for never), and how many runs left the band more than 0.3 s after
first entering it.

    cargo build --release
    python3 docs/scripts/end_game_grid.py target/release/capsule-mpc
"""
import statistics
import sys
from concurrent.futures import ThreadPoolExecutor

from grid_runs import NEVER_S, TARGETS, simulate

PLANTS = [
    ("model", []),
    ("drag x0.8", ["--plant-drag-scale", "0.8"]),
    ("gain x0.9", ["--plant-gain-scale", "0.9"]),
    ("drag (x1.2, x0.8)", ["--plant-drag-scale", "1.2,0.8"]),
]
SEEDS = (1, 2)


def run(binary, sampling, extra, target, seed):
    m = simulate(binary, sampling, extra, target, seed)["metrics"]
    return m["first_in_band_s"], m["settle_time_s"]


def main():
    binary = sys.argv[1]
    for sampling in ("constant", "variable"):
        for name, extra in PLANTS:
            jobs = [(binary, sampling, extra, t, s) for t in TARGETS for s in SEEDS]
            with ThreadPoolExecutor(2) as ex:
                res = list(ex.map(lambda a: run(*a), jobs))
            first = sorted(NEVER_S if f is None else f for f, _ in res)
            strict = sorted(NEVER_S if s is None else s for _, s in res)
            left = sum(1 for f, s in res if f is not None and (s or NEVER_S) - f > 0.3)
            print(f"{sampling:8s} {name:18s} first entry {statistics.median(first):.2f} / "
                  f"{first[-1]:.2f} s | strict settle {statistics.median(strict):.2f} / "
                  f"{strict[-1]:.2f} s | left the band {left}/{len(res)}")


if __name__ == "__main__":
    main()
