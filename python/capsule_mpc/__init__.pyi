import enum
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

class ConfigError(ValueError): ...

class Config:
    @staticmethod
    def default() -> Config: ...
    @staticmethod
    def three_capsules() -> Config: ...
    @staticmethod
    def from_toml(path: object) -> Config: ...
    @staticmethod
    def from_str(text: str) -> Config: ...
    @property
    def capsule_count(self) -> int: ...
    @property
    def names(self) -> List[str]: ...
    @property
    def g(self) -> np.ndarray: ...
    @property
    def b(self) -> np.ndarray: ...
    @property
    def sample_time_s(self) -> float: ...
    @property
    def tracking_time_s(self) -> float: ...
    @property
    def u_max_t_per_m(self) -> float: ...
    @property
    def workspace(self) -> Tuple[float, float]: ...
    def to_dict(self) -> Dict: ...

class Run:
    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    phase: np.ndarray
    measurements: List[Dict]
    metrics: Dict
    target: np.ndarray
    frames: Optional[Dict]
    timing: Optional[Dict]
    plant: Optional[Dict]
    modes: List[Dict]
    estimated_factors: Optional[List[Dict]]
    retarget: Optional[Dict]
    @property
    def settle_time_s(self) -> Optional[float]: ...
    def to_json(self) -> str: ...

def simulate(
    target: Sequence[float],
    *,
    start: Optional[Sequence[float]] = ...,
    config: Optional[Config] = ...,
    sampling: str = ...,
    disturbance: str = ...,
    disturbance_model: str = ...,
    seed: int = ...,
    duration_s: float = ...,
    refine: Optional[str] = ...,
    plant_drag_scale: Optional[object] = ...,
    plant_gain_scale: Optional[object] = ...,
    shooting: Optional[bool] = ...,
    calibrated_drag_scale: Optional[object] = ...,
    calibrated_gain_scale: Optional[object] = ...,
    calibrated_std: Optional[float] = ...,
    extra_delay_s: Optional[float] = ...,
    lose_every: Optional[int] = ...,
    retarget: Optional[Sequence[float]] = ...,
    retarget_at_s: Optional[float] = ...,
) -> Run: ...

class ReachMap:
    targets_m: np.ndarray
    refused: List[Optional[str]]
    settle_time_s: np.ndarray
    min_time_bound_s: np.ndarray
    ratio: np.ndarray
    schedule_min_time_s: np.ndarray
    schedule_ratio: np.ndarray
    workspace_excursion_m: np.ndarray
    start_m: np.ndarray
    axis_m: np.ndarray
    grid_settle_time_s: np.ndarray
    grid_min_time_bound_s: np.ndarray
    grid_ratio: np.ndarray
    summary: Dict
    def summary_line(self) -> str: ...

def reach(
    *,
    config: Optional[Config] = ...,
    range_cm: float = ...,
    step_cm: float = ...,
    sampling: str = ...,
    disturbance: str = ...,
    seed: int = ...,
    shooting: Optional[bool] = ...,
    plant_drag_scale: Optional[object] = ...,
    plant_gain_scale: Optional[object] = ...,
    calibrated_drag_scale: Optional[object] = ...,
    calibrated_gain_scale: Optional[object] = ...,
    calibrated_std: Optional[float] = ...,
    disturbance_model: str = ...,
    duration_s: Optional[float] = ...,
    extra_delay_s: Optional[float] = ...,
    start: Optional[Sequence[float]] = ...,
) -> ReachMap: ...

class Calibration:
    capsules: List[Dict]
    residual_rms_m: float
    drag_law: str
    warnings: List[str]
    gain: np.ndarray
    drag: np.ndarray
    fitted_config_toml: str
    fitted_config: Config

def calibrate(log: object, config: Optional[Config] = ..., min_measurements: int = ...) -> Calibration: ...
def design_excitation(config: Optional[Config] = ..., duration_s: float = ...) -> Dict: ...

class Status(enum.IntEnum):
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
    def __init__(self, config: Optional[Config] = ..., positions: Sequence[float] = ...) -> None: ...
    def set_sampling(self, sampling: str) -> None: ...
    def set_disturbance_bound(self, bound_si: float) -> None: ...
    def set_model_factors(
        self, capsule: int, gain: float, drag: float, gain_std: float = ..., drag_std: float = ...
    ) -> None: ...
    def set_target(self, target: Sequence[float]) -> None: ...
    def feed_tracking(self, positions: Sequence[float], t_measured_s: float, lost: bool = ...) -> None: ...
    def feed_state(self, state: Sequence[float]) -> None: ...
    def next_actuation(self, t_actuation_start_s: float) -> Tuple[np.ndarray, Status]: ...
    def estimate(self) -> np.ndarray: ...
    def reset(self, positions: Sequence[float]) -> None: ...
