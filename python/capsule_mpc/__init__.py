"""capsule-mpc from Python: closed-loop control of several magnetic capsules
driven by one MRI gradient.

Thin over the same Rust code the ``capsule-mpc`` command line runs:
``simulate`` gives the run ``capsule-mpc simulate --json`` gives (the same
settle time, final error and gradient, bit for bit), ``reach`` the reach
map, ``Controller`` the runtime's closed loop in the C ABI's call order.
Everything is SI (m, m/s, s, T/m); arrays come back as numpy arrays.
"""

import enum
import json
from typing import Dict, List, Optional, Sequence

import numpy as np

from . import _native

__all__ = [
    "Calibration",
    "Config",
    "ConfigError",
    "Controller",
    "ReachMap",
    "Run",
    "Status",
    "calibrate",
    "design_excitation",
    "reach",
    "simulate",
]

ConfigError = _native.ConfigError


class Config:
    """A capsule/scanner config: the embedded default (Table I of the
    paper), the three-capsule preset, or a TOML file or string (the format
    of ``configs/paper.toml``). Read-only; ``to_dict()`` gives all of it."""

    def __init__(self, native):
        self._native = native

    @staticmethod
    def default() -> "Config":
        """The embedded default config (two capsules)."""
        return Config(_native.Config.default())

    @staticmethod
    def three_capsules() -> "Config":
        """The shipped three-capsule preset (``configs/three-capsules.toml``)."""
        return Config(_native.Config.three_capsules())

    @staticmethod
    def from_toml(path) -> "Config":
        """Reads a TOML config file. ``FileNotFoundError`` when it is missing,
        ``ConfigError`` (a ``ValueError``) naming the field when it is bad."""
        return Config(_native.Config.from_toml(str(path)))

    @staticmethod
    def from_str(text: str) -> "Config":
        """Reads a config from TOML text (``ConfigError`` names a bad field)."""
        return Config(_native.Config.from_str(text))

    @property
    def capsule_count(self) -> int:
        """Number of capsules M."""
        return self._native.capsule_count

    @property
    def names(self) -> List[str]:
        """Capsule names."""
        return self._native.names

    @property
    def g(self) -> np.ndarray:
        """Magnetic acceleration per gradient of each capsule, m/s^2 per T/m."""
        return np.asarray(self._native.g)

    @property
    def b(self) -> np.ndarray:
        """Quadratic drag coefficient of each capsule, 1/m (effective at 0.1 m/s)."""
        return np.asarray(self._native.b)

    @property
    def sample_time_s(self) -> float:
        """Controller sample time, s."""
        return self._native.sample_time_s

    @property
    def tracking_time_s(self) -> float:
        """Tracking phase length, s."""
        return self._native.tracking_time_s

    @property
    def u_max_t_per_m(self) -> float:
        """Gradient bound, T/m."""
        return self._native.u_max_t_per_m

    @property
    def workspace(self):
        """(lowest, highest) position of a target or start, m."""
        return self._native.workspace

    def to_dict(self) -> Dict:
        """The whole config as a dict (SI)."""
        return json.loads(self._native.to_json())

    def __repr__(self) -> str:
        return f"Config(capsules={self.names}, g={list(self.g)}, b={list(self.b)})"


def _config(config: Optional[Config]) -> Config:
    if config is None:
        return Config.default()
    if not isinstance(config, Config):
        raise TypeError(f"config must be a capsule_mpc.Config, not {type(config).__name__}")
    return config


def _target_state(target, m: int) -> List[float]:
    t = [float(v) for v in np.asarray(target, dtype=float).ravel()]
    if len(t) == m:
        return [v for p in t for v in (p, 0.0)]
    if len(t) == 2 * m:
        return t
    raise ValueError(f"target has {len(t)} entries; give {m} positions (m) or the full state of {2 * m}")


def _count(name: str, value) -> int:
    """A whole number >= 1, or a ValueError naming ``name``."""
    if isinstance(value, bool) or int(value) != value or value < 1:
        raise ValueError(f"{name} {value!r} must be a whole number >= 1")
    return int(value)


