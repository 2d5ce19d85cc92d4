"""The controller around a lab's own plant, written in Python: two capsules
(drag -b v|v|, gain g of the default config), ideal sampling, to target A;
prints the settle time and the time the Python side costs per cycle."""

import time

import numpy as np

import capsule_mpc as cm

cfg = cm.Config.default()
b, g, dt = cfg.b, cfg.g, cfg.sample_time_s


def step(x, u, h=1e-3):
    def f(s):
        d = np.empty_like(s)
        d[0::2] = s[1::2]
        d[1::2] = -b * s[1::2] * np.abs(s[1::2]) + g * u
        return d
    k1 = f(x); k2 = f(x + 0.5 * h * k1); k3 = f(x + 0.5 * h * k2); k4 = f(x + h * k3)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


target = np.array([0.02, 0.0, 0.03, 0.0])
c = cm.Controller(cfg, [0.0, 0.0])
c.set_sampling("ideal")
c.set_target(target)
x, t, last_out = np.zeros(4), 0.0, None
for k in range(150):
    c.feed_state(x)
    u, status = c.next_actuation(t)
    for _ in range(20):
        x = step(x, u[0])
        t += 1e-3
        inside = np.all(np.abs(x[0::2] - target[0::2]) <= 1e-3) and np.all(np.abs(x[1::2]) < 5e-3)
        if not inside:
            last_out = t
print(f"settle {last_out:.3f} s (the Rust simulator: {cm.simulate(target, sampling='ideal', disturbance='none').settle_time_s:.3f} s)")

# The Python side of a cycle: the same calls on a controller without a
# target (the runtime returns at once), so what is timed is the binding.
idle = cm.Controller(cfg, [0.0, 0.0])
idle.set_sampling("ideal")
times = []
state = np.zeros(4)
for k in range(20000):
    t0 = time.perf_counter()
    idle.feed_state(state)
    idle.next_actuation(0.02 * k)
    times.append(time.perf_counter() - t0)
print(f"Python-side overhead per cycle (feed_state + next_actuation, no solve): median {1e6 * np.median(times):.1f} us, p99 {1e6 * np.percentile(times, 99):.1f} us")
