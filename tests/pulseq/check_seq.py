#!/usr/bin/env python3
"""Reads a .seq file written by capsule-mpc with pypulseq and checks it against
the run's JSON u(t) (the output of `capsule-mpc simulate --json`, or of the
`synthetic_run` example of the capsule-mpc-pulseq crate).

Checks:
  * the [SIGNATURE] MD5 matches the file;
  * pypulseq's check_timing() reports no error;
  * the x gradient pypulseq reconstructs (waveforms_and_times) equals u(t),
    converted to Hz/m, within 0.1 % of u_max at every gradient-raster point
    farther than the longest possible ramp from a change of u;
  * the x gradient stays within the amplitude and slew-rate limits the file
    declares, and the y and z gradients are empty;
  * there are as many tracking events (blocks with an ADC, each with one RF
    excitation) as the run has measurements (none for ideal sampling), and
    each starts at its measurement's time;
  * the sequence lasts as long as the run.

Prints what it measured; exits 1 if a check fails. `--plot FILE.png` draws the
exported sequence (x gradient and tracking events on a time axis).
"""

import argparse
import hashlib
import json
import sys
import warnings

import numpy as np
import pypulseq as pp

# Tolerance of the waveform comparison, as a fraction of u_max (the 0.1 %).
WAVEFORM_TOLERANCE = 1e-3


def block_starts(seq):
    """Start time of every block, in file order, and the total duration."""
    starts, now = {}, 0.0
    for block_id in seq.block_events:
        starts[block_id] = now
        now += seq.block_durations[block_id]
    return starts, now


def check(seq_path, run_path, plot_path=None):
    results = []  # (name, ok, detail)

    def record(name, ok, detail):
        results.append((name, bool(ok), detail))
        print(f"  [{'ok' if ok else 'FAIL'}] {name}: {detail}")

    with open(seq_path, encoding="utf-8") as f:
        text = f.read()
    with open(run_path, encoding="utf-8") as f:
        run = json.load(f)

    seq = pp.Sequence()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # e.g. an unknown version or missing raster
        seq.read(seq_path)

    head, _, _ = text.partition("\n[SIGNATURE]")
    md5 = hashlib.md5(head.encode("utf-8")).hexdigest()
    stored = getattr(seq, "signature_value", None)
    record("signature", md5 == stored, f"md5 {md5}, file says {stored}")

    ok, errors = seq.check_timing()
    record("check_timing", ok and not errors, f"{len(errors)} timing errors" + (f": {errors[:3]}" if errors else ""))

    defs = seq.definitions
    gamma = float(defs["CapsuleMpcGammaHzPerT"])
    u_max = float(defs["CapsuleMpcMaxGradientTPerM"])
    slew = float(defs["CapsuleMpcSlewRateTPerMPerS"])
    raster = float(seq.grad_raster_time)

    t = np.asarray(run["t"], dtype=float)
    u = np.asarray(run["u"], dtype=float)
    run_duration = float(t[-1] - t[0])
    _, seq_duration = block_starts(seq)
    record(
        "total duration",
        abs(seq_duration - run_duration) <= 1e-9 * max(1.0, run_duration),
        f"sequence {seq_duration:.6f} s, run {run_duration:.6f} s, {len(seq.block_events)} blocks",
    )

    wave_data, tfp_excitation, _, t_adc, _ = seq.waveforms_and_times()
    gx = np.asarray(wave_data[0], dtype=float).reshape(2, -1)
    tx, ax = gx[0] + t[0], gx[1]
    other = sum(np.asarray(w).reshape(2, -1).shape[1] for w in wave_data[1:])
    record("y and z gradients empty", other == 0, f"{other} points on y and z")

    # u(t) of the run: u[k] holds on [t[k], t[k+1]); zero before and after.
    # A ramp lies within u_max / slew (+ raster rounding) of each change of u.
    u_before = np.concatenate(([0.0], u[:-1]))
    changes = t[np.flatnonzero(u != u_before)]
    changes = np.unique(np.concatenate((changes, [t[0], t[-1]])))
    margin = u_max / slew + 2 * raster
    tc = t[0] + (np.arange(int(round(run_duration / raster))) + 0.5) * raster
    idx = np.searchsorted(changes, tc)
    near_prev = np.abs(tc - changes[np.clip(idx - 1, 0, len(changes) - 1)]) < margin
    near_next = np.abs(changes[np.clip(idx, 0, len(changes) - 1)] - tc) < margin
    away = ~(near_prev | near_next)
    tc = tc[away]
    u_run = u[np.clip(np.searchsorted(t, tc, side="right") - 1, 0, len(u) - 1)]
    u_seq = np.interp(tc, tx, ax, left=0.0, right=0.0) / gamma if len(tx) else np.zeros_like(tc)
    deviation = np.abs(u_seq - u_run)
    worst = float(deviation.max()) if len(deviation) else 0.0
    worst_at = float(tc[np.argmax(deviation)]) if len(deviation) else 0.0
    record(
        "x gradient equals u(t) away from ramps",
        worst <= WAVEFORM_TOLERANCE * u_max,
        f"max deviation {worst:.3e} T/m = {100 * worst / u_max:.2e} % of u_max (at t = {worst_at:.5f} s) "
        f"over {len(tc)} raster points (ramp margin {margin * 1e6:.0f} us, {away.size - len(tc)} points excluded)",
    )

    peak = float(np.max(np.abs(ax))) / gamma if len(ax) else 0.0
    record("amplitude limit", peak <= u_max * (1 + 1e-9), f"peak |gx| {peak * 1e3:.4f} mT/m, limit {u_max * 1e3:.1f} mT/m")
    dt = np.diff(tx)
    da = np.diff(ax) / gamma
    jumps = np.flatnonzero((dt <= 1e-12) & (np.abs(da) > 1e-9 * u_max))
    rate = np.abs(da[dt > 1e-12] / dt[dt > 1e-12])
    max_rate = float(rate.max()) if len(rate) else 0.0
    record(
        "slew-rate limit",
        len(jumps) == 0 and max_rate <= slew * (1 + 1e-6),
        f"max slew {max_rate:.2f} T/m/s, limit {slew:.0f} T/m/s, {len(jumps)} instantaneous jumps",
    )

    starts, _ = block_starts(seq)
    adc_blocks = [b for b, ev in seq.block_events.items() if ev[5] > 0]
    rf_blocks = [b for b, ev in seq.block_events.items() if ev[1] > 0]
    measurements = run.get("measurements", [])
    sampling = run.get("sampling")
    expected = 0 if sampling == "ideal" else len(measurements)
    n_exc = np.asarray(tfp_excitation).reshape(3, -1).shape[1]
    record(
        "tracking events",
        len(adc_blocks) == expected and rf_blocks == adc_blocks and n_exc == expected,
        f"{len(adc_blocks)} ADC blocks, {n_exc} excitations; run has {len(measurements)} measurements "
        f"({sampling} sampling: {expected} expected), {len(np.asarray(t_adc))} ADC samples",
    )
    if expected:
        t_meas = np.sort([float(m["t_s"]) for m in measurements])
        t_trk = np.sort([starts[b] + t[0] for b in adc_blocks])
        offset = float(np.max(np.abs(t_meas - t_trk))) if len(t_meas) == len(t_trk) else np.inf
        record("tracking at the measurement times", offset <= raster / 2, f"max offset {offset:.2e} s")

    if plot_path:
        plot(seq, run, tx, ax / gamma, starts, adc_blocks, plot_path, u_max)
        print(f"  wrote {plot_path}")

    return results