class Run:
    """One closed-loop run: ``t`` (T,), ``x`` (T, 2M) true states, ``u`` (T,)
    gradients (``u[k]`` holds from ``t[k]`` to ``t[k+1]``), ``phase`` (T,)
    strings ('track' or 'actuate'), ``measurements`` (list of dicts),
    ``metrics`` (the CLI's metrics, same keys and values), ``modes`` (the
    controller's mode timeline: dicts with ``t_s`` and ``mode``),
    ``estimated_factors`` (per capsule, the controller's estimate of its
    gain and drag factors against the model, with standard deviations),
    ``timing`` (under the scanner cycle: ``tracking_time_s``,
    ``extra_delay_s`` and ``lose_every`` as simulated), ``retarget`` (when
    the target changed: ``at_s`` and ``first_target``; ``target`` is the
    final one);
    ``to_json()`` is the CLI's
    JSON."""

    def __init__(self, text: str):
        self._json = text
        d = json.loads(text)
        self.t = np.asarray(d["t"], dtype=float)
        self.x = np.asarray(d["x"], dtype=float)
        self.u = np.asarray(d["u"], dtype=float)
        self.phase = np.asarray([str(p).lower() for p in d["phase"]])
        self.measurements = d["measurements"]
        self.metrics = d["metrics"]
        self.target = np.asarray(d["target"], dtype=float)
        self.frames = d.get("frames")
        self.timing = d.get("timing")
        self.plant = d.get("plant")
        self.modes = d.get("modes") or []
        self.estimated_factors = d.get("estimated_factors")
        self.retarget = d.get("retarget")

    @property
    def settle_time_s(self) -> Optional[float]:
        """Strict settle time (in the 1 mm / 5 mm/s band to the end), s; None if never."""
        return self.metrics["settle_time_s"]

    def to_json(self) -> str:
        """The run as ``capsule-mpc simulate --json`` writes it."""
        return self._json

    def __repr__(self) -> str:
        return f"Run(rows={len(self.t)}, settle_time_s={self.settle_time_s})"


def simulate(
    target: Sequence[float],
    *,
    start: Optional[Sequence[float]] = None,
    config: Optional[Config] = None,
    sampling: str = "variable",
    disturbance: str = "paper",
    disturbance_model: str = "random",
    seed: int = 1,
    duration_s: float = 3.0,
    refine: Optional[str] = None,
    plant_drag_scale=None,
    plant_gain_scale=None,
    shooting: Optional[bool] = None,
    calibrated_drag_scale=None,
    calibrated_gain_scale=None,
    calibrated_std: Optional[float] = None,
    extra_delay_s: Optional[float] = None,
    lose_every: Optional[int] = None,
    retarget: Optional[Sequence[float]] = None,
    retarget_at_s: Optional[float] = None,
) -> Run:
    """One closed-loop run in the plant simulator, from rest at ``start``
    (positions, m; the origin when None) to ``target`` (M positions in m,
    speeds 0, or the full state of 2M). ``sampling``: 'ideal', 'constant'
    or 'variable'; ``disturbance``: 'none', 'paper' or 'stress';
    ``disturbance_model``: 'random', 'drift' or 'constant'; ``refine``:
    None (the config's), 'none', 'once' or 'per-sample'; the plant's drag
    and gain as factors of the model's (one for all or one per capsule);
    ``shooting``: minimum-time shots on or off (None: the controller's
    default: on); ``calibrated_*_scale``: factors the controller is told at
    the start, as a calibration gives them (None: it starts from the model
    and learns them), with standard deviation ``calibrated_std`` (a
    fraction; None: 0.03). Odd timing under the scanner cycle:
    ``extra_delay_s`` after each tracking phase (s; None: the config's) and
    ``lose_every`` N-th tracking frame lost (None: none lost; 1 loses them
    all). ``retarget`` (as ``target``) replaces the target at
    ``retarget_at_s`` s, wherever the capsules are then; the metrics refer
    to it.
    Releases the GIL while it runs. ``ValueError`` names a bad argument."""
    cfg = _config(config)
    scale = lambda s: None if s is None else [float(v) for v in np.atleast_1d(s)]
    text = _native.simulate_json(
        cfg._native,
        _target_state(target, cfg.capsule_count),
        None if start is None else [float(v) for v in start],
        sampling,
        disturbance,
        disturbance_model,
        int(seed),
        float(duration_s),
        refine,
        scale(plant_drag_scale),
        scale(plant_gain_scale),
        None if shooting is None else bool(shooting),
        scale(calibrated_drag_scale),
        scale(calibrated_gain_scale),
        None if calibrated_std is None else float(calibrated_std),
        None if extra_delay_s is None else float(extra_delay_s),
        None if lose_every is None else _count("lose_every", lose_every),
        None if retarget is None else _target_state(retarget, cfg.capsule_count),
        None if retarget_at_s is None else float(retarget_at_s),
    )
    return Run(text)


