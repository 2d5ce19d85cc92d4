#!/usr/bin/env python3
"""Short corrections (docs/known-limits.md, "Three capsules").

Starts at rest within +-2 mm of a target at (1, 1, 1) cm (three capsules)
or (1, 1) cm (two, without `--config`), drawn per run with a seeded
generator, constant or variable sampling, the paper's random disturbance
or none, 6 s runs on the model, strict settle. Prints the unsettled runs,
the median and 90th percentile settle and the runs slower than 3 s.

    cargo build --release
    python3 docs/scripts/short_moves.py target/release/capsule-mpc [RUNS] [--config FILE] [--disturbance paper|none]
"""
import random
import sys
from concurrent.futures import ThreadPoolExecutor

from grid_runs import pop_option, simulate_args

OFFSET_M = 0.002
TARGET_M = 0.01
DRAW_SEED = 7
DURATION_S = 6
NEVER_S = 99.0


def draw(runs, capsules):
    rng = random.Random(DRAW_SEED)
    out = []
    for _ in range(runs):
        offsets = [round(rng.uniform(-OFFSET_M, OFFSET_M), 5) for _ in range(capsules)]
        out.append((offsets, rng.choice(["constant", "variable"]), rng.randint(1, 100)))
    return out


def settle_s(binary, config, disturbance, run):
    offsets, sampling, seed = run
    args = ["--start", ",".join(str(TARGET_M + o) for o in offsets),
            "--target", ",".join(f"{TARGET_M},0" for _ in offsets),
            "--sampling", sampling, "--disturbance", disturbance, "--seed", str(seed),
            "--duration", str(DURATION_S)]
    if config:
        args += ["--config", config]
    return simulate_args(binary, args)["metrics"]["settle_time_s"]


def main():
    args = sys.argv[1:]
    config = pop_option(args, "--config")
    disturbance = pop_option(args, "--disturbance") or "paper"
    binary = args[0]
    runs = int(args[1]) if len(args) > 1 else 60
    capsules = 3 if config and "three" in config else 2
    plan = draw(runs, capsules)
    with ThreadPoolExecutor(2) as ex:
        settles = list(ex.map(lambda r: settle_s(binary, config, disturbance, r), plan))
    times = sorted(NEVER_S if s is None else s for s in settles)
    print(f"{runs} short moves ({capsules} capsules, disturbance {disturbance}): "
          f"{times.count(NEVER_S)} unsettled; settle median {times[len(times) // 2]:.2f} s, "
          f"90th percentile {times[int(0.9 * len(times))]:.2f} s (99 = never)")
    for s, r in zip(settles, plan):
        if s is None or s > 3.0:
            print(f"  {'never' if s is None else f'{s:.2f} s'}: offsets {r[0]} m, {r[1]}, seed {r[2]}")


if __name__ == "__main__":
    main()
