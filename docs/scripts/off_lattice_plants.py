#!/usr/bin/env python3
"""Off-lattice targets on plants off the model (docs/known-limits.md).

Two sets, the paper disturbance's size, 6 s runs, strict settle:

* four off-lattice targets, seeds 1-3, both scanner samplings, on the
  model and two plants the grids use (drag x1.2 / gain x0.9; drag
  (x0.8, x1.2) / gain (x1.1, x0.9));
* six off-lattice targets, seeds 1-3, variable sampling, on the model and
  two plants no grid uses (drag x1.15 / gain x0.88; drag (x0.82, x1.18) /
  gain (x1.12, x0.9)), also with 10 ms of extra delay per cycle.

Each under the random, drifting and constant-bias disturbance. Per row:
unsettled runs, median / worst settle (9.00 stands for never) and the
median of settle over the ideal minimum time.

    cargo build --release
    python3 docs/scripts/off_lattice_plants.py target/release/capsule-mpc
"""
import statistics
import sys
from concurrent.futures import ThreadPoolExecutor

from grid_runs import NEVER_S, simulate

FOUR_M = [(0.025, -0.015), (-0.033, 0.017), (0.012, 0.036), (-0.007, -0.024)]
SIX_M = FOUR_M + [(0.043, 0.011), (-0.018, -0.041)]
MODEL = ("the model", [])
SEEN = [
    ("drag x1.2 / gain x0.9", ["--plant-drag-scale", "1.2", "--plant-gain-scale", "0.9"]),
    ("drag (x0.8, x1.2) / gain (x1.1, x0.9)",
     ["--plant-drag-scale", "0.8,1.2", "--plant-gain-scale", "1.1,0.9"]),
]
UNSEEN = [
    ("drag x1.15 / gain x0.88", ["--plant-drag-scale", "1.15", "--plant-gain-scale", "0.88"]),
    ("drag (x0.82, x1.18) / gain (x1.12, x0.9)",
     ["--plant-drag-scale", "0.82,1.18", "--plant-gain-scale", "1.12,0.9"]),
]
SEEDS = range(1, 4)


def row(binary, label, samplings, extra, targets):
    jobs = [(s, t, seed) for s in samplings for t in targets for seed in SEEDS]

    def one(job):
        d = simulate(binary, job[0], extra, job[1], job[2])
        m = d["metrics"]
        return m["settle_time_s"], m["settle_over_bound"]

    with ThreadPoolExecutor(2) as ex:
        res = list(ex.map(one, jobs))
    settle = sorted(NEVER_S if s is None else s for s, _ in res)
    ratios = [r for s, r in res if s is not None and r is not None]
    unsettled = sum(1 for s, _ in res if s is None)
    ratio = statistics.median(ratios) if ratios else float("nan")
    print(f"{label:70s} unsettled {unsettled:2d}/{len(res)} median {statistics.median(settle):.2f} "
          f"worst {settle[-1]:.2f} s, settle / minimum time median {ratio:.2f}", flush=True)


def main():
    binary = sys.argv[1]
    for model in ("random", "drift", "constant"):
        for name, extra in [MODEL] + SEEN:
            row(binary, f"four targets, {model}, {name}", ("constant", "variable"),
                extra + ["--disturbance-model", model], FOUR_M)
    for model in ("random", "drift", "constant"):
        for delay in (None, "0.01"):
            if model == "constant" and delay:
                continue
            for name, extra in [MODEL] + UNSEEN:
                more = ["--disturbance-model", model] + (["--extra-delay", delay] if delay else [])
                label = f"six targets, variable, {model}{', +10 ms' if delay else ''}, {name}"
                row(binary, label, ("variable",), extra + more, SIX_M)


if __name__ == "__main__":
    main()
