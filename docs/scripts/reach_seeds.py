#!/usr/bin/env python3
"""The scanner-cycle reach grids over several seeds (docs/results.md,
"Reach: every target of a grid").

`capsule-mpc reach` with the paper disturbance for seeds 1..N (default 8),
both scanner samplings. Per sampling: runs, unsettled runs, the strict
settle over its bound (constant sampling: the coasted schedule's own bound
where the tables have it, else the ideal one; variable sampling: the ideal
minimum time) at the median, 90th percentile and worst, how many runs are
above 1.8x and 2x, the settle times' median and worst, and the worst run.
Extra arguments go to `reach` (e.g. `--range-cm 5 --step-cm 1.1`,
`--no-shooting`, `--extra-delay 0.01`, `--plant-drag-scale 1.2`).

    cargo build --release
    python3 docs/scripts/reach_seeds.py target/release/capsule-mpc [N] [reach arguments...]
"""
import json
import os
import statistics
import subprocess
import sys
import tempfile


def reach(binary, sampling, seed, extra):
    """The JSON report of one reach grid."""
    fd, path = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        subprocess.run(
            [binary, "reach", "--sampling", sampling, "--disturbance", "paper",
             "--seed", str(seed), "--json", path] + extra,
            check=True, capture_output=True)
        with open(path) as f:
            return json.load(f)
    finally:
        os.remove(path)


def ratio(point, sampling):
    """Settle over the bound this sampling is compared with (None: no bound)."""
    own = point["settle_over_schedule_bound"] if sampling == "constant" else None
    return own if own is not None else point["settle_over_bound"]


def summarize(binary, sampling, seeds, extra):
    ratios, settles, unsettled, worst = [], [], 0, None
    for seed in seeds:
        for p in reach(binary, sampling, seed, extra)["points"]:
            if p["refused"]:
                continue
            if p["settle_time_s"] is None:
                unsettled += 1
                continue
            r = ratio(p, sampling)
            if r is None:
                continue
            ratios.append(r)
            settles.append(p["settle_time_s"])
            if worst is None or r > worst[0]:
                worst = (r, p["target_m"], seed, p["settle_time_s"])
    ratios.sort()
    settles.sort()
    runs = len(ratios) + unsettled
    print(f"{sampling:8s} runs {runs} unsettled {unsettled} | ratio median "
          f"{statistics.median(ratios):.2f} p90 {ratios[int(0.9 * len(ratios))]:.2f} "
          f"worst {ratios[-1]:.2f}, above 1.8x {sum(r > 1.8 for r in ratios)}, "
          f"above 2x {sum(r > 2.0 for r in ratios)} | settle median "
          f"{statistics.median(settles):.2f} s worst {settles[-1]:.2f} s | worst run: "
          f"target {[round(100 * t, 2) for t in worst[1]]} cm, seed {worst[2]}, "
          f"{worst[3]:.3f} s", flush=True)


def main():
    binary = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 8
    extra = sys.argv[3:]
    for sampling in ("constant", "variable"):
        summarize(binary, sampling, range(1, n + 1), extra)


if __name__ == "__main__":
    main()