class ReachMap:
    """Every target of a grid: ``targets_m`` (P, M), ``settle_time_s``,
    ``min_time_bound_s`` and ``ratio`` (P,) with NaN where refused or never
    settled, ``schedule_min_time_s`` and ``schedule_ratio`` against the
    played schedule's minimum time (constant sampling: the coasted plan),
    ``workspace_excursion_m`` (how far a capsule went outside the config's
    workspace on the way, 0 inside, NaN where refused), and for two capsules the same as grids (``grid_*``, first
    capsule's offset from ``start_m`` along axis 0, ``axis_m`` the offsets);
    ``summary`` is the CLI's."""

    def __init__(self, text: str, axis_cm: np.ndarray, start_m: np.ndarray):
        d = json.loads(text)
        pts = d["points"]
        self.summary = d["summary"]
        nan = float("nan")
        val = lambda p, k: nan if p.get(k) is None else float(p[k])
        self.targets_m = np.asarray([p["target_m"] for p in pts], dtype=float)
        self.refused = [p["refused"] for p in pts]
        self.settle_time_s = np.asarray([val(p, "settle_time_s") for p in pts])
        self.min_time_bound_s = np.asarray([val(p, "min_time_bound_s") for p in pts])
        self.ratio = np.asarray([val(p, "settle_over_bound") for p in pts])
        self.schedule_min_time_s = np.asarray([val(p, "schedule_min_time_s") for p in pts])
        self.schedule_ratio = np.asarray([val(p, "settle_over_schedule_bound") for p in pts])
        self.workspace_excursion_m = np.asarray([val(p, "workspace_excursion_m") for p in pts])
        self.start_m = start_m
        self.axis_m = axis_cm / 100.0
        if self.targets_m.shape[1:] == (2,):
            n = len(self.axis_m)
            grids = {k: np.full((n, n), nan) for k in ("settle", "bound", "ratio")}
            for p, s, b, r in zip(self.targets_m, self.settle_time_s, self.min_time_bound_s, self.ratio):
                i = int(np.argmin(np.abs(self.axis_m - (p[0] - start_m[0]))))
                j = int(np.argmin(np.abs(self.axis_m - (p[1] - start_m[1]))))
                grids["settle"][i, j], grids["bound"][i, j], grids["ratio"][i, j] = s, b, r
            self.grid_settle_time_s = grids["settle"]
            self.grid_min_time_bound_s = grids["bound"]
            self.grid_ratio = grids["ratio"]

    def summary_line(self) -> str:
        """The summary as the CLI prints it (the counts and the ratios)."""
        s = self.summary
        f = lambda v: "-" if v is None else f"{v:.2f}"
        return (
            f"{s['targets']} targets: {s['refused']} refused, {s['never_settled']} never settled; "
            f"settle / min-time bound median {f(s['median_settle_over_bound'])} worst {f(s['worst_settle_over_bound'])}; "
            f"settle time median {f(s['median_settle_time_s'])} s worst {f(s['worst_settle_time_s'])} s"
        )