def plot(seq, run, tx, gx_t_per_m, starts, adc_blocks, path, u_max):
    """Overview of the whole sequence, a window around one tracking block, and
    a zoom on one ramp between two actuation samples."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(run["t"], dtype=float)
    u = np.asarray(run["u"], dtype=float)
    phase = list(run["phase"])
    mt = 1e3  # T/m -> mT/m

    fig = plt.figure(figsize=(11, 7.2))
    grid = fig.add_gridspec(2, 2, height_ratios=[1.15, 1])
    overview = fig.add_subplot(grid[0, :])
    window = fig.add_subplot(grid[1, 0])
    ramp = fig.add_subplot(grid[1, 1])

    def tracking(ax, t0, t1, events):
        labelled = False
        for b in adc_blocks:
            s = starts[b] + t[0]
            if s > t1 or s + seq.block_durations[b] < t0:
                continue
            ax.axvspan(s, s + seq.block_durations[b], color="tab:orange", alpha=0.18, lw=0)
            if events:
                block = seq.get_block(b)
                rf0, adc0 = s + block.rf.delay, s + block.adc.delay
                ax.plot([rf0, rf0 + block.rf.shape_dur], [0.9 * u_max * mt] * 2, color="tab:red", lw=5, solid_capstyle="butt")
                adc1 = adc0 + block.adc.num_samples * block.adc.dwell
                ax.plot([adc0, adc1], [0.9 * u_max * mt] * 2, color="tab:green", lw=5, solid_capstyle="butt")
                if not labelled:
                    ax.annotate("placeholder RF", (rf0, 0.9 * u_max * mt), xytext=(rf0, 1.1 * u_max * mt),
                                fontsize=8, color="tab:red", ha="right", arrowprops={"arrowstyle": "-", "color": "tab:red"})
                    ax.annotate("placeholder ADC", (0.5 * (adc0 + adc1), 0.9 * u_max * mt), xytext=(adc1, 1.1 * u_max * mt),
                                fontsize=8, color="tab:green", ha="left", arrowprops={"arrowstyle": "-", "color": "tab:green"})
                    labelled = True

    # Overview.
    tracking(overview, t[0], t[-1], events=False)
    overview.step(t, u * mt, where="post", color="0.6", lw=2.2, label="run u(t) (JSON)")
    overview.plot(tx, gx_t_per_m * mt, color="tab:blue", lw=0.9, label="x gradient read from the .seq by pypulseq")
    overview.fill_between([], [], color="tab:orange", alpha=0.3, label="tracking block (placeholder RF + ADC)")
    overview.set_xlim(t[0], t[-1])
    overview.set_ylim(-1.1 * u_max * mt, 1.1 * u_max * mt)
    overview.set_ylabel("gradient (mT/m)")
    overview.set_xlabel("time (s)")
    overview.set_title(
        f"Exported sequence: scenario {run.get('scenario', '?')}, {run.get('sampling', '?')} sampling, "
        f"{len(seq.block_events)} blocks, {len(adc_blocks)} tracking events"
    )
    overview.legend(loc="upper right", fontsize=8, ncol=3)

    # A window around the tracking block that follows the strongest gradient.
    track_starts = [starts[b] + t[0] for b in adc_blocks]
    before = [abs(u[max(int(np.searchsorted(t, s)) - 1, 0)]) for s in track_starts]
    centre = track_starts[int(np.argmax(before))] if track_starts else t[0] + 0.5 * (t[-1] - t[0])
    w0, w1 = centre - 0.05, centre + 0.07
    tracking(window, w0, w1, events=True)
    window.step(t, u * mt, where="post", color="0.6", lw=2.2)
    window.plot(tx, gx_t_per_m * mt, color="tab:blue", lw=1.2)
    window.set_xlim(w0, w1)
    window.set_ylim(-1.1 * u_max * mt, 1.3 * u_max * mt)
    window.set_xlabel("time (s)")
    window.set_ylabel("gradient (mT/m)")
    window.set_title("around one tracking block", fontsize=10)

    # The largest step between two consecutive actuation samples.
    steps = [
        (abs(u[k] - u[k - 1]), k)
        for k in range(1, len(u) - 1)
        if phase[k] == "actuate" and phase[k - 1] == "actuate" and u[k] != u[k - 1]
    ]
    k = max(steps)[1] if steps else int(np.argmax(np.abs(np.diff(u)))) + 1
    tz, half = t[k], 0.6e-3
    sel = (tx > tz - 2 * half) & (tx < tz + 2 * half)
    ramp.step(t, u * mt, where="post", color="0.6", lw=2.2, label="run u(t): zero-order hold")
    ramp.plot(tx[sel], gx_t_per_m[sel] * mt, "o-", color="tab:blue", ms=4, lw=1.2, label="x gradient: ramp centred on the boundary")
    ramp.axvline(tz, color="0.3", lw=0.6, ls=":")
    ramp.set_xlim(tz - half, tz + half)
    ramp.set_xlabel("time (s)")
    ramp.set_ylabel("gradient (mT/m)")
    ramp.set_title(f"largest step between two samples (t = {tz:.2f} s)", fontsize=10)
    ramp.ticklabel_format(axis="x", useOffset=False)
    ramp.legend(loc="upper left" if u[k] > u[k - 1] else "lower left", fontsize=8)

    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pairs", nargs="+", metavar="SEQ JSON", help="pairs of .seq and run JSON files")
    parser.add_argument("--plot", metavar="PNG", help="draw the first sequence into this file")
    args = parser.parse_args()
    if len(args.pairs) % 2:
        parser.error("give .seq and JSON files in pairs")
    passed = failed = 0
    for i in range(0, len(args.pairs), 2):
        seq_path, run_path = args.pairs[i], args.pairs[i + 1]
        print(f"{seq_path} against {run_path} (pypulseq {pp.__version__}):")
        try:
            results = check(seq_path, run_path, args.plot if i == 0 else None)
        except Exception as e:  # a reader error is a failed check, reported as such
            print(f"  [FAIL] reading: {type(e).__name__}: {e}")
            failed += 1
            continue
        passed += sum(ok for _, ok, _ in results)
        failed += sum(not ok for _, ok, _ in results)
    print(f"pulseq checks: {passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
