#!/usr/bin/env python3
"""The model-mismatch grid of docs/known-limits.md.

24 targets (+-4 cm, 2 cm steps) x seeds 1..N (default 8), the paper
disturbance, 6 s runs, strict settle, both scanner samplings, on the model
and five plants off it. Per row: unsettled runs, median / 90th percentile /
worst settle (9.00 stands for never) and the true frames rejected.

    cargo build --release
    python3 docs/scripts/mismatch_grid.py target/release/capsule-mpc [N] [--told STD] [--disturbance-model MODEL] [--refine MODE]

With `--told STD` every plant's controller is told the plant's own factors
with deviation STD (`--calibrated-*-scale`, `--calibrated-std`; the model
is told 1). `--disturbance-model drift` (or `constant`) changes how the
disturbance varies in time, at the same size. `--refine none` measures the
explicit law alone.
"""
import statistics
import sys
from concurrent.futures import ThreadPoolExecutor

from grid_runs import NEVER_S, TARGETS, pop_option, simulate

PLANTS = [
    ("model", []),
    ("drag x0.8", ["--plant-drag-scale", "0.8"]),
    ("drag x1.2", ["--plant-drag-scale", "1.2"]),
    ("drag (x1.2, x0.8)", ["--plant-drag-scale", "1.2,0.8"]),
    ("gain x0.9", ["--plant-gain-scale", "0.9"]),
    ("gain x1.1", ["--plant-gain-scale", "1.1"]),
]


def run(binary, sampling, extra, target, seed):
    d = simulate(binary, sampling, extra, target, seed)
    return d["metrics"]["settle_time_s"], d["frames"]["rejected"], d["frames"]["received"]


def told(extra, std):
    """`extra` with the controller told the plant's factors at `std`."""
    drag = extra[extra.index("--plant-drag-scale") + 1] if "--plant-drag-scale" in extra else "1"
    gain = extra[extra.index("--plant-gain-scale") + 1] if "--plant-gain-scale" in extra else "1"
    return extra + ["--calibrated-drag-scale", drag, "--calibrated-gain-scale", gain,
                    "--calibrated-std", std]


def main():
    args = sys.argv[1:]
    told_std = pop_option(args, "--told")
    disturbance_model = pop_option(args, "--disturbance-model")
    refine = pop_option(args, "--refine")
    binary = args[0]
    seeds = range(1, int(args[1]) + 1) if len(args) > 1 else range(1, 9)
    for sampling in ("constant", "variable"):
        for name, extra in PLANTS:
            if told_std is not None:
                extra = told(extra, told_std)
            if disturbance_model is not None:
                extra = extra + ["--disturbance-model", disturbance_model]
            if refine is not None:
                extra = extra + ["--refine", refine]
            jobs = [(binary, sampling, extra, t, s) for t in TARGETS for s in seeds]
            with ThreadPoolExecutor(2) as ex:
                res = list(ex.map(lambda a: run(*a), jobs))
            settle = sorted(NEVER_S if s is None else s for s, _, _ in res)
            unsettled = sum(1 for s, _, _ in res if s is None)
            rejected = sum(r for _, r, _ in res)
            received = sum(n for _, _, n in res)
            print(f"{sampling:8s} {name:18s} unsettled {unsettled:3d}/{len(res)} "
                  f"median {statistics.median(settle):.2f} p90 {settle[int(0.9 * len(settle))]:.2f} "
                  f"worst {settle[-1]:.2f} s | rejected {rejected}/{received} frames", flush=True)


if __name__ == "__main__":
    main()