def reach(
    *,
    config: Optional[Config] = None,
    range_cm: float = 4.0,
    step_cm: float = 1.0,
    sampling: str = "ideal",
    disturbance: str = "none",
    seed: int = 1,
    shooting: Optional[bool] = None,
    plant_drag_scale=None,
    plant_gain_scale=None,
    calibrated_drag_scale=None,
    calibrated_gain_scale=None,
    calibrated_std: Optional[float] = None,
    disturbance_model: str = "random",
    duration_s: Optional[float] = None,
    extra_delay_s: Optional[float] = None,
    start: Optional[Sequence[float]] = None,
) -> ReachMap:
    """The closed loop from rest at ``start`` (positions, m; the origin
    when None) to every target of the grid around it (``range_cm``
    half-width, ``step_cm`` spacing, per capsule) on both
    cores; releases the GIL and prints nothing. ``shooting``, the plant's
    factors, the told (calibrated) ones, ``disturbance_model`` and
    ``extra_delay_s`` as for ``simulate``; ``duration_s`` per run (None:
    the CLI's default for the grid and sampling)."""
    cfg = _config(config)
    scale = lambda s: None if s is None else [float(v) for v in np.atleast_1d(s)]
    text = _native.reach_json(
        cfg._native,
        float(range_cm),
        float(step_cm),
        sampling,
        disturbance,
        int(seed),
        None if shooting is None else bool(shooting),
        scale(plant_drag_scale),
        scale(plant_gain_scale),
        scale(calibrated_drag_scale),
        scale(calibrated_gain_scale),
        None if calibrated_std is None else float(calibrated_std),
        disturbance_model,
        None if duration_s is None else float(duration_s),
        None if extra_delay_s is None else float(extra_delay_s),
        None if start is None else [float(v) for v in start],
    )
    half = int(np.floor(range_cm / step_cm + 1e-9))
    start_m = np.zeros(cfg.capsule_count) if start is None else np.asarray(start, dtype=float)
    return ReachMap(text, np.arange(-half, half + 1) * float(step_cm), start_m)


class Calibration:
    """A fit of every capsule's gain (m/s^2 per T/m) and drag (1/m):
    ``capsules`` (list of dicts: name, gain, gain_stderr, gain_ci95, drag,
    drag_stderr, drag_ci95, gain_model, drag_model, x0_m, v0_m_per_s,
    measurements, residual_rms_m), ``residual_rms_m``, ``warnings``, and
    ``fitted_config`` (the base config with the fitted values, a
    ``Config``; ``fitted_config_toml`` its TOML for ``generate --config``)."""

    def __init__(self, text: str):
        d = json.loads(text)
        c = d["calibration"]
        self.capsules = c["capsules"]
        self.residual_rms_m = c["residual_rms_m"]
        self.drag_law = c["drag_law"]
        self.warnings = c["warnings"]
        self.gain = np.asarray([k["gain"] for k in self.capsules])
        self.drag = np.asarray([k["drag"] for k in self.capsules])
        self.fitted_config_toml = d["fitted_config_toml"]
        self.fitted_config = Config.from_str(self.fitted_config_toml)


def calibrate(log, config: Optional[Config] = None, min_measurements: int = 20) -> Calibration:
    """Fits each capsule's gain and drag to a tracking log: a path to a CSV
    (``t_s,gradient_t_per_m,x1_m,...``, docs/calibrate.md) or run JSON, or
    arrays ``(t_s, gradient_t_per_m, positions_m)`` with positions of shape
    (T, M) and NaN where not measured. ``ValueError`` names the line and
    column of a malformed log."""
    cfg = _config(config)
    if isinstance(log, (tuple, list)) and len(log) == 3:
        t, u, x = (np.asarray(a, dtype=float) for a in log)
        if x.ndim != 2 or x.shape[0] != t.shape[0] or u.shape != t.shape:
            raise ValueError("log arrays: t (T,), gradient (T,) and positions (T, M) must agree in T")
        lines = ["t_s,gradient_t_per_m," + ",".join(f"x{i + 1}_m" for i in range(x.shape[1]))]
        for k in range(len(t)):
            cells = ["" if np.isnan(v) else repr(float(v)) for v in x[k]]
            lines.append(",".join([repr(float(t[k])), repr(float(u[k]))] + cells))
        text = "\n".join(lines) + "\n"
    else:
        with open(log) as f:
            text = f.read()
    return Calibration(_native.calibrate_json(cfg._native, text, int(min_measurements)))


def design_excitation(config: Optional[Config] = None, duration_s: float = 10.0) -> Dict:
    """The excitation that identifies every capsule's gain and drag: a dict
    with ``csv`` (the log to play, positions empty), ``t_s``,
    ``gradient_t_per_m``, ``actuation_rows`` and the model's
    ``predicted_m`` (M, T) from rest."""
    cfg = _config(config)
    d = json.loads(_native.design_excitation_json(cfg._native, float(duration_s)))
    d["predicted_m"] = np.asarray(d["predicted_m"])
    return d


