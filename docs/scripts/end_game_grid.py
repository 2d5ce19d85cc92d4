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
import json
import os
import statistics
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor

NEVER_S = 9.0
PLANTS = [
    ("model", []),
    ("drag x0.8", ["--plant-drag-scale", "0.8"]),
    ("gain x0.9", ["--plant-gain-scale", "0.9"]),
    ("drag (x1.2, x0.8)", ["--plant-drag-scale", "1.2,0.8"]),
]
STEPS_M = (-0.04, -0.02, 0.0, 0.02, 0.04)
TARGETS = [(a, b) for a in STEPS_M for b in STEPS_M if (a, b) != (0.0, 0.0)]
SEEDS = (1, 2)


def run(binary, sampling, extra, target, seed):
    fd, path = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        subprocess.run(
            [binary, "simulate", "--target", f"{target[0]},0,{target[1]},0",
             "--sampling", sampling, "--disturbance", "paper", "--seed", str(seed),
             "--duration", "6", "--json", path] + extra,
            check=True, capture_output=True)
        with open(path) as f:
            m = json.load(f)["metrics"]
    finally:
        os.remove(path)
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
