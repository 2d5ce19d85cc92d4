"""The Python package against the CLI and the runtime: same runs, same
errors, the closed loop around a Python plant."""

import json
import math
import os
import subprocess
import time

import numpy as np
import pytest

import capsule_mpc as cm

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CLI = os.path.join(REPO, "target", "release", "capsule-mpc")


def test_default_config_constants():
    c = cm.Config.default()
    assert c.capsule_count == 2
    assert np.allclose(c.g, [173.2484, 173.2484], rtol=1e-6)
    assert np.allclose(c.b, [134.713, 16.839], rtol=1e-4)
    assert c.sample_time_s == 0.02 and c.u_max_t_per_m == 0.04
    assert c.workspace == (-0.06, 0.06)
    assert c.to_dict()["scanner"]["max_gradient_t_per_m"] == 0.04


def test_three_capsule_config():
    assert cm.Config.three_capsules().capsule_count == 3


def test_config_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        cm.Config.from_toml(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    toml = open(os.path.join(REPO, "configs", "paper.toml")).read().replace("max_gradient_t_per_m = 0.04", "max_gradient_t_per_m = -1.0")
    bad.write_text(toml)
    with pytest.raises(cm.ConfigError, match="max_gradient_t_per_m"):
        cm.Config.from_toml(bad)
    assert issubclass(cm.ConfigError, ValueError)


def test_config_from_str():
    toml = open(os.path.join(REPO, "configs", "paper.toml")).read()
    assert cm.Config.from_str(toml).capsule_count == 2
    with pytest.raises(cm.ConfigError):
        cm.Config.from_str("[[capsule]]\nname = 'x'\n")


def test_simulate_scenario_c_settles():
    run = cm.simulate([0.02, -0.01], sampling="ideal", disturbance="none")
    assert run.x.shape == (len(run.t), 4) and run.u.shape == run.t.shape
    # Ideal sampling shoots by default: near the independent 0.68 s minimum.
    assert 0.65 < run.settle_time_s < 0.72
    assert run.metrics["final_position_error_m"] < 1e-3
    assert set(run.phase) <= {"track", "actuate"}


def test_target_as_full_state_is_the_same_run():
    a = cm.simulate([0.02, -0.01], sampling="ideal", disturbance="none")
    b = cm.simulate([0.02, 0.0, -0.01, 0.0], sampling="ideal", disturbance="none")
    assert np.array_equal(a.u, b.u)


@pytest.mark.skipif(not os.path.exists(CLI), reason="the CLI is not built (cargo build --release)")
@pytest.mark.parametrize("sampling,disturbance", [("ideal", "none"), ("constant", "paper"), ("variable", "stress")])
def test_simulate_is_the_cli_bit_for_bit(tmp_path, sampling, disturbance):
    out = tmp_path / "run.json"
    subprocess.run(
        [CLI, "simulate", "--target", "0.02,0,-0.01,0", "--sampling", sampling, "--disturbance", disturbance, "--seed", "3", "--json", str(out)],
        check=True,
        capture_output=True,
    )
    cli = json.loads(out.read_text())
    py = cm.simulate([0.02, -0.01], sampling=sampling, disturbance=disturbance, seed=3)
    assert py.u.tolist() == cli["u"]
    assert py.metrics["settle_time_s"] == cli["metrics"]["settle_time_s"]
    assert py.metrics["final_position_error_m"] == cli["metrics"]["final_position_error_m"]
    ours = json.loads(py.to_json())
    for k in ("t", "x", "u", "target", "measurements"):
        assert ours[k] == cli[k]


@pytest.mark.skipif(not os.path.exists(CLI), reason="the CLI is not built (cargo build --release)")
def test_odd_timing_is_the_cli_bit_for_bit_and_recorded(tmp_path):
    out = tmp_path / "run.json"
    subprocess.run(
        [CLI, "simulate", "--target", "0.02,0,-0.01,0", "--sampling", "constant", "--seed", "2",
         "--extra-delay", "0.005", "--lose-every", "4", "--json", str(out)],
        check=True,
        capture_output=True,
    )
    cli = json.loads(out.read_text())
    py = cm.simulate([0.02, -0.01], sampling="constant", seed=2, extra_delay_s=0.005, lose_every=4)
    assert py.u.tolist() == cli["u"]
    assert py.timing == cli["timing"] == {"tracking_time_s": 0.02, "extra_delay_s": 0.005, "lose_every": 4}
    lost = sum(1 for m in py.measurements if m["lost"])
    assert abs(lost - len(py.measurements) / 4) <= 1, (lost, len(py.measurements))
    # The frame reaches the controller 5 ms after its tracking phase ends.
    delays = {round(m["available_s"] - m["t_s"], 6) for m in py.measurements}
    assert delays == {0.025}, delays
    assert cm.simulate([0.02, -0.01], sampling="constant").timing["lose_every"] is None


def test_odd_timing_errors_name_the_argument():
    for bad in (0, -2, 2.5, True):
        with pytest.raises(ValueError, match="lose_every"):
            cm.simulate([0.02, -0.01], sampling="constant", lose_every=bad)
    with pytest.raises(ValueError, match=r"extra delay -0.01 s is outside \[0, 1\] s"):
        cm.simulate([0.02, -0.01], sampling="constant", extra_delay_s=-0.01)
    with pytest.raises(ValueError, match="ideal sampling has no tracking phase"):
        cm.simulate([0.02, -0.01], sampling="ideal", extra_delay_s=0.005)


def test_a_target_changed_mid_run_is_the_cli_bit_for_bit(tmp_path):
    out = tmp_path / "run.json"
    subprocess.run(
        [CLI, "simulate", "--target", "0.02,0,0.03,0", "--retarget", "0.02,0,-0.01,0",
         "--retarget-at", "0.2", "--sampling", "constant", "--seed", "3", "--duration", "4",
         "--json", str(out)],
        check=True,
        capture_output=True,
    )
    cli = json.loads(out.read_text())
    py = cm.simulate([0.02, 0.03], sampling="constant", seed=3, duration_s=4.0,
                     retarget=[0.02, -0.01], retarget_at_s=0.2)
    assert py.u.tolist() == cli["u"]
    assert py.retarget == cli["retarget"] == {"at_s": 0.2, "first_target": [0.02, 0.0, 0.03, 0.0]}
    assert py.target.tolist() == [0.02, 0.0, -0.01, 0.0]
    assert py.settle_time_s is not None and py.settle_time_s < 2.0
    assert cm.simulate([0.02, 0.03]).retarget is None
    with pytest.raises(ValueError, match="retarget and retarget_at_s go together"):
        cm.simulate([0.02, 0.03], retarget=[0.02, -0.01])
    with pytest.raises(ValueError, match=r"retarget at 3.5 s: the target can change only during the run, \[0, 3\) s"):
        cm.simulate([0.02, 0.03], retarget=[0.02, -0.01], retarget_at_s=3.5)
    with pytest.raises(ValueError, match="retarget .* capsule 2 at -0.09 m is outside the workspace"):
        cm.simulate([0.02, 0.03], retarget=[0.02, -0.09], retarget_at_s=1.0)


def test_bad_target_length():
    with pytest.raises(ValueError, match="target has 3 entries"):
        cm.simulate([0.01, 0.02, 0.03])


def test_target_outside_workspace_names_capsule_and_excess():
    with pytest.raises(ValueError, match=r"capsule 2 at 0.09 m is outside the workspace .* by 0.0300 m"):
        cm.simulate([0.01, 0.09], sampling="ideal", disturbance="none")


def test_unknown_sampling():
    with pytest.raises(ValueError, match="sampling 'fast' is not one of"):
        cm.simulate([0.01, 0.01], sampling="fast")


def test_unknown_disturbance_and_refine():
    with pytest.raises(ValueError, match="disturbance"):
        cm.simulate([0.01, 0.01], disturbance="huge")
    with pytest.raises(ValueError, match="refine 'always'"):
        cm.simulate([0.01, 0.01], refine="always")


def test_non_finite_position():
    with pytest.raises(ValueError, match="not finite"):
        cm.simulate([0.01, float("nan")])
    c = cm.Controller()
    c.set_target([0.02, 0.0, -0.01, 0.0])
    with pytest.raises(ValueError, match="not finite"):
        c.feed_tracking([0.0, float("inf")], 0.0)


def test_plant_off_the_model_is_recorded():
    run = cm.simulate([0.02, 0.03], sampling="constant", duration_s=2.0, plant_drag_scale=[1.2, 0.8], plant_gain_scale=0.9)
    assert run.plant["drag_scale"] == [1.2, 0.8] and run.plant["gain_scale"] == [0.9, 0.9]
    with pytest.raises(ValueError, match="plant drag scale"):
        cm.simulate([0.02, 0.03], plant_drag_scale=[1.0, 1.0, 1.0])


def test_the_controller_learns_a_plant_off_the_model():
    # Drag x0.8 on both capsules: after a 6 s run the estimated drag factors
    # are within 0.1 of the truth and closer to it than to the model's 1;
    # the mode timeline starts planning and ends in the hold.
    run = cm.simulate([0.02, 0.03], sampling="constant", duration_s=6.0, plant_drag_scale=0.8)
    factors = run.estimated_factors
    assert len(factors) == 2
    for f in factors:
        assert abs(f["drag"] - 0.8) < 0.1 and abs(f["drag"] - 0.8) < abs(f["drag"] - 1.0), factors
        assert f["drag_std"] > 0.0
    assert run.modes[0]["mode"] == "plan" and run.modes[-1]["mode"] == "hold", run.modes
    # Ideal sampling learns them from the full state, within 1 % in 1 s.
    ideal = cm.simulate([0.02, 0.03], sampling="ideal", duration_s=1.0, plant_gain_scale=0.9)
    for f in ideal.estimated_factors:
        assert abs(f["gain"] - 0.9) < 0.01, ideal.estimated_factors


def test_reach_map_grids():
    m = cm.reach(range_cm=2.0, step_cm=1.0)
    assert m.summary["targets"] == 24 and m.summary["refused"] == 0
    assert m.grid_ratio.shape == (5, 5)
    assert math.isnan(m.grid_ratio[2, 2])  # the start itself is not a target
    assert np.nanmax(m.ratio) < 1.6
    assert "24 targets" in m.summary_line()


@pytest.mark.skipif(not os.path.exists(CLI), reason="the CLI is not built (cargo build --release)")
def test_reach_from_a_start_is_the_cli(tmp_path):
    out = tmp_path / "reach.json"
    subprocess.run(
        [CLI, "reach", "--start", "0.02,-0.01", "--range-cm", "1", "--step-cm", "1", "--json", str(out)],
        check=True,
        capture_output=True,
    )
    cli = json.loads(out.read_text())
    m = cm.reach(start=[0.02, -0.01], range_cm=1.0, step_cm=1.0)
    assert m.summary == cli["summary"]
    assert m.targets_m.tolist() == [p["target_m"] for p in cli["points"]]
    assert m.start_m.tolist() == [0.02, -0.01]
    # The grid is centred on the start: its centre cell is the start itself.
    assert math.isnan(m.grid_ratio[1, 1]) and not np.isnan(m.grid_ratio[0, 2])
    with pytest.raises(ValueError, match="start has 1 positions"):
        cm.reach(start=[0.02], range_cm=1.0)


def test_reach_reports_how_far_the_way_leaves_the_workspace():
    # Both capsules to (6, 6) cm: the large one swings about 4 cm past the
    # +-6 cm workspace (docs/known-limits.md).
    m = cm.reach(range_cm=6.0, step_cm=3.0)
    e = m.workspace_excursion_m
    assert e.shape == (24,) and np.all(e >= 0.0)
    assert m.summary["left_workspace"] == int(np.sum(e > 0.0)) > 0
    assert m.summary["worst_workspace_excursion_m"] == e.max() > 0.03
    assert m.summary["worst_excursion_target_m"] == m.targets_m[np.argmax(e)].tolist()


@pytest.mark.skipif(not os.path.exists(CLI), reason="the CLI is not built (cargo build --release)")
def test_reach_under_drift_and_delay_is_the_cli(tmp_path):
    out = tmp_path / "reach.json"
    subprocess.run(
        [CLI, "reach", "--range-cm", "1", "--step-cm", "1", "--sampling", "variable", "--disturbance", "paper",
         "--disturbance-model", "drift", "--seed", "2", "--duration", "3", "--extra-delay", "0.005",
         "--json", str(out)],
        check=True,
        capture_output=True,
    )
    cli = json.loads(out.read_text())
    m = cm.reach(range_cm=1.0, step_cm=1.0, sampling="variable", disturbance="paper",
                 disturbance_model="drift", seed=2, duration_s=3.0, extra_delay_s=0.005)
    assert m.summary == cli["summary"] and m.summary["targets"] == 8
    theirs = [math.nan if p["settle_time_s"] is None else p["settle_time_s"] for p in cli["points"]]
    assert np.array_equal(m.settle_time_s, np.asarray(theirs), equal_nan=True)
    # The drift and the delay change the runs.
    plain = cm.reach(range_cm=1.0, step_cm=1.0, sampling="variable", disturbance="paper", seed=2, duration_s=3.0)
    assert not np.array_equal(plain.settle_time_s, m.settle_time_s, equal_nan=True)
    with pytest.raises(ValueError, match="ideal sampling has no tracking phase"):
        cm.reach(range_cm=1.0, extra_delay_s=0.005)
    with pytest.raises(ValueError, match="disturbance"):
        cm.reach(range_cm=1.0, disturbance_model="sideways")


def test_shooting_is_a_choice_for_two_capsules():
    # On by default (the same run as asked on), faster than the refinement
    # alone, under ideal sampling and under the scanner cycle.
    default = cm.simulate([0.02, -0.01], sampling="ideal", duration_s=2.0)
    off = cm.simulate([0.02, -0.01], sampling="ideal", duration_s=2.0, shooting=False)
    on = cm.simulate([0.02, -0.01], sampling="ideal", duration_s=2.0, shooting=True)
    assert np.array_equal(default.u, on.u) and default.settle_time_s == on.settle_time_s
    assert on.settle_time_s is not None and on.settle_time_s <= 0.95 * off.settle_time_s
    scanner = cm.simulate([0.02, -0.01], sampling="constant", duration_s=2.0)
    scanner_on = cm.simulate([0.02, -0.01], sampling="constant", duration_s=2.0, shooting=True)
    scanner_off = cm.simulate([0.02, -0.01], sampling="constant", duration_s=2.0, shooting=False)
    assert np.array_equal(scanner.u, scanner_on.u)
    assert scanner.settle_time_s is not None and scanner.settle_time_s < scanner_off.settle_time_s
    m = cm.reach(range_cm=1.0, step_cm=1.0, shooting=True)
    assert m.summary["never_settled"] == 0 and np.nanmax(m.ratio) < 1.3


def _plant_step(x, u, b, g, h):
    """One RK4 step of the capsules (drag -b v|v|, gain g), for a Python plant."""
    def f(s):
        d = np.empty_like(s)
        d[0::2] = s[1::2]
        d[1::2] = -b * s[1::2] * np.abs(s[1::2]) + g * u
        return d
    k1 = f(x); k2 = f(x + 0.5 * h * k1); k3 = f(x + 0.5 * h * k2); k4 = f(x + h * k3)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


@pytest.mark.parametrize("target", [[0.02, 0.0, 0.03, 0.0], [0.02, 0.0, -0.01, 0.0]])
def test_python_closed_loop_matches_the_rust_simulator(target):
    cfg = cm.Config.default()
    c = cm.Controller(cfg, [0.0, 0.0])
    c.set_sampling("ideal")
    c.set_target(target)
    x = np.zeros(4)
    xs, t, settle = [], 0.0, None
    overhead = []
    for _ in range(150):
        t0 = time.perf_counter()
        c.feed_state(x)
        u, status = c.next_actuation(t)
        overhead.append(time.perf_counter() - t0)
        assert status in (cm.Status.OK, cm.Status.ABOVE_ITERATION_MAP)
        for k in range(20):  # 1 ms steps of the 20 ms sample, as the Rust plant
            x = _plant_step(x, u[0], cfg.b, cfg.g, 1e-3)
            xs.append((t + (k + 1) * 1e-3, x.copy()))
        t += cfg.sample_time_s
    # Strict settle on the 1 ms rows, as the Rust simulator's metrics.
    tgt = np.asarray(target)
    inside = [np.all(np.abs(s[0::2] - tgt[0::2]) <= 1e-3) and np.all(np.abs(s[1::2]) < 5e-3) for _, s in xs]
    for k in range(len(xs) - 1, -1, -1):
        if not inside[k]:
            settle = xs[k][0]
            break
    rust = cm.simulate(target, sampling="ideal", disturbance="none").settle_time_s
    assert settle is not None and abs(settle - rust) <= 0.005, (settle, rust)
    assert np.median(overhead) < 5e-3


def test_controller_errors_and_status_enum():
    with pytest.raises(ValueError, match="outside the workspace"):
        cm.Controller(positions=[0.0, 1.0e6])
    c = cm.Controller()
    with pytest.raises(ValueError, match="target has 3 entries"):
        c.set_target([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="feed_state outside ideal sampling"):
        c.feed_state([0.0, 0.0, 0.0, 0.0])
    u, status = c.next_actuation(0.0)
    assert status == cm.Status.NO_TARGET and status.name == "NO_TARGET"
    with pytest.raises(cm.ConfigError):
        toml = open(os.path.join(REPO, "configs", "paper.toml")).read().replace("sphere_radius_m = 0.0015", "sphere_radius_m = 0.0010")
        cm.Controller(cm.Config.from_str(toml))


def _play(design, b, g, noise_m, seed):
    """Plays the designed excitation on a Python plant; positions (T, M) with NaN off the tracking rows."""
    rng = np.random.default_rng(seed)
    t, u = np.asarray(design["t_s"]), np.asarray(design["gradient_t_per_m"])
    act = set(design["actuation_rows"])
    x = np.zeros(2 * len(b))
    pos = np.full((len(t), len(b)), np.nan)
    for k in range(len(t)):
        if k not in act:
            pos[k] = x[0::2] + rng.normal(0.0, noise_m, len(b))
        if k + 1 < len(t):
            n = int(np.ceil((t[k + 1] - t[k]) / 1e-3))
            for _ in range(n):
                x = _plant_step(x, u[k], b, g, (t[k + 1] - t[k]) / n)
    return t, u, pos


def test_calibrate_recovers_an_off_model_plant():
    cfg = cm.Config.default()
    d = cm.design_excitation(cfg, 10.0)
    b, g = cfg.b * np.array([1.2, 0.8]), cfg.g * np.array([0.9, 1.1])
    cal = cm.calibrate(_play(d, b, g, 2e-4, 1), cfg)
    assert np.all(np.abs(cal.gain / g - 1) < 0.02) and np.all(np.abs(cal.drag / b - 1) < 0.02)
    assert cal.warnings == [] and cal.residual_rms_m < 3e-4
    assert np.allclose(cal.fitted_config.g, cal.gain) and np.allclose(cal.fitted_config.b, cal.drag)
    # What to tell a controller built for cfg: factors over its values,
    # deviations that cover the plant's true factors.
    truth = np.stack([g / cfg.g, b / cfg.b], axis=1)
    told = np.array([c["told_factors"] for c in cal.capsules])
    std = np.array([c["told_std"] for c in cal.capsules])
    assert np.all(std >= 0.01) and np.all(np.abs(told - truth) <= std)
    c = cm.Controller(cfg)
    for i in range(2):
        c.set_model_factors(i, told[i, 0], told[i, 1], gain_std=std[i, 0], drag_std=std[i, 1])


def test_calibrate_refuses_a_malformed_log(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text("t_s,gradient_t_per_m,x1_m,x2_m\n0,0,0,0\n0.02,abc,,\n")
    with pytest.raises(ValueError, match="line 3, column 2"):
        cm.calibrate(p)


def test_constant_sampling_reach_reports_the_coasted_schedule_bound():
    m = cm.reach(range_cm=1.0, step_cm=1.0, sampling="constant")
    on_grid = ~np.isnan(m.schedule_min_time_s)
    assert on_grid.sum() == 8
    assert np.all(m.schedule_min_time_s[on_grid] > m.min_time_bound_s[on_grid])
    assert m.summary["median_settle_over_schedule_bound"] < m.summary["median_settle_over_bound"]


def test_calibrated_factors():
    """A calibrated capsule: the controller told its factors at the start
    (simulate) or by the host (Controller); bad values named."""
    run = cm.simulate([0.02, -0.01], sampling="variable", seed=1, duration_s=4.0,
                      plant_drag_scale=1.2, calibrated_drag_scale=1.2)
    assert run.settle_time_s is not None
    assert json.loads(run.to_json())["calibrated"]["drag_scale"] == [1.2, 1.2]
    c = cm.Controller()
    c.set_model_factors(1, 0.9, 1.2, gain_std=0.01, drag_std=0.02)
    with pytest.raises(ValueError, match="factors"):
        c.set_model_factors(0, 1.0, 9.0)
    with pytest.raises(ValueError, match="capsule"):
        c.set_model_factors(5, 1.0, 1.0)
    with pytest.raises(ValueError, match="std_devs"):
        c.set_model_factors(0, 1.0, 1.0, drag_std=float("nan"))


def test_disturbance_bound():
    """The disturbance the estimator assumes: the config's by default,
    settable before the loop; bad values named."""
    c = cm.Controller()
    c.set_disturbance_bound(0.0)
    c.set_disturbance_bound(5e-4)
    with pytest.raises(ValueError, match="disturbance_bound"):
        c.set_disturbance_bound(-1e-6)
    with pytest.raises(ValueError, match="not finite"):
        c.set_disturbance_bound(float("nan"))


def test_calibrated_std_and_reach_on_a_plant_off_the_model():
    """The told factors' deviation is an argument of simulate and reach;
    reach runs on a plant off the model, told or not; bad values named."""
    run = cm.simulate([0.0, 0.01], sampling="variable", seed=6, duration_s=3.0,
                      calibrated_gain_scale=1.0, calibrated_std=0.01)
    assert json.loads(run.to_json())["calibrated"]["std"] == 0.01
    # The (0, 1) cm differential move of seed 6: 2.07 s with the speeds as
    # uncertain as the model's prior; a 1 % calibration arrives at rest.
    assert run.settle_time_s < 0.5
    plain = cm.reach(range_cm=1.0, step_cm=1.0, sampling="variable", disturbance="paper",
                     plant_drag_scale=1.2)
    told = cm.reach(range_cm=1.0, step_cm=1.0, sampling="variable", disturbance="paper",
                    plant_drag_scale=1.2, calibrated_drag_scale=1.2)
    assert plain.summary["targets"] == told.summary["targets"] == 8
    assert not np.array_equal(plain.settle_time_s, told.settle_time_s, equal_nan=True)
    with pytest.raises(ValueError, match="calibrated std"):
        cm.simulate([0.02, -0.01], calibrated_drag_scale=1.0, calibrated_std=2.0)
    with pytest.raises(ValueError, match="needs the factors"):
        cm.reach(range_cm=1.0, calibrated_std=0.01)