class Status(enum.IntEnum):
    """Status of one cycle (the C ABI's CAPSULE_MPC_STATUS_* values)."""

    OK = 0
    FALLBACK = 1
    ITERATION_LIMIT = 2
    MEASUREMENT_REJECTED = 3
    MEASUREMENT_LOST = 4
    NO_TARGET = 5
    REACQUIRED = 6
    ABOVE_ITERATION_MAP = 7
    RECOVERING = 8


class Controller:
    """The runtime's closed loop for a lab's own plant or hardware, in the C
    ABI's order: ``set_sampling`` (before the loop), ``set_target``, then per
    cycle ``feed_tracking`` (or ``feed_state`` under ideal sampling) and
    ``next_actuation``. Only the compiled-in controllers are available: the
    default two-capsule config's and the three-capsule preset's (another
    config raises ``ConfigError``: regenerate and rebuild). The step does
    not allocate inside the runtime."""

    def __init__(self, config: Optional[Config] = None, positions: Sequence[float] = (0.0, 0.0)):
        cfg = _config(config)
        self._native = _native.Controller(cfg._native, [float(p) for p in positions])

    def set_sampling(self, sampling: str) -> None:
        """'ideal', 'constant' or 'variable' (only before the loop runs)."""
        self._native.set_sampling(sampling)

    def set_disturbance_bound(self, bound_si: float) -> None:
        """The bound on the additive disturbance of the state derivative
        the estimator assumes, SI (m/s on the position rates, m/s^2 on the
        accelerations). Default: the config's ``[disturbance]`` bound, 5e-4
        for the default config (the paper's 0.05 in cm units), as in every
        ``simulate`` run under that disturbance; 0 when the capsules move
        exactly as modelled. Before the loop runs: it restarts the estimate
        at rest at the estimated positions. ``ValueError`` when negative,
        above 1e3 or not finite."""
        self._native.set_disturbance_bound(float(bound_si))

    def set_model_factors(
        self, capsule: int, gain: float, drag: float, gain_std: float = 0.03, drag_std: float = 0.03
    ) -> None:
        """What a calibration says of capsule ``capsule``'s (0-based) gain
        and drag against the model (factors, 1 = the model, and their
        standard deviations, 3 % by default as in ``simulate``: tell 1 %
        only for a capsule known within 2-3 %); kept across ``reset``.
        Before the loop runs (or after ``reset``) the gain's deviation also
        sets how sure the estimator is of the starting speeds.
        ``ValueError`` names a bad argument (factors in [0.25, 4],
        deviations in [0.001, 1])."""
        self._native.set_model_factors(int(capsule), float(gain), float(drag), float(gain_std), float(drag_std))

    def set_target(self, target: Sequence[float]) -> None:
        """Target state [x1, 0, x2, 0, ...] (m), inside the workspace."""
        self._native.set_target([float(v) for v in target])

    def feed_tracking(self, positions: Sequence[float], t_measured_s: float, lost: bool = False) -> None:
        """The frame measured at ``t_measured_s`` (scanner clock, s); ``lost``: no frame."""
        self._native.feed_tracking([float(v) for v in positions], float(t_measured_s), bool(lost))

    def feed_state(self, state: Sequence[float]) -> None:
        """The full state [x1, v1, ...] (ideal sampling)."""
        self._native.feed_state([float(v) for v in state])

    def next_actuation(self, t_actuation_start_s: float):
        """(gradients to play from ``t_actuation_start_s``, one per sample, T/m; ``Status``)."""
        u, status = self._native.next_actuation(float(t_actuation_start_s))
        return np.asarray(u, dtype=float), Status(status)

    def estimate(self) -> np.ndarray:
        """The estimated state [x1, v1, ...] at the end of the last actuation phase."""
        return np.asarray(self._native.estimate(), dtype=float)

    def reset(self, positions: Sequence[float]) -> None:
        """Restarts the estimate at rest at ``positions`` (keeps the target)."""
        self._native.reset([float(p) for p in positions])
