#!/usr/bin/env python3
"""How well one move's frames identify the factors (docs/decisions.md,
"Identifying the factors before the first entry").

For each run of the mismatch grid (24 targets x seeds 1..N, default 8,
variable sampling, paper disturbance, 6 s) on one plant: a batch
least-squares fit of each capsule's gain and drag factors to the frames
taken before the first hold entry (the gradient played is known; the
model's RK2 step at 1 ms; the 10 % / 20 % prior; frames of 0.2 mm),
against the runtime's own recursive estimate at the end of the run.
Prints the median and 90th-percentile absolute errors per capsule.

    cargo build --release
    python3 docs/scripts/factor_fit.py target/release/capsule-mpc "--plant-drag-scale 1.2" 1,1.2,1,1.2 [N]

The third argument is the plant's true factors: gain, drag of capsule 1,
then of capsule 2.
"""
import statistics
import sys
from concurrent.futures import ThreadPoolExecutor

from grid_runs import TARGETS, simulate

FRAME_STD_M = 2e-4
PRIOR_STD = (0.1, 0.2)


def positions(g, b, gradients, dt_s, times_s):
    """Positions at `times_s` of a capsule from rest at 0 (RK2)."""
    x, v, t, out, i = 0.0, 0.0, 0.0, [], 0
    for u in gradients:
        while i < len(times_s) and times_s[i] <= t + 1e-9:
            out.append(x)
            i += 1
        a1 = g * u - b * v * abs(v)
        vm = v + 0.5 * dt_s * a1
        x += dt_s * (v + 0.5 * dt_s * a1)
        v += dt_s * (g * u - b * vm * abs(vm))
        t += dt_s
    out.extend([x] * (len(times_s) - len(out)))
    return out


def fit(g, b, gradients, dt_s, times_s, z):
    """Gauss-Newton on (gain factor, drag factor) with the prior as two
    extra residuals."""
    p = [1.0, 1.0]
    for _ in range(8):
        r0 = positions(g * p[0], b * p[1], gradients, dt_s, times_s)
        jac = []
        for j in range(2):
            q = list(p)
            q[j] += 1e-4
            r = positions(g * q[0], b * q[1], gradients, dt_s, times_s)
            jac.append([(a - c) / 1e-4 for a, c in zip(r, r0)])
        res = [zi - ri for zi, ri in zip(z, r0)]
        a = [[sum(jac[m][k] * jac[n][k] for k in range(len(z))) for n in range(2)] for m in range(2)]
        rhs = [sum(jac[m][k] * res[k] for k in range(len(z))) for m in range(2)]
        for m in range(2):
            w = (FRAME_STD_M / PRIOR_STD[m]) ** 2
            a[m][m] += w
            rhs[m] += w * (1.0 - p[m])
        det = a[0][0] * a[1][1] - a[0][1] * a[1][0]
        d = [(a[1][1] * rhs[0] - a[0][1] * rhs[1]) / det, (a[0][0] * rhs[1] - a[1][0] * rhs[0]) / det]
        p = [p[0] + d[0], p[1] + d[1]]
        if abs(d[0]) + abs(d[1]) < 1e-6:
            break
    return p


def run(binary, extra, truth, target, seed):
    d = simulate(binary, "variable", extra, target, seed)
    holds = [m["t_s"] for m in d["modes"] if m["mode"] == "hold"]
    end_s = holds[0] if holds else d["t"][-1]
    dt_s = d["t"][1] - d["t"][0]
    gradients = [u for t, u in zip(d["t"], d["u"]) if t < end_s]
    frames = [m for m in d["measurements"] if not m["lost"] and m["t_s"] < end_s]
    out = []
    for i in range(2):
        times = [m["t_s"] for m in frames]
        z = [m["positions_m"][i] for m in frames]
        p = fit(d["params"]["g"][i], d["params"]["b"][i], gradients, dt_s, times, z)
        learned = d["estimated_factors"][i]
        out.append((abs(p[0] - truth[2 * i]), abs(p[1] - truth[2 * i + 1]),
                    abs(learned["gain"] - truth[2 * i]), abs(learned["drag"] - truth[2 * i + 1])))
    return out


def main():
    binary, extra = sys.argv[1], sys.argv[2].split()
    truth = [float(v) for v in sys.argv[3].split(",")]
    seeds = range(1, int(sys.argv[4]) + 1) if len(sys.argv) > 4 else range(1, 9)
    jobs = [(binary, extra, truth, t, s) for t in TARGETS for s in seeds]
    with ThreadPoolExecutor(2) as ex:
        res = list(ex.map(lambda a: run(*a), jobs))

    def stat(values):
        v = sorted(values)
        return f"{statistics.median(v):.3f} / {v[int(0.9 * len(v))]:.3f}"

    for i in range(2):
        rows = [r[i] for r in res]
        print(f"capsule {i + 1}: gain, drag error (median / p90): batch before the first hold "
              f"{stat(r[0] for r in rows)}, {stat(r[1] for r in rows)}; runtime at 6 s "
              f"{stat(r[2] for r in rows)}, {stat(r[3] for r in rows)}")


if __name__ == "__main__":
    main()
