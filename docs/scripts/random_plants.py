#!/usr/bin/env python3
"""Random capsules off the model (docs/known-limits.md).

Each run draws its own plant, one factor per capsule (drag x0.8-1.2, gain
x0.9-1.1), a random target (at rest, +-5 cm for two capsules, +-3 cm for
three), constant or variable sampling, a random or drifting disturbance of
the paper's size and a random seed; 8 s runs, strict settle. Prints the
unsettled runs, the median / 90th percentile / worst settle and the
slowest runs. The draw is seeded, so a run list is reproducible.

    cargo build --release
    python3 docs/scripts/random_plants.py target/release/capsule-mpc [RUNS] [DRAW_SEED] [--config FILE]
"""
import random
import sys
from concurrent.futures import ThreadPoolExecutor

from grid_runs import pop_option, simulate_args

NEVER_S = 99.0


def draw(runs, seed, capsules):
    rng = random.Random(seed)
    reach_m = 0.03 if capsules == 3 else 0.05
    out = []
    for _ in range(runs):
        out.append({
            "target_m": [round(rng.uniform(-reach_m, reach_m), 4) for _ in range(capsules)],
            "drag": [round(rng.uniform(0.8, 1.2), 3) for _ in range(capsules)],
            "gain": [round(rng.uniform(0.9, 1.1), 3) for _ in range(capsules)],
            "sampling": rng.choice(["constant", "variable"]),
            "disturbance": rng.choice(["random", "drift"]),
            "seed": rng.randint(1, 1000),
        })
    return out


def settle_s(binary, config, run):
    """Strict settle time of one 8 s run (None: never)."""
    args = ["--target", ",".join(f"{x},0" for x in run["target_m"]),
            "--sampling", run["sampling"], "--disturbance", "paper",
            "--disturbance-model", run["disturbance"], "--seed", str(run["seed"]),
            "--duration", "8",
            "--plant-drag-scale", ",".join(map(str, run["drag"])),
            "--plant-gain-scale", ",".join(map(str, run["gain"]))]
    if config:
        args += ["--config", config]
    return simulate_args(binary, args)["metrics"]["settle_time_s"]


def main():
    args = sys.argv[1:]
    config = pop_option(args, "--config")
    binary = args[0]
    runs = int(args[1]) if len(args) > 1 else 400
    seed = int(args[2]) if len(args) > 2 else 1
    capsules = 3 if config and "three" in config else 2
    plan = draw(runs, seed, capsules)
    with ThreadPoolExecutor(2) as ex:
        settle = list(ex.map(lambda r: settle_s(binary, config, r), plan))
    times = sorted(NEVER_S if s is None else s for s in settle)
    unsettled = sum(1 for s in settle if s is None)
    print(f"{runs} runs ({capsules} capsules, draw {seed}): {unsettled} unsettled; "
          f"settle median {times[len(times) // 2]:.2f} s, 90th percentile "
          f"{times[int(0.9 * len(times))]:.2f} s, worst {times[-1]:.2f} s (99 = never)")
    slowest = sorted(zip(settle, plan), key=lambda p: -(NEVER_S if p[0] is None else p[0]))
    for s, r in slowest[:5]:
        print(f"  {'never' if s is None else f'{s:.2f} s'}: {r}")


if __name__ == "__main__":
    main()
