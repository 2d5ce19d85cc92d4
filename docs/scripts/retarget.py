#!/usr/bin/env python3
"""A target changed mid-move (docs/results.md, "A target changed mid-move").

Each run draws a first and a second target at rest (+-4 cm for two
capsules, +-3 cm for three), the time the host changes to the second
(0.05-0.6 s), ideal, constant or variable sampling, a random or drifting
disturbance of the paper's size (half the ideal runs none) and a seed;
with `--off-model` also a plant per capsule (drag x0.8-1.2, gain
x0.9-1.1). Each run is paired with the same second move from rest at the
first target. Prints per sampling the settled runs and the median / 90th
percentile / worst time from the change to the strict settle, against
the move from rest. The draw is seeded, so a run list is reproducible.

    cargo build --release
    python3 docs/scripts/retarget.py target/release/capsule-mpc [RUNS] [DRAW_SEED] [--config FILE] [--off-model]
"""
import random
import sys
from concurrent.futures import ThreadPoolExecutor

from grid_runs import draw_arguments, simulate_args

NEVER_S = 99.0


def draw(runs, seed, capsules, off_model):
    rng = random.Random(seed)
    reach_m = 0.03 if capsules == 3 else 0.04
    out = []
    for _ in range(runs):
        run = {
            "first_m": [round(rng.uniform(-reach_m, reach_m), 4) for _ in range(capsules)],
            "second_m": [round(rng.uniform(-reach_m, reach_m), 4) for _ in range(capsules)],
            "at_s": round(rng.uniform(0.05, 0.6), 3),
            "sampling": rng.choice(["ideal", "constant", "variable"]),
            "disturbance": rng.choice(["random", "drift"]),
        }
        run["size"] = "none" if run["sampling"] == "ideal" and rng.random() < 0.5 else "paper"
        run["seed"] = rng.randint(1, 1000)
        if off_model:
            run["drag"] = [round(rng.uniform(0.8, 1.2), 3) for _ in range(capsules)]
            run["gain"] = [round(rng.uniform(0.9, 1.1), 3) for _ in range(capsules)]
        out.append(run)
    return out


def at_rest(positions_m):
    return ",".join(f"{x},0" for x in positions_m)


def settle_pair(binary, config, run):
    """Settle after the change, and of the move from rest (None: never)."""
    common = ["--sampling", run["sampling"], "--disturbance", run["size"],
              "--disturbance-model", run["disturbance"], "--seed", str(run["seed"]),
              "--duration", "8"]
    if "drag" in run:
        common += ["--plant-drag-scale", ",".join(map(str, run["drag"])),
                   "--plant-gain-scale", ",".join(map(str, run["gain"]))]
    if config:
        common += ["--config", config]
    changed = simulate_args(binary, common + [
        "--target", at_rest(run["first_m"]), "--retarget", at_rest(run["second_m"]),
        "--retarget-at", str(run["at_s"])])["metrics"]["settle_time_s"]
    rest = simulate_args(binary, common + [
        "--start", ",".join(map(str, run["first_m"])),
        "--target", at_rest(run["second_m"])])["metrics"]["settle_time_s"]
    return (None if changed is None else changed - run["at_s"]), rest


def summary(times):
    t = sorted(NEVER_S if s is None else s for s in times)
    return (f"{sum(1 for s in times if s is not None)} of {len(t)} settled, median "
            f"{t[len(t) // 2]:.2f} s, 90th percentile {t[int(0.9 * len(t))]:.2f} s, worst {t[-1]:.2f} s")


def main():
    binary, runs, seed, config, capsules, off_model = draw_arguments(sys.argv[1:], "--off-model")
    plan = draw(runs, seed, capsules, off_model)
    with ThreadPoolExecutor(2) as ex:
        pairs = list(ex.map(lambda r: settle_pair(binary, config, r), plan))
    print(f"{runs} runs ({capsules} capsules, draw {seed}{', off the model' if off_model else ''})")
    for sampling in ("ideal", "constant", "variable"):
        rows = [p for p, r in zip(pairs, plan) if r["sampling"] == sampling]
        if rows:
            print(f"  {sampling}: after the change {summary([c for c, _ in rows])}; "
                  f"from rest {summary([s for _, s in rows])}")
    slowest = sorted(zip(pairs, plan), key=lambda p: -(NEVER_S if p[0][0] is None else p[0][0]))
    for (changed, _), r in slowest[:5]:
        print(f"  {'never' if changed is None else f'{changed:.2f} s'}: {r}")


if __name__ == "__main__":
    main()
