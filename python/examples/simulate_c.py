"""Scenario C (2 cm and -1 cm, opposite ways, from rest) under the scanner
cycle, positions and gradient plotted into simulate_c.png."""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import capsule_mpc as cm

run = cm.simulate([0.02, -0.01], sampling="variable", disturbance="paper", seed=1, duration_s=3.0)
print(f"settle {run.settle_time_s} s, final error {1e3 * run.metrics['final_position_error_m']:.3f} mm")
fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
for i, name in enumerate(cm.Config.default().names):
    ax1.plot(run.t, 1e3 * run.x[:, 2 * i], label=name)
    ax1.axhline(1e3 * run.target[2 * i], color="grey", lw=0.5)
ax1.set_ylabel("position (mm)")
ax1.legend()
ax2.step(run.t, 1e3 * run.u, where="post")
ax2.set_ylabel("gradient (mT/m)")
ax2.set_xlabel("t (s)")
out = sys.argv[1] if len(sys.argv) > 1 else "simulate_c.png"
fig.savefig(out, dpi=100)
print(f"wrote {out}")
