"""Type stubs of the Rust extension ``swingrt._core`` (checked by ``stubtest`` in CI)."""

from typing import Any

import numpy as np
import numpy.typing as npt

__version__: str
GRAVITY: float
TRACE_COLUMNS: tuple[str, ...]
STATE_KEYS: tuple[str, ...]

# --- simulation -----------------------------------------------------------------------

def scenario_from_toml(text: str) -> str: ...
def scenario_from_json(text: str) -> str: ...
def scenario_to_toml(json: str) -> str: ...
def default_scenario(kind: str) -> str: ...
def run_scenario(json: str) -> dict[str, npt.NDArray[np.float64]]: ...
def sim_real_time_factor(json: str, seconds: float) -> float: ...

class Simulator:
    def __init__(self, json: str) -> None: ...
    @property
    def t(self) -> float: ...
    @property
    def duration(self) -> float: ...
    @property
    def steps_left(self) -> int: ...
    @property
    def fallback_reason(self) -> str | None: ...
    @property
    def constrained_ticks(self) -> int: ...
    def advance(self, dt: float) -> None: ...
    def run_to_end(self) -> None: ...
    def set_setpoint(self, axis: int, mode: str, value: float) -> None: ...
    def state(self) -> dict[str, float]: ...
    def trace(self) -> dict[str, npt.NDArray[np.float64]]: ...
    def take_trace(self) -> dict[str, npt.NDArray[np.float64]]: ...
    def tick_times(self) -> npt.NDArray[np.float64]: ...
    def attach_mpc(
        self, model_json: str, settings_json: str | None, engage_at: float, budget: float
    ) -> None: ...
    def attach_lqr(
        self,
        m_q: float,
        m_p: float,
        l: float,
        c: float,
        axes: int,
        settings_json: str | None,
        engage_at: float,
        budget: float,
    ) -> None: ...
    def controller_prediction(self) -> npt.NDArray[np.float64] | None: ...

# --- system identification ---------------------------------------------------------------

def sysid_fit(
    x: npt.NDArray[np.float64],
    u: npt.NDArray[np.float64],
    states: list[str],
    inputs: list[str],
    *,
    delays: int,
    rank: int | None = None,
    offset: str = "affine",
    dt: float = 0.03,
    method: str = "dmdc",
) -> str: ...
def sysid_search(
    x_train: npt.NDArray[np.float64],
    u_train: npt.NDArray[np.float64],
    x_test: npt.NDArray[np.float64],
    u_test: npt.NDArray[np.float64],
    states: list[str],
    inputs: list[str],
    *,
    method: str = "dmdc",
    offset: str = "affine",
    dt: float = 0.03,
    horizon: int = 667,
    starts: int = 10,
    delays: list[int] | None = None,
    rank_start: int = 5,
    rank_step: int = 5,
    rank_extra: int = 0,
    fine: tuple[int, int] | None = None,
    stability_tolerance: float = 1e-3,
) -> tuple[str, list[Any], int]: ...
def sysid_evaluate(
    model_json: str,
    x: npt.NDArray[np.float64],
    u: npt.NDArray[np.float64],
    *,
    horizon: int,
    starts: int = 10,
) -> tuple[list[float], float]: ...
def sysid_predict(
    model_json: str, history: npt.NDArray[np.float64], inputs: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]: ...
def sysid_check_model(model_json: str) -> tuple[str, float]: ...
def sysid_whitebox(
    states: list[str],
    inputs: list[str],
    *,
    payload_mass: float,
    length: float,
    vehicle_mass: float = 0.952,
    friction: float = 0.0,
    gravity: float = 9.80665,
    dt: float = 0.03,
    frequency_hz: float | None = None,
    x: npt.NDArray[np.float64] | None = None,
    u: npt.NDArray[np.float64] | None = None,
    offset: str = "none",
) -> str: ...
def sysid_fft_peak(
    signal: npt.NDArray[np.float64], dt: float, f_min: float, f_max: float
) -> float: ...
def sysid_cable_length(
    freq_hz: float, vehicle_mass: float, payload_mass: float, gravity: float = 9.80665
) -> float: ...
def sysid_rls_mass(
    thrust_vertical: npt.NDArray[np.float64],
    acc_down: npt.NDArray[np.float64],
    *,
    gravity: float = 9.80665,
    forgetting: float = 1.0,
    initial: float = 1.0,
) -> npt.NDArray[np.float64]: ...
def sysid_smooth_quadratic(
    signal: npt.NDArray[np.float64], window: int
) -> npt.NDArray[np.float64]: ...
def sysid_smooth_gaussian(
    signal: npt.NDArray[np.float64], window: int
) -> npt.NDArray[np.float64]: ...

# --- control --------------------------------------------------------------------------

class Mpc:
    def __init__(self, model_json: str, settings: dict[str, Any] | None = None) -> None: ...
    @property
    def period(self) -> float: ...
    @property
    def axes(self) -> int: ...
    def step(self, state: npt.NDArray[np.float64], vel_ref: Any) -> npt.NDArray[np.float64]: ...
    def reset(self, state: npt.NDArray[np.float64], acc: Any = None) -> None: ...
    def predicted(self) -> npt.NDArray[np.float64]: ...
    def predicted_inputs(self) -> npt.NDArray[np.float64]: ...
    def disturbance(self) -> npt.NDArray[np.float64]: ...
    def last_tick(self) -> dict[str, Any]: ...
    def settings(self) -> dict[str, Any]: ...

class Lqr:
    def __init__(
        self,
        m_q: float,
        m_p: float,
        l: float,
        c: float = 0.0,
        axes: int = 1,
        settings: dict[str, Any] | None = None,
    ) -> None: ...
    @property
    def period(self) -> float: ...
    @property
    def axes(self) -> int: ...
    def step(self, state: npt.NDArray[np.float64], vel_ref: Any) -> npt.NDArray[np.float64]: ...
    def reset(self, state: npt.NDArray[np.float64], acc: Any = None) -> None: ...
    def gain(self) -> npt.NDArray[np.float64]: ...

def mpc_step_check(
    model_json: str,
    plant_jsons: list[str],
    settings: dict[str, Any] | None = None,
    step: float = 2.0,
    t_step: float = 2.0,
    duration: float = 20.0,
    input_lags: list[float] = ...,
) -> list[dict[str, float]]: ...
def care(
    A: npt.NDArray[np.float64],
    B: npt.NDArray[np.float64],
    Q: npt.NDArray[np.float64],
    R: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
def dare(
    A: npt.NDArray[np.float64],
    B: npt.NDArray[np.float64],
    Q: npt.NDArray[np.float64],
    R: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
def mpc_tick_timing(
    model_json: str,
    settings: dict[str, Any] | None = None,
    n_ticks: int = 2000,
    constrained: bool = False,
) -> dict[str, float]: ...
def pendulum_model_json(
    m_q: float = 0.952,
    m_p: float = 0.2,
    l: float = 1.0,
    c: float = 0.002,
    dt: float = 0.03,
    delays: int = 50,
    axes: int = 1,
    seed: int = 7,
) -> str: ...
