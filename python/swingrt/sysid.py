"""System identification from flight data (thesis chapter 4).

``identify`` turns a flight (a :class:`swingrt.Trace`, or any mapping of numpy columns
named as in :data:`swingrt.io.TRACE_COLUMNS`) into a :class:`LinearModel` over delay
coordinates, z_{k+1} = A z_k + B (u_k - input_mean) + c with
z_k = [x_k; x_{k-1}; ...; x_{k-q+1}] (newest first):

* ``dmdc``    DMDc with delay coordinates (eq. 4.9-4.15), rank-p truncated SVD;
* ``havokc``  HAVOKc (eq. 4.16-4.23) with the structural 0/1 entries forced (figure 4.4);
* ``whitebox`` the linearised pendulum (eq. 5.7, stable sign) with the cable length of the
  single pendulum that answers the vehicle's motion as the swing does (the FFT peak of
  eq. 4.8 when that fit fails; both in ``diagnostics['whitebox']``; on the IMU's swing,
  the length its scale fit measured, ``diagnostics['whitebox_length']``) and the payload
  mass from RLS on hover thrust (section 4.3.2).

Every rule of identification lives in the Rust core: the settings with their defaults and
checks (``_core.identify_settings``: the keyword arguments below are its fields), the
held-out split, fit, search, scoring, white-box and the control-relevant selection. This
module reads columns, resamples them onto the ``dt`` grid, smooths them when asked, and
calls the core. Figures are in :mod:`swingrt.reports.plots`.

A flight with no swing sensor (its ``swing_*`` columns absent or all NaN) that logs the
swing estimated from the IMU (``swing_est_*``, see ``swing_core::sensors::swing``) is
identified on that estimate without being told (:func:`swing_source`); the model records
where its swing came from in ``diagnostics['swing_source']``.
"""

from __future__ import annotations

import hashlib
import json
import math
import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from swingrt import _core
from swingrt.errors import ConfigError, DataError, IdentificationError, ModelError
from swingrt.io.flight import Trace
from swingrt.io.ulog import euler_to_quat
from swingrt.scenario import scaled_inertia

__all__ = [
    "AXES",
    "PLAN_KEYS",
    "TWINS",
    "DEFAULT_CHECK_PAYLOAD_MASS",
    "LinearModel",
    "SearchResult",
    "estimate_payload_mass",
    "evaluate",
    "identify",
    "identify_settings",
    "imu_swing_scale",
    "flown_estimator",
    "swing_drag",
    "with_swing_drag",
    "flies_measured_scale",
    "body_sensor",
    "model_body_sensor",
    "with_thrust",
    "model_estimator",
    "model_twin",
    "resample",
    "search",
    "builtin_twin",
    "PX4_GAINS",
    "check_plant",
    "select_for_control",
    "sweep_noise",
    "sweep_sample_time",
    "sweep_training_length",
    "swing_period",
    "swing_source",
    "to_statespace",
]

#: Keys of an experiment's ``[identify]`` that say how the identification is run, not core
#: identification settings: ``search`` (bool: search q and p) and ``twin`` (one of
#: :data:`TWINS`).
PLAN_KEYS = ("search", "twin")

#: What flies as the vehicle's twin in a study's control-relevant selection: ``"exact"`` the
#: training flight's own vehicle (its airframe and PX4 gains), ``"builtin"`` the built-in
#: vehicle weighed at the flight's vehicle mass and flown under its PX4 gains (what a log
#: gives; its airframe is not the plant's), ``"off"`` no twin.
TWINS = ("exact", "builtin", "off")

#: The key of a trace's ``meta`` naming the drag its IMU swing estimate is read with
#: (:func:`with_swing_drag`).
SWING_DRAG_META = "swing_drag"

#: State and input columns per axis choice.
AXES: dict[str, tuple[list[str], list[str]]] = {
    "n": (["vn", "swing_n"], ["acc_sp_n"]),
    "ne": (["vn", "ve", "swing_n", "swing_e"], ["acc_sp_n", "acc_sp_e"]),
}

#: Payload mass [kg] the closed-loop check's white-box plant assumes when neither
#: ``payload_mass`` is given nor the log has a usable ``thrust`` column: the thesis's payload
#: (table 6.1) and the simulator's default.
DEFAULT_CHECK_PAYLOAD_MASS = 0.2

#: A discrete linear model over delay coordinates (``swingrt-model/1``), a core object:
#: ``A``, ``B``, ``c`` (read-only numpy), ``dt``, ``delays``, ``rank``, ``states``,
#: ``inputs``, ``offset``, ``input_mean``, ``method``, ``diagnostics``, ``predict()``,
#: ``to_json()``/``from_json()``, ``save()``/``load()``.
LinearModel = _core.LinearModel


def identify_settings(**settings: Any) -> dict[str, Any]:
    """The identification settings with every default filled in, checked by the core
    (``ConfigError`` naming the field). ``None`` values mean "the default"."""
    # None is "the default" except for ``fine``, where it means "no fine stage".
    given = {k: v for k, v in settings.items() if v is not None or k == "fine"}
    if isinstance(given.get("fine"), tuple):
        given["fine"] = list(given["fine"])
    if isinstance(given.get("swing_band"), tuple):
        given["swing_band"] = list(given["swing_band"])
    return _core.check_settings("identify", given)


@dataclass
class SearchResult:
    """A search's selected model, every scored candidate, and what selection needs."""

    model: LinearModel
    table: list[dict[str, Any]] = field(default_factory=list)
    search: Any = None
    settings: dict[str, Any] = field(default_factory=dict)

    def best_per_delay(self) -> list[dict[str, Any]]:
        """Lowest stable NMAE per q (the error-vs-q curve of figure 4.6)."""
        best: dict[int, dict[str, Any]] = {}
        for row in self.table:
            if row["stable"] is not True:
                continue
            q = row["delays"]
            if q not in best or row["nmae"] < best[q]["nmae"]:
                best[q] = row
        return [best[q] for q in sorted(best)]


# --------------------------------------------------------------------------- data


def _columns(data: Any) -> Mapping[str, Any]:
    if hasattr(data, "columns") and isinstance(data.columns, Mapping):
        return data.columns
    if isinstance(data, Mapping):
        return data
    raise DataError("data must be a dict of numpy columns or an object with a .columns dict")


def resample(
    columns: Mapping[str, Any], dt: float, names: Sequence[str] | None = None
) -> dict[str, np.ndarray]:
    """Linearly interpolate every column (or ``names``) onto t0, t0+dt, ... <= t_end.

    Requires a strictly increasing, finite ``t`` column [s]. A non-finite value in a
    column raises ``DataError`` naming the column and the time.
    """
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise ConfigError(f"dt: must be a positive number of seconds, not {dt!r}", field="dt")
    if "t" not in columns:
        raise DataError("data has no time column 't'")
    t = np.asarray(columns["t"], dtype=float)
    if t.ndim != 1 or len(t) < 2:
        raise DataError("column 't' must be one-dimensional with at least two samples")
    if not np.all(np.isfinite(t)):
        raise DataError(f"column 't' is not finite at index {int(np.argmin(np.isfinite(t)))}")
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0))
        raise DataError(f"column 't' is not strictly increasing at t = {t[k]:.3f} s")
    wanted = list(names) if names is not None else [k for k in columns if k != "t"]
    missing = [k for k in wanted if k not in columns]
    if missing:
        raise DataError(f"data lacks column(s) {', '.join(missing)}")
    count = int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1
    grid = t[0] + dt * np.arange(count)
    out: dict[str, np.ndarray] = {"t": grid}
    for name in wanted:
        v = np.asarray(columns[name])
        if v.dtype.kind not in "fiub" or v.shape != t.shape:
            if v.shape != t.shape:
                raise DataError(f"column {name!r} has {v.shape} samples, 't' has {t.shape}")
            continue  # non-numeric columns are not resampled
        v = v.astype(float)
        bad = ~np.isfinite(v)
        if bad.any():
            k = int(np.argmax(bad))
            raise DataError(f"column {name!r} is not finite (NaN gap?) at t = {t[k]:.3f} s")
        out[name] = np.interp(grid, t, v)
    return out


def swing_source(data: Any) -> str:
    """Where a flight's swing comes from: ``imu`` when it has no swing column with a value
    (absent or all NaN) but a finite IMU estimate ``swing_est_n`` for every sample, else the
    flight's ``swing_source`` (a ULog read from ``adc_report``) or its scenario's
    ``sensors.swing`` (``sensor`` or ``body``; ``sensor`` when the flight does not say)."""
    cols = _columns(data)
    sw = cols.get("swing_n")
    if sw is None or not np.isfinite(np.asarray(sw, dtype=float)).any():
        est = cols.get("swing_est_n")
        if est is not None and len(est) and np.isfinite(np.asarray(est, dtype=float)).all():
            return "imu"
    meta = getattr(data, "meta", None) or {}
    sensors = (meta.get("scenario") or {}).get("sensors") or {}
    # A ULog read from its cable sensor's ADC says so itself (swingrt.io.ulog).
    src = meta.get("swing_source") or sensors.get("swing", "sensor")
    return src if src in ("sensor", "body") else "sensor"


def _swing_columns(data: Any) -> tuple[Mapping[str, Any], str]:
    """The flight's columns with the swing the identification reads, and its source: for
    ``imu`` (no swing column, see :func:`swing_source`) the IMU estimate made by
    :func:`flown_estimator`."""
    cols = _columns(data)
    src = swing_source(data)
    if src != "imu":
        return cols, src
    out = dict(cols)
    swing = _flown(data)[1]
    out["swing_n"], out["swing_e"] = swing[:, 0], swing[:, 1]
    return out, src


def flown_estimator(data: Any) -> dict[str, Any] | None:
    """The IMU swing estimator a model identified on ``data`` flies: the flight's own, with
    the scale measured from it (:func:`imu_swing_scale`) where that is the smaller one, and
    then with the pendulum observer on the fitted cable (``length``, ``damping``:
    ``swing_core::sensors::pendulum``), which tells the swing from the drag a light
    payload's small pull lets dominate the estimate. At either scale, where the fit stands,
    it loses the airframe's quadratic drag the fit measured (``drag_quadratic``;
    ``swing_core::sysid::swing_scale::DragRemoval``): a linear model cannot hold the drag's
    curvature, and the vehicle then creeps to its speed with the payload leaning.

    The MPC's swing weight was set for the cable's angle, and at a scale k̂ the estimate
    reads (k/k̂) of the angle plus (1 − k/k̂) of the vehicle's tilt. Where the payload is
    lighter than the estimator assumed (k < k̂), the swing is read too small, the tilt leaks
    in (three quarters of it at a quarter of the assumed mass), and an MPC on that output
    damps the tilt more than the swing: the measured scale reads the angle. Where it is
    heavier (k > k̂), the swing is read larger than it is, which weighs it more, and the
    estimator's own scale is kept: flying the measured one there failed more in the
    sensorless robustness study (README, "Nothing on the cable"). None when the flight keeps
    its own estimator and does not say which (:func:`swing_estimator`)."""
    est = _flown(data)[0]
    return None if est is None else dict(est)


def flies_measured_scale(scale: Mapping[str, Any]) -> bool:
    """Whether a model flies the IMU estimate's measured scale, from what
    :func:`imu_swing_scale` reported (``diagnostics``): where it is smaller than the assumed
    one (:func:`flown_estimator`)."""
    return scale.get("fit") is not None and scale["scale"] < scale["assumed_scale"]


def _flown(data: Any) -> tuple[dict[str, Any] | None, np.ndarray]:
    """:func:`flown_estimator`'s settings and the flight's estimate as they make it (N×2)."""
    found = imu_swing_scale(data)
    if flies_measured_scale(found["diagnostics"]):
        return found["estimator"], found["swing"]
    if found["diagnostics"]["fit"] is not None:
        own = found["own_scale"]
        return own["estimator"], own["swing"]
    cols = _columns(data)
    nan = np.full(len(cols["t"]), np.nan)
    raw = [np.asarray(cols.get(f"swing_est_{a}", nan), dtype=float) for a in "ne"]
    return swing_estimator(data), np.column_stack(raw)


#: What :func:`imu_swing_scale` found lately, by the digest of what it read: the selection
#: asks again for the same flight through copies of it (the twin's, the candidates'), and
#: each fit takes seconds.
_SCALES: OrderedDict[bytes, dict[str, Any]] = OrderedDict()

#: How many fits :data:`_SCALES` keeps (each holds two N×2 estimates).
_SCALES_KEPT = 8

#: Guards :data:`_SCALES` where a scheduler's worker runs tasks on several threads.
_SCALES_LOCK = threading.Lock()


def _scale_key(cols: Mapping[str, Any], given: Mapping[str, Any], drag: str | None) -> bytes:
    """A digest of everything :func:`imu_swing_scale` reads from a flight: its columns
    (those the remake reads too), the estimator's settings and the drag it removes."""
    h = hashlib.blake2b(digest_size=20)
    h.update(json.dumps([given, drag], sort_keys=True, default=repr).encode())
    for c in ("t", "swing_est_n", "swing_est_e", *IMU_COLUMNS):
        if c in cols:
            h.update(c.encode())
            h.update(np.ascontiguousarray(cols[c], dtype=float).tobytes())
    return h.digest()


def imu_swing_scale(data: Any) -> dict[str, Any]:
    """The scale of a flight's IMU swing estimate, fitted to how that swing answers the
    vehicle's motion (``swing_core::sysid::swing_scale``): the estimator assumes the
    payload-to-vehicle mass ratio, the fit measures it, with the cable's length and the
    airframe's drag the estimate reads as swing. Returns ``estimator`` (the calibrated
    settings, with the fitted pendulum for its observer, or the flight's own when the fit is
    refused), ``swing`` (N×2, the flight's estimate as the calibrated estimator would have
    made it, on the flight's own times: the swing angle, the drag told apart by the
    observer and its quadratic term removed), ``own_scale`` (``estimator`` and ``swing``
    at the flight's own scale, without the observer, the fitted quadratic drag removed;
    the flight's own when refused) and ``diagnostics`` (``assumed_scale``, ``scale``, the
    ``fit`` or None and the ``reason`` it was refused: the fit needs the flight's ``vn``,
    ``ve``, ``roll``, ``pitch`` and ``yaw`` beside ``swing_est_*``)."""
    cols = _columns(data)
    names = ["vn", "ve", "swing_est_n", "swing_est_e", "roll", "pitch", "yaw"]
    given = swing_estimator(data) or {}
    drag = swing_drag(data)
    key = _scale_key(cols, given, drag)
    with _SCALES_LOCK:
        if key in _SCALES:
            _SCALES.move_to_end(key)
            return _SCALES[key]
    settings = dict(_core.ImuSwingEstimator(given or None).settings)
    missing = [c for c in names if c not in cols]
    reason = f"the flight has no column(s) {', '.join(missing)}" if missing else None
    if reason is None:
        # A gap in a column the measurement alone reads (the attitude) refuses the
        # measurement, and the assumed scale is flown, rather than the identification.
        gaps = [c for c in names if not np.isfinite(np.asarray(cols[c], dtype=float)).all()]
        if gaps:
            reason = f"column(s) {', '.join(gaps)} are not finite throughout the flight"
    if reason is not None:
        found: dict[str, Any] = {"estimator": settings, "fit": None, "reason": reason}
        nan = np.full(len(cols["t"]), np.nan)
        swing = np.column_stack([np.asarray(cols.get(f"swing_est_{a}", nan), float) for a in "ne"])
        own: dict[str, Any] = {"estimator": settings, "swing": swing}
    else:
        src = {c: np.asarray(cols[c], dtype=float) for c in names}
        src["t"] = np.asarray(cols["t"], dtype=float)
        src["yaw"] = np.unwrap(src["yaw"])
        dt = 1.0 / float(settings["rate"])
        grid = resample(src, dt, names=names)
        stack = lambda *c: np.ascontiguousarray(np.column_stack([grid[k] for k in c]))  # noqa: E731
        found = _core.swing_scale_fit(
            stack("vn", "ve"),
            stack("swing_est_n", "swing_est_e"),
            stack("roll", "pitch", "yaw"),
            dt,
            settings,
            **({} if drag is None else {"drag": drag}),
        )
        on_times = lambda e: np.column_stack(  # noqa: E731
            [np.interp(src["t"], grid["t"], e[:, i]) for i in range(2)]
        )
        swing = on_times(found["estimate"])
        own = {
            "estimator": dict(found["own_scale"]["estimator"]),
            "swing": on_times(found["own_scale"]["estimate"]),
        }
        if found["fit"] is not None and all(c in cols for c in IMU_COLUMNS):
            # The fit's estimate is to first order; the drag it removes is large where the
            # pull is small, so with the flight's IMU at hand the estimators make it as a
            # flight on the model will (online and offline then agree).
            swing = _remade(cols, found["estimator"])
            own["swing"] = _remade(cols, own["estimator"])
    out = {
        "estimator": dict(found["estimator"]),
        "swing": swing,
        "own_scale": own,
        "diagnostics": {
            "assumed_scale": float(settings["scale"]),
            "scale": float(found["estimator"]["scale"]),
            "fit": found["fit"],
            "reason": found["reason"],
        },
    }
    # Shared by every caller that reads the same flight: no one may write into it.
    for arr in (swing, own["swing"]):
        arr.setflags(write=False)
    with _SCALES_LOCK:
        _SCALES[key] = out
        while len(_SCALES) > _SCALES_KEPT:
            _SCALES.popitem(last=False)
    return out


def swing_drag(data: Any) -> str | None:
    """The drag removal a flight's IMU swing estimate is read with, where it was given one
    (:func:`with_swing_drag`), else None (the scale fit's default, ``ScaleSettings::drag``)."""
    meta = getattr(data, "meta", None) or {}
    drag = meta.get(SWING_DRAG_META)
    return None if drag is None else str(drag)


def with_swing_drag(data: Any, drag: str) -> Trace:
    """``data`` read with its IMU swing estimate losing ``drag`` of the drag the scale fit
    measures (``keep``, ``quadratic`` or ``all``: ``swing_core::sysid::swing_scale::
    DragRemoval``; an unknown name is refused by the fit): a trace sharing its columns,
    whose identification, selection and model (:func:`flown_estimator`) remove that."""
    meta = dict(getattr(data, "meta", None) or {})
    meta[SWING_DRAG_META] = drag
    # A mapping may hold non-numeric columns, which nothing here reads (as in resample).
    cols = {k: v for k, v in _columns(data).items() if np.asarray(v).dtype.kind in "fiub"}
    return Trace(cols, meta, source=getattr(data, "source", ""))


def swing_estimator(data: Any) -> dict[str, Any] | None:
    """The settings of the estimator that made a flight's ``swing_est_*`` columns: a ULog's
    (``meta["swing_estimator"]``) or the simulated flight's scenario's
    (``sensors.estimator``); None when the flight does not say."""
    meta = getattr(data, "meta", None) or {}
    if meta.get("swing_estimator") is not None:
        return dict(meta["swing_estimator"])
    sensors = (meta.get("scenario") or {}).get("sensors") or {}
    est = sensors.get("estimator")
    return None if est is None else dict(est)


def body_sensor(data: Any) -> dict[str, Any] | None:
    """The settings of the cable sensor on the airframe that made a flight's swing columns:
    a log's (``meta["body_sensor"]``: a ULog read from its ADC or a node's log) or the
    simulated flight's scenario's (``sensors.body``); None when the flight does not say."""
    meta = getattr(data, "meta", None) or {}
    if meta.get("body_sensor") is not None:
        return dict(meta["body_sensor"])
    sensors = (meta.get("scenario") or {}).get("sensors") or {}
    body = sensors.get("body")
    return None if body is None else dict(body)


def model_body_sensor(model: LinearModel) -> dict[str, Any] | None:
    """The cable sensor on the airframe a flight on ``model`` reads: its settings when the
    model's swing came from one (the counts must be calibrated and composed alike), else
    None. A model on the body sensor that does not say with which settings raises
    ``ModelError``."""
    d = model.diagnostics
    if d.get("swing_source") != "body":
        return None
    body = d.get("body_sensor")
    if not isinstance(body, dict):
        raise ModelError(
            "the model was identified on a cable sensor on the airframe but does not say "
            "with which settings (diagnostics.body_sensor)"
        )
    return dict(body)


def model_twin(model: LinearModel) -> tuple[_core.Scenario, tuple[float, float, float]] | None:
    """The vehicle twin ``model`` was selected on, as the adaptive MPC's twin path flies it
    (``AdaptiveMpc(..., twin=, twin_payload=)``): that vehicle's training flight (its
    airframe, PX4 gains and swing sensing; table 4.1's random steps on the model's axes) and
    (payload mass [kg], cable length [m], vehicle mass [kg]) of the white-box estimate the
    model was checked with; None for a model selected without a twin."""
    from swingrt.scenario import resolve

    rec = model.diagnostics.get("twin")
    if rec is None:
        return None
    try:
        sc = rec["scenario"]
        payload = (
            float(rec["payload_mass"]),
            float(rec["cable_length"]),
            float(rec["vehicle_mass"]),
        )
        sections = {k: sc[k] for k in ("vehicle", "controller", "sensors") if k in sc}
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"diagnostics.twin: not a twin record ({exc})") from None
    axes = "ne" if len(model.inputs) == 2 else "n"
    training = resolve({**sections, "random_steps": {"axes": axes}}, default="training")
    return training, payload


def unchecked_warning(model: LinearModel) -> str | None:
    """A line for whoever flies ``model`` when its selection found no candidate that passed
    the closed-loop check (``diagnostics['control_check']['passed']`` false: the least
    violating one was kept), else None. Such a model flies only because nothing better was
    found, and fails far more often than one that passed (README, "Nothing on the
    cable")."""
    cc = model.diagnostics.get("control_check")
    if not isinstance(cc, dict) or cc.get("passed", True):
        return None
    pick = cc.get("pick") or "the least violating candidate was kept"
    return (
        f"warning: no candidate passed the closed-loop check at identification ({pick}); "
        "it may damp the swing little or settle slowly"
    )


def model_estimator(model: LinearModel) -> dict[str, Any] | None:
    """The swing estimator a flight on ``model`` must run: the settings it was identified
    with when its swing is the IMU's estimate (its swing output is that estimate: another
    scale or drag would mean another output), else None (a swing sensor). A model on the IMU
    that does not say with which settings raises ``ModelError``."""
    d = model.diagnostics
    if d.get("swing_source") != "imu":
        return None
    est = d.get("swing_estimator")
    if not isinstance(est, dict):
        raise ModelError(
            "the model was identified on the IMU's swing estimate but does not say with "
            "which estimator settings (diagnostics.swing_estimator)"
        )
    return dict(est)


#: Columns a flight's IMU swing estimate is remade from (:func:`model_columns`).
IMU_COLUMNS = ("imu_ax", "imu_ay", "imu_az", "roll", "pitch", "yaw", "vn", "ve", "vd")


def model_columns(model: LinearModel, data: Any) -> Mapping[str, Any]:
    """``data``'s columns with the swing that ``model``'s swing output stands for.

    A model identified on the IMU's swing estimate (:func:`model_estimator`) outputs that
    estimate as its own estimator makes it: its scale (the measured one for a light payload),
    drag and pendulum observer. Another flight's estimate, made by that flight's estimator or
    calibrated from that flight (what :func:`_swing_columns` gives), reads the swing in other
    units, and a swing sensor reads the angle itself. So the flight's IMU (``imu_a*``, the
    attitude and the velocity) is run through the model's estimator from the flight's start,
    as a flight on the model runs it; an estimate the model's estimator already made
    (``swing_est_*`` by the same settings: a flight on the model, a ULog loaded with them)
    is read as it is. Without an IMU to remake it from the flight is refused (``DataError``):
    its swing is not the model's output. A model on a swing sensor reads what the
    identification reads."""
    est = model_estimator(model)
    if est is None:
        return _swing_columns(data)[0]
    cols = _columns(data)
    want = dict(_core.ImuSwingEstimator(est).settings)
    made = [np.asarray(cols.get(f"swing_est_{a}", []), dtype=float) for a in "ne"]
    if _estimated_by(data, want) and all(
        len(m) == len(cols["t"]) and np.isfinite(m).all() for m in made
    ):
        return {**cols, "swing_n": made[0], "swing_e": made[1]}
    missing = [c for c in IMU_COLUMNS if c not in cols]
    if missing:
        raise DataError(
            f"the model's swing is the IMU's estimate at scale {want['scale']:.4g} m/s²"
            f"{' with the pendulum observer' if want['length'] > 0 else ''}; the flight has "
            f"no column(s) {', '.join(missing)} to make it from"
        )
    swing = _remade(cols, want)
    return {**cols, "swing_n": swing[:, 0], "swing_e": swing[:, 1]}


def _remade(cols: Mapping[str, Any], settings: Mapping[str, Any]) -> np.ndarray:
    """The swing estimate (N×2, on the flight's own times) an estimator of ``settings``
    makes from the flight's IMU (:data:`IMU_COLUMNS`, all present), run from its start as a
    flight runs it."""
    src = {c: np.asarray(cols[c], dtype=float) for c in IMU_COLUMNS}
    src["t"] = np.asarray(cols["t"], dtype=float)
    src["yaw"] = np.unwrap(src["yaw"])
    grid = resample(src, 1.0 / float(settings["rate"]), names=IMU_COLUMNS)
    stack = lambda *c: np.ascontiguousarray(np.column_stack(c))  # noqa: E731
    swing = _core.estimate_swing(
        stack(grid["imu_ax"], grid["imu_ay"], grid["imu_az"]),
        stack(*euler_to_quat(grid["roll"], grid["pitch"], grid["yaw"])),
        stack(grid["vn"], grid["ve"], grid["vd"]),
        dict(settings),
    )
    t = src["t"]
    return np.column_stack([np.interp(t, grid["t"], swing[:, i]) for i in range(2)])


def _estimated_by(data: Any, settings: Mapping[str, Any]) -> bool:
    """Whether ``data``'s ``swing_est_*`` were made by an estimator of ``settings`` (complete
    ones, as the core fills them in); a flight that does not say, or names settings the core
    refuses, was not."""
    own = swing_estimator(data)
    if own is None:
        return False
    try:
        return dict(_core.ImuSwingEstimator(own).settings) == dict(settings)
    except (ConfigError, TypeError, ValueError):
        return False


def _with_source(model: LinearModel, data: Any) -> LinearModel:
    """``model`` with the flight's swing source in its diagnostics and, for ``imu``, the
    estimator's settings (a flight on the model must estimate the swing the same way) and
    the scale measured from the flight (``swing_scale``, :func:`imu_swing_scale`) and, from
    a ULog, the low-pass its vibration chose (``swing_vibration``,
    :mod:`swingrt.io.vibration`); the estimator it carries is the one it flies
    (:func:`flown_estimator`: the measured scale only where it is the smaller)."""
    source = swing_source(data)
    extra: dict[str, Any] = {"swing_source": source}
    if source == "imu":
        extra["swing_estimator"] = flown_estimator(data)
        extra["swing_scale"] = imu_swing_scale(data)["diagnostics"]
        vibration = (getattr(data, "meta", None) or {}).get("swing_vibration")
        if vibration is not None:
            extra["swing_vibration"] = dict(vibration)
    if source == "body":
        extra["body_sensor"] = body_sensor(data)
    return model.with_diagnostics(extra)


def _axes(axes: str) -> tuple[list[str], list[str]]:
    if axes not in AXES:
        raise ConfigError(f"axes: must be one of {', '.join(AXES)}, not {axes!r}", field="axes")
    return AXES[axes]


def _prepare(
    data: Any, axes: str, settings: Mapping[str, Any]
) -> tuple[np.ndarray, np.ndarray, list[str], list[str]]:
    """Resampled (and, with ``smooth``, smoothed) state and input columns of ``axes``."""
    states, inputs = _axes(axes)
    given, _ = _swing_columns(data)
    missing = [c for c in (*states, *inputs) if c not in given]
    if missing:
        hint = []
        if any(c.startswith("swing_") for c in missing):
            hint.append(
                "a ULog's swing sensor is chosen with --ulog-swing-topic/--ulog-swing-name "
                "(Python: load_flight(ulog_swing=...))"
            )
        if axes == "ne" and not any(c.startswith("swing_") for c in missing):
            hint.append("--axes n identifies the North axis alone")
        raise DataError(
            f"the flight has no column(s) {', '.join(repr(c) for c in missing)} that "
            f"identification on axes {axes!r} needs" + (f"; {'; '.join(hint)}" if hint else "")
        )
    cols = resample(given, settings["dt"], names=[*states, *inputs])
    x = np.column_stack([cols[s] for s in states])
    u = np.column_stack([cols[s] for s in inputs])
    if settings["smooth"]:
        # Section 4.6.6: quadratic regression for states, Gaussian average for inputs.
        w = settings["smooth_window"]
        x = np.column_stack([_core.sysid_smooth_quadratic(np.ascontiguousarray(c), w) for c in x.T])
        u = np.column_stack([_core.sysid_smooth_gaussian(np.ascontiguousarray(c), w) for c in u.T])
    return np.ascontiguousarray(x), np.ascontiguousarray(u), states, inputs


# --------------------------------------------------------------------------- identify


def search(
    data: Any, *, axes: str = "n", delays: Sequence[int] | None = None, **settings: Any
) -> SearchResult:
    """Search (q, p) on the held-out first ``test_span`` seconds, training on the rest
    (section 4.6.3). ``search_mode="refine"`` (default): the coarse grid's q (``delays``,
    default 2, 6, ..., 78) with every rank up to ``dense_ranks`` and steps of ``rank_step``
    above, then unit steps within ``fine`` = (q radius, p radius) around the best p of each
    of the ``winners`` best q (``fine=None``: the coarse grid alone);
    ``search_mode="exhaustive"``: every q of ``delays`` (default 2...``score_delays`` = 80)
    and every p. Both score every candidate from the same rollout starts, so their NMAEs
    compare. The stability screen (criterion and, for a refused row, the reason in
    ``diagnostics['stability_screen']``) judges a candidate by its use: no mode may grow by
    more than ``growth_limit`` (2) over ``prediction_horizon`` (3 s, the MPC's horizon), except
    the velocity integrator's, which may lie within 1 ± ``integrator_tolerance``. Other
    keywords are identification settings (:func:`identify_settings`)."""
    if settings.get("method") == "whitebox":
        raise ConfigError("method: search applies to dmdc and havokc", field="method")
    grid = list(delays) if delays is not None else settings.get("search_delays")
    rest = {k: v for k, v in settings.items() if k not in ("search", "search_delays")}
    s = identify_settings(**rest, search=True, search_delays=grid)
    x, u, states, inputs = _prepare(data, axes, s)
    model, found = _core.identify(x, u, states, inputs, s)
    table = found.table() if found is not None else []
    model = _with_source(model, data)
    return SearchResult(model=model, table=table, search=found, settings=s)


def identify(data: Any, *, axes: str = "n", **settings: Any) -> LinearModel:
    """Identify a model from a flight.

    ``method``: ``dmdc`` | ``havokc`` | ``whitebox``; ``axes``: ``n`` (``[vn, swing_n] <-
    acc_sp_n``) or ``ne``; ``offset``: ``none`` | ``mean`` | ``affine``. With ``search``
    (DMDc/HAVOKc) q and p come from a search (:func:`search`); otherwise ``delays`` (default
    20) and ``rank`` (default full). The first ``test_span`` seconds are held out and the
    model's ``diagnostics['test_nmae']`` is its rollout NMAE there; ``test_span=0`` trains
    on everything. White-box: ``payload_mass`` from RLS on the ``thrust`` column unless
    given, ``cable_length`` from the swing's answer to the vehicle's motion unless given.
    Every keyword is a field of :func:`identify_settings`.
    """
    s = identify_settings(**settings)
    if s["search"]:
        rest = {k: v for k, v in s.items() if k not in ("delays", "rank")}
        return search(data, axes=axes, **rest).model
    if swing_source(data) == "imu":
        # The swing is the IMU's estimate: the white-box asks more of a second link.
        s = {**s, "imu_swing": True}
    x, u, states, inputs = _prepare(data, axes, s)
    mass = None
    if s["method"] == "whitebox" and s["payload_mass"] is None:
        mass = estimate_payload_mass(data, vehicle_mass=s["vehicle_mass"], skip=s["test_span"])
    model, _ = _core.identify(x, u, states, inputs, s, payload_mass=mass)
    if s["method"] == "whitebox" and s.get("imu_swing") and s["cable_length"] is None:
        model = _imu_cable_length(data, model, x, u, states, inputs, s, mass)
    return _with_source(model, data)


def _imu_cable_length(
    data: Any,
    model: LinearModel,
    x: np.ndarray,
    u: np.ndarray,
    states: list[str],
    inputs: list[str],
    s: Mapping[str, Any],
    mass: float | None,
) -> LinearModel:
    """A white-box of an IMU flight on the cable length its swing-scale fit measured
    (:func:`imu_swing_scale`), where that fit stands and the swing shows one link.

    The swing the white-box reads is the estimate the MPC flies, and at the estimator's
    assumed scale it is the angle plus a share of the vehicle's tilt (:func:`flown_estimator`):
    the single pendulum that answers the vehicle's motion as that estimate does is too short
    for a payload heavier than assumed (on ``robustness-imu`` seed 3, 17 % at 0.35–0.5 kg)
    and a few percent long for a light one. The scale fit models the tilt's share and
    drag, and its length is the cable's within 1 %. A second link (``links``) keeps the
    swing's own fit, whose two links the twin flies."""
    wb = model.diagnostics.get("whitebox") or {}
    if wb.get("links") is not None:
        return model
    fit = imu_swing_scale(data)["diagnostics"]["fit"]
    if fit is None:
        return model
    refit, _ = _core.identify(
        x, u, states, inputs, {**s, "cable_length": float(fit["length"])}, payload_mass=mass
    )
    return refit.with_diagnostics(
        {
            "whitebox_length": {
                "source": "imu_scale_fit",
                "length": float(fit["length"]),
                "swing_fit_length": float(wb["length"]),
                "fft_length": wb.get("fft_length"),
            }
        }
    )


def select_for_control(
    data: Any,
    result: SearchResult,
    *,
    axes: str = "n",
    mpc_settings: Mapping[str, Any] | None = None,
    candidates: int | None = None,
    passers: int | None = None,
    look_ahead: int | None = None,
    input_lags: Sequence[float] | None = None,
    input_delays: Sequence[float] | None = None,
    bound_amplitudes: Sequence[float] | None = None,
    flight_lag: bool | None = None,
    vehicle_drag: Sequence[float] | None = None,
    step: float | None = None,
    bounds: Mapping[str, float] | None = None,
    twin: _core.Scenario | str | None = "builtin",
    twin_bounds: Mapping[str, float] | None = None,
    noise_factors: Sequence[float] | None = None,
    disturbance_factors: Sequence[float] | None = None,
    gust_noise: float | None = None,
    trust_factors: Sequence[float] | None = None,
    pick_on_gust: bool | None = None,
    payload_tolerance: float | None = None,
    slow_motor_lag: float | None = None,
    slow_inertia: float | None = None,
    wander_sigmas: float | None = None,
    spillover: Mapping[str, float] | None = None,
    fallback: str | None = None,
    swing_drags: Sequence[str] | None = None,
    check: tuple[LinearModel, str] | None = None,
    **settings: Any,
) -> SearchResult:
    """Pick from a search the model to fly an MPC on (control-relevant selection, see
    ``swing_core::design::selection``): up to ``candidates`` distinct (q, p), the stable
    ones of lowest NMAE first, then (with a ``twin``) those the search did not screen,
    screened in turn, fly
    the MPC (``mpc_settings``) on the white-box model of the same flight,
    with each of ``vehicle_drag`` [1/s] added and behind each of ``input_lags`` [s]: hover,
    a ``step`` m/s step, hold (unset settings take the core's defaults: 300 candidates, lags
    0 and 0.1 s, drags 0.12 and 0.4 /s, a 2 m/s step), and with ``flight_lag`` (off by
    default) also behind the attitude lag the flight shows (``diagnostics['whitebox']
    ['attitude_lag']``: the acceleration command against the measured acceleration), and
    with no lag behind each dead time of ``input_delays`` [s] (the delay margin at the
    acceleration input), and with no limit cycle predicted against the acceleration bound
    for a command of each of ``bound_amplitudes`` times it (describing function; none by
    default); one
    within ``bounds`` (fractions of
    the step: ``overshoot``, ``final_error``, ``hold_drift``) passes, else the least
    violating is taken. The
    outcome is in ``model.diagnostics['control_check']``. ``settings`` override the
    search's identification settings.

    With ``twin`` (a scenario of the vehicle: its airframe and PX4 gains, e.g. the training
    flight's or one from ``swingrt vehicle``; by default ``"builtin"``, the built-in vehicle
    at the identification's vehicle mass (:func:`builtin_twin`), whose worth as a twin is
    PX4's cascade and its lag more than its exact airframe; ``None``
    flies no twin), each candidate's MPC first flies the step on swingrt's nonlinear simulator of
    that vehicle carrying the white-box payload (both links when the swing shows a second
    one, ``diagnostics['whitebox']['links']``), with the flight's swing-sensor noise, in still
    air, and must settle within ``twin_bounds`` (``settle`` [s] after the step,
    ``final_error`` as a fraction of it) before the linear plants are flown. One that
    settles there too then holds the step on the twin for 60 s, with the noise and without:
    what the noise alone does to its velocity (``wander``, the RMS of the 2 s mean
    difference) and its largest error over the last 20 s without noise (``late_error``: a
    slowly growing oscillation) are bounded, as fractions of the step. One that settles and
    whose swing excess stays within ``swing_vs_pid`` of PX4's own on the same step (or below
    ``swing_excess_min`` deg·s) passes; of the first ``passers`` that pass, looking at most
    ``look_ahead`` candidates past the first that passes, the one that swings least on the
    twin is taken (ties to the lower NMAE), else the one of all that settled that swings
    least. On a swing estimated from the IMU, whose channels the gust's drag lands on, each
    candidate within every bound also flies the twin's gust flight (below) and "swings
    least" is its step excess plus the gust's swing IAE (``checked[*].swing_cost``;
    ``pick_on_gust``, default True). Before a candidate flies, its estimator is designed
    against the flight's swing noise: the swing channels' Kalman measurement noise is the
    first of ``noise_factors`` (default 1, 3, 10 times the MPC's own) whose predicted wander
    (:func:`swingrt._core.velocity_wander`, the standard deviation of the 2 s mean velocity
    on the white-box plant behind the largest lag) is within the twin's ``late_error`` over
    ``wander_sigmas`` (3.29: the noise alone ends one flight in a thousand past it), else the
    one that wanders least; a model flown with a raised noise carries it
    (``diagnostics['swing_measurement_noise']``) and every MPC built on it assumes at
    least that. When none passes so designed, every candidate is flown once more with the
    largest factor (``control_check['strongest_filter_pass']``) and the pick is taken from
    both passes. A pick that passed on the twin then has its disturbance estimate's rate
    designed there: it flies the twin's gust flight (the step held, a 1 m/s headwind gust
    for 2 s, no sensor noise) as designed and with its disturbances' Kalman process noise
    raised by each of ``disturbance_factors`` above 1 (default 1, 2.5), each also with a
    gust state of stationary std ``gust_noise`` m/s² (default 0.3; 0 tries none: a force
    the MPC predicts to fade, ``MpcSettings::gust_noise``); a design that passes every
    flight again and is back within the settle band within the twin's ``settle`` after the
    gust is taken when the gust leaves less swing, and the model carries it
    (``diagnostics['disturbance_noise']``, ``diagnostics['gust_noise']``;
    ``control_check['disturbance_design']``). On a swing estimated from the IMU, the pick
    that passed then has its trust in that estimate designed there: its swing measurement
    noise as designed and raised by each of ``trust_factors`` above 1 (default 1: none;
    e.g. 1, 10, 30, 100) is judged on every flight again and flown on the twin's gust (both
    flights with the twin's IMU noise), and of those that pass and resettle after the gust
    the one whose step excess plus gust swing IAE is least is taken
    (``control_check['trust_design']``; the model carries its noise). Off by default: the
    twin's flights start from rest, and a raised noise damps a swing already present
    slowly. A candidate that passes every other flight
    also flies the twin's step with every link of the payload ``1 ∓ payload_tolerance``
    times as long (default 0.1: the white-box's lengths are estimates) and must settle
    there within the
    twin's step bounds (``checked[*].payload_miss``, the worst ratio of a figure to its
    bound; 0 flies the nominal twin alone), and on a slow vehicle: the twin with motors of
    time constant ``slow_motor_lag`` [s] (default 0.04, where slower than its own) and
    ``slow_inertia`` times its inertia (default 1.5), what the twin does not know of the
    attitude loop (``checked[*].slow_vehicle_miss``; 0 and 1 fly none).
    Where the white-box recorded a second peak of the swing's spectrum
    (``diagnostics['whitebox']['second_peak']``, a lower mode it did not fit), a pick that
    passed also flies the twin's step with its payload as the heaviest double pendulum of
    the two rates; where it does not settle there, it is designed smoother
    (``spillover``: ``acc_rate_factor`` times the MPC's input-rate weight, default 4, and a
    swing measurement noise of at least ``swing_noise`` rad, default 0.05), and the smooth
    design flies when it passes every flight again and settles there (the model carries it:
    ``diagnostics['acc_rate_weight']``; ``control_check['spillover']``; 1 and 0 fly none).
    When no candidate's MPC passes, the ``fallback`` law (default ``"zvd"``; ``"zv"``, or
    ``"none"`` for none) flies the same twin flights: the input shaper of PX4's velocity
    setpoint on the white-box pendulum (:mod:`swing_core::design::law`), judged like a
    candidate but for the linear plants (it has no feedback on the model); when the rule
    picks it, ``control_check['law']`` records it and every flight of the model flies it.
    ``control_check['wander']`` reports the pick's predicted
    wander on each checked loop. Without a white-box (a model-only check) the twin is not
    flown. A flight identified on the IMU's swing estimate (:func:`swing_source`) flies the
    twin on the same estimate (its ``sensors`` set to the flight's swing source and
    estimator). Such a flight, where its scale fit stands, is searched and selected once
    for each drag removal of ``swing_drags`` (``SelectionSettings::swing_drags``, default
    ``quadratic`` then ``keep``: :func:`with_swing_drag`), and the selection whose pick the
    twin judges best is returned (within every bound first, then the least swing on the
    twin's step over PX4's there; ties to the earlier), with what each weighed in
    ``diagnostics['swing_drag_choice']``. ``check`` is :func:`check_plant`'s answer when the
    caller already has it (it is built from the same flight and settings otherwise)."""
    if result.search is None:
        raise ConfigError("result: not from a search (no candidates to check)", field="result")
    s = identify_settings(**{**result.settings, **settings})
    # Unset selection settings take the core's defaults (``SelectionSettings``): one home.
    given = {
        "candidates": candidates,
        "passers": passers,
        "look_ahead": look_ahead,
        "input_lags": None if input_lags is None else list(input_lags),
        "input_delays": None if input_delays is None else list(input_delays),
        "bound_amplitudes": None if bound_amplitudes is None else list(bound_amplitudes),
        "flight_lag": flight_lag,
        "vehicle_drag": None if vehicle_drag is None else list(vehicle_drag),
        "step": step,
        "bounds": None if bounds is None else dict(bounds),
        "twin_bounds": None if twin_bounds is None else dict(twin_bounds),
        "noise_factors": None if noise_factors is None else list(noise_factors),
        "disturbance_factors": None if disturbance_factors is None else list(disturbance_factors),
        "gust_noise": gust_noise,
        "trust_factors": None if trust_factors is None else list(trust_factors),
        "pick_on_gust": pick_on_gust,
        "payload_tolerance": payload_tolerance,
        "slow_motor_lag": slow_motor_lag,
        "slow_inertia": slow_inertia,
        "wander_sigmas": wander_sigmas,
        "spillover": None if spillover is None else dict(spillover),
        "fallback": fallback,
        "swing_drags": None if swing_drags is None else list(swing_drags),
    }
    selection = {k: v for k, v in given.items() if v is not None}
    drags = _core.check_settings("selection", selection)["swing_drags"]
    if isinstance(twin, str):
        if twin != "builtin":
            raise ConfigError(f"twin: a Scenario, 'builtin' or None, not {twin!r}", field="twin")
        twin = builtin_twin(s["vehicle_mass"])
    runs = []
    for drag, view in _drag_views(data, drags):
        found = result if view is data else search(view, axes=axes, **result.settings)
        plant = check if view is data else None
        runs.append((drag, _select(view, found, axes, s, mpc_settings, selection, twin, plant)))
    if len(runs) == 1:
        return runs[0][1]
    weighed = [{"drag": drag, **_pick_outcome(r.model)} for drag, r in runs]
    best = _core.selection_choose_reading(
        [(w["pick_kind"], w["twin_swing_vs_pid"]) for w in weighed]
    )
    assert best is not None  # two readings or more
    chosen = runs[best][1]
    record = {"chosen": runs[best][0], "weighed": weighed}
    return replace(chosen, model=chosen.model.with_diagnostics({"swing_drag_choice": record}))


def _drag_views(data: Any, drags: Sequence[str]) -> list[tuple[str | None, Any]]:
    """The flight as the selection reads it with each removal of ``drags``
    (``SelectionSettings::swing_drags``), the flight itself for the one its scale fit made;
    the flight alone (drag None) when its swing is not the IMU's estimate, its scale fit is
    refused (nothing measured to remove) or it is read with a removal of its own."""
    if swing_source(data) != "imu" or swing_drag(data) is not None:
        return [(None, data)]
    fit = imu_swing_scale(data)["diagnostics"]["fit"]
    if fit is None:
        return [(None, data)]
    own = fit["drag_removed"]
    return [(d, data if d == own else with_swing_drag(data, d)) for d in drags]


def _pick_outcome(model: LinearModel) -> dict[str, Any]:
    """What the twin said of a selection's pick: how it was picked, the law it flies, its
    (q, p), its swing excess on the twin's step over PX4's there (None without a twin) and
    the twin step's figures (``twin``: settle time, overshoot, final error, swing excess).
    The readings are weighed on the step alone, not on the twin's gust as the candidates
    of one reading are (``pick_on_gust``): the drag removal's worth is the step's end, where
    the estimate's quadratic drag leaves the payload leaning, which the gust flight does not
    show (the default step's seed 6 weighed on both took ``keep`` and leaned 1.15° 4 s
    after the step)."""
    cc = model.diagnostics.get("control_check") or {}
    flown = cc.get("checked", [])[cc["flown"]] if "flown" in cc else {}
    twin, pid = flown.get("twin") or {}, ((cc.get("twin") or {}).get("pid") or {})
    swing, ref = twin.get("swing_excess"), pid.get("swing_excess")
    return {
        "pick_kind": cc.get("pick_kind"),
        "law": (cc.get("law") or {}).get("kind", "mpc"),
        "q": int(model.delays),
        "p": int(model.rank),
        "twin_swing_vs_pid": None if swing is None or not ref else float(swing) / float(ref),
        "twin": flown.get("twin"),
    }


def _select(
    data: Any,
    result: SearchResult,
    axes: str,
    s: Mapping[str, Any],
    mpc_settings: Mapping[str, Any] | None,
    selection: Mapping[str, Any],
    twin: _core.Scenario | None,
    check: tuple[LinearModel, str] | None,
) -> SearchResult:
    """One control-relevant selection of :func:`select_for_control` on ``data`` as read."""
    plant, label = check or check_plant(data, result, axes=axes, settings=s)
    selection = {**selection, "plant_label": label}
    if plant.method != "whitebox":
        twin = None
    if twin is not None and swing_source(data) == "imu":
        # The twin measures the swing as a flight on the model does: the model's swing
        # output is the IMU estimate (its scale and the drag it carries), and its MPC flies
        # on that estimate.
        sensors: dict[str, Any] = {"swing": "imu"}
        est = flown_estimator(data)
        if est is not None:
            sensors["estimator"] = est
        twin = twin.with_overrides({"sensors": sensors})
    x, u, states, inputs = _prepare(data, axes, s)
    model, _passed = _core.select_for_control(
        x, u, states, inputs, s, result.search, plant, mpc_settings, selection, twin
    )
    model = _with_source(model, data)
    wb = plant.diagnostics.get("whitebox")
    if twin is not None and isinstance(wb, dict):
        # What the model was selected on: the adaptive MPC re-identifies on the same twin
        # in flight (:func:`model_twin`).
        model = model.with_diagnostics(
            {
                "twin": {
                    "scenario": twin.to_dict(),
                    "payload_mass": float(wb["payload_mass"]),
                    "cable_length": float(wb["length"]),
                    "vehicle_mass": float(wb["vehicle_mass"]),
                }
            }
        )
    return SearchResult(model=model, table=result.table, search=result.search, settings=dict(s))


#: The fields of a scenario's ``controller`` table that are PX4's cascade gains (velocity,
#: attitude and rate loops): what every ULog's parameters give of a vehicle.
PX4_GAINS = ("vel_p", "vel_i", "vel_d", "att_p", "rate_p", "rate_i", "rate_d")


def builtin_twin(vehicle_mass: float, gains: Mapping[str, Any] | None = None) -> _core.Scenario:
    """The built-in vehicle as the twin of one that weighs ``vehicle_mass`` [kg] (the
    identification's: given, described or the default), flown under PX4's ``gains`` when
    given (fields of :data:`PX4_GAINS`, as a scenario's ``controller`` table holds them; a
    ULog's parameters give them). The mass ratio of vehicle and payload sets how hard the
    swing pulls on the vehicle, and the gains shape the attitude loop the MPC commands
    through, so the twin takes what is known. What is not known stays the built-in
    Honeybee's: its motors are scaled with the mass (the same hover thrust and
    thrust-to-weight, as :func:`swingrt.hil.params.vehicle_from_px4` scales them to a given
    mass) and so is its inertia; drag and motor lag are nominal, and so are the gains not
    given."""
    twin = _core.Scenario.builtin("step")
    if gains:
        unknown = sorted(set(gains) - set(PX4_GAINS))
        if unknown:
            raise ConfigError(
                f"gains: {', '.join(unknown)} not PX4 cascade gains ({', '.join(PX4_GAINS)})",
                field="gains",
            )
        try:
            twin = twin.with_overrides({"controller": {k: list(v) for k, v in gains.items()}})
        except (ConfigError, TypeError) as e:
            raise ConfigError(f"gains: the built-in twin refuses them ({e})", field="gains") from e
    vehicle = twin.to_dict()["vehicle"]
    scale = float(vehicle_mass) / float(vehicle["mass"])
    if scale == 1.0:
        return twin
    if not (math.isfinite(scale) and scale > 0.0):
        raise ConfigError(
            f"vehicle_mass must be a positive number of kg, not {vehicle_mass}",
            field="vehicle_mass",
        )
    try:
        return twin.with_overrides(
            {
                "vehicle": {
                    "mass": float(vehicle_mass),
                    "thrust_poly": [c * scale for c in vehicle["thrust_poly"]],
                    "inertia": scaled_inertia(vehicle, float(vehicle_mass)),
                }
            }
        )
    except ConfigError as e:
        raise ConfigError(
            f"vehicle_mass {vehicle_mass:g} kg: the built-in twin scaled to it is refused ({e})",
            field="vehicle_mass",
        ) from e


def check_plant(
    data: Any, result: SearchResult, *, axes: str = "n", settings: Mapping[str, Any]
) -> tuple[LinearModel, str]:
    """The plant the closed-loop check flies, and a label saying what it is.

    The white-box of the same flight: cable length from the swing's answer to the vehicle's
    motion (or ``cable_length``), payload mass from ``payload_mass`` if given, else RLS on a
    ``thrust`` column [N], else :data:`DEFAULT_CHECK_PAYLOAD_MASS` (not estimated; the label
    says so). If no white-box can be built (no swing peak in the band …), the search's lowest-NMAE
    model stands in as the plant (a model-only check; the label says why)."""
    s = settings
    cols = _columns(data)
    length = (
        f"cable length {s['cable_length']:.3g} m given"
        if s["cable_length"] is not None
        else "cable length from the swing's answer to the vehicle's motion"
    )
    if s["payload_mass"] is not None:
        mass = float(s["payload_mass"])
        source = f"payload mass {mass:.3g} kg given"
    else:
        why = None
        if "thrust" in cols:
            try:
                mass = estimate_payload_mass(
                    data, vehicle_mass=s["vehicle_mass"], skip=s["test_span"]
                )
                source = f"payload mass {mass:.3g} kg from thrust"
            except (DataError, IdentificationError) as exc:
                why = f"the thrust estimate failed ({exc})"
        elif "thrust_sp" in cols:
            why = (
                "the log's thrust is PX4's normalised setpoint, not newtons (the vehicle's "
                "description, --twin vehicle.toml / sysid.with_thrust, gives its motors)"
            )
        else:
            why = "the log has no 'thrust' column"
        if why is not None:
            mass = DEFAULT_CHECK_PAYLOAD_MASS
            source = (
                f"default payload mass {mass:.3g} kg, not estimated: {why}; "
                "--payload-mass / payload_mass sets it"
            )
    try:
        plant = identify(
            data,
            axes=axes,
            method="whitebox",
            dt=s["dt"],
            test_span=s["test_span"],
            vehicle_mass=s["vehicle_mass"],
            payload_mass=mass,
            cable_length=s["cable_length"],
            swing_band=s["swing_band"],
        )
    except (DataError, IdentificationError) as exc:
        best = result.model
        return best, (
            f"model(the search's best, q = {best.delays}, p = {best.rank}; model-only check, "
            f"no white-box: {exc})"
        )
    return plant, f"whitebox({source}; {length})"


def with_thrust(data: Any, vehicle: Any) -> Any:
    """``data`` (a Trace) with ``thrust`` [N] from PX4's normalised collective thrust
    ``thrust_sp`` (a ULog's) through ``vehicle``'s motors (a scenario: four times eq. 6.1's
    thrust at the command, :meth:`Scenario.mass_hovering_at` · g); the white-box's
    payload-mass estimate reads it. Unchanged when it has ``thrust`` already."""
    cols = _columns(data)
    if "thrust" in cols or "thrust_sp" not in cols:
        return data
    cmd = np.clip(np.asarray(cols["thrust_sp"], dtype=float), 0.0, 1.0)
    newtons = np.array([vehicle.mass_hovering_at(float(c)) for c in cmd]) * _core.GRAVITY
    from swingrt.io.flight import Trace

    thrust = np.where(np.isfinite(cols["thrust_sp"]), newtons, np.nan)
    if isinstance(data, Trace):
        return Trace(
            {**data.columns, "thrust": thrust},
            data.meta,
            source=data.source,
            notes={k: v for k, v in data.notes.items() if k != "thrust"},
        )
    return {**cols, "thrust": thrust}


def estimate_payload_mass(
    data: Any, *, vehicle_mass: float | None = None, skip: float = 0.0, forgetting: float = 1.0
) -> float:
    """Payload mass [kg] by RLS on hover thrust (section 4.3.2): total rotor thrust
    (``thrust``, projected on the vertical with ``roll``/``pitch`` when present) against
    g - a_down, with a_down the derivative of ``vd``; minus the known vehicle mass."""
    cols = _columns(data)
    if "thrust" not in cols:
        raise DataError(
            "the white-box needs a 'thrust' column [N] for the payload-mass estimate; "
            "give the mass instead (--payload-mass KG, or payload_mass=)"
        )
    if vehicle_mass is None:
        vehicle_mass = identify_settings()["vehicle_mass"]
    names = ["thrust", "vd"] + [k for k in ("roll", "pitch") if k in cols]
    dt = 0.01
    r = resample(cols, dt, names=names)
    t = r["t"]
    return _core.whitebox_payload_mass(
        r["thrust"],
        r["vd"],
        r.get("roll"),
        r.get("pitch"),
        dt=dt,
        skip=int(np.count_nonzero(t < t[0] + skip)),
        vehicle_mass=vehicle_mass,
        forgetting=forgetting,
    )


def to_statespace(model: LinearModel) -> Any:
    """The model as a discrete python-control ``StateSpace`` (outputs = newest states).

    The input is u - input_mean; the affine term ``model.c`` is not representable in a
    ``StateSpace``.
    """
    import control

    n = len(model.states)
    C = np.zeros((n, model.order))
    C[:, :n] = np.eye(n)
    D = np.zeros((n, len(model.inputs)))
    return control.ss(
        model.A, model.B, C, D, model.dt, inputs=list(model.inputs), outputs=list(model.states)
    )


#: Swing periods :func:`swing_period` looks for [s]: cables of 4 cm to 25 m.
SWING_PERIODS = (0.4, 10.0)


def lqr_parameters(model: LinearModel) -> dict[str, float]:
    """The baseline LQR's pendulum (``m_q``, ``m_p``, ``l``, ``c``) from a white-box model's
    estimate; ModelError naming the model's method when it has none."""
    est = model.diagnostics.get("whitebox")
    if not est:
        raise ModelError(
            "the LQR needs a white-box model (`identify --method whitebox`): this one carries "
            "no pendulum estimate"
        )
    return {
        "m_q": float(est["vehicle_mass"]),
        "m_p": float(est["payload_mass"]),
        "l": float(est["length"]),
        "c": float(est.get("friction", 0.0)),
    }


def swing_period(model: LinearModel, span: float = 30.0) -> float | None:
    """The period [s] of the swing the model answers an acceleration pulse with on its
    first axis: the largest peak, within :data:`SWING_PERIODS`, of the spectrum of the swing
    output's pulse response over ``span`` seconds (the affine drift removed by subtracting
    the unforced response). It is the period of vehicle and payload together under PX4's
    cascade, which is what a reference shaped against the swing must match: shorter than
    the pendulum's own 2π√(l/g) by about √(1 + m_p/m_Q) when the cascade leaves the vehicle
    free to be pulled. None when the model carries no swing output or no peak stands out."""
    swings = [i for i, s in enumerate(model.states) if s.startswith("swing")]
    if not swings or not model.inputs:
        return None
    q, n = model.delays, len(model.states)
    steps = max(int(round(span / model.dt)), 16)
    hist = np.zeros((q, n))
    u0 = np.zeros((steps, len(model.inputs)))
    u1 = u0.copy()
    u1[: max(1, int(round(0.05 / model.dt))), 0] = 1.0
    s = model.predict(hist, u1)[:, swings[0]] - model.predict(hist, u0)[:, swings[0]]
    if not np.all(np.isfinite(s)) or not np.any(s):
        return None
    pad = 16 * steps
    spectrum = np.abs(np.fft.rfft((s - s.mean()) * np.hanning(steps), n=pad))
    f = np.fft.rfftfreq(pad, model.dt)
    band = (f >= 1.0 / SWING_PERIODS[1]) & (f <= 1.0 / SWING_PERIODS[0])
    if not band.any():
        return None
    k = int(np.argmax(np.where(band, spectrum, -np.inf)))
    # A peak is a period only if it stands above the band's typical level (a model whose
    # swing only creeps has a flat, falling spectrum whose maximum sits at the band's edge).
    if k in (int(np.argmax(band)), len(band) - 1 - int(np.argmax(band[::-1]))):
        return None
    if spectrum[k] < 3.0 * float(np.median(spectrum[band])):
        return None
    return float(1.0 / f[k])


# --------------------------------------------------------------------------- evaluate


def evaluate(
    model: LinearModel,
    data: Any,
    *,
    test_span: float | None = None,
    rollout: float = 20.0,
    starts: int = 10,
) -> dict[str, Any]:
    """k-step rollout NMAE (section 4.6.2) of ``model`` on ``data`` resampled to the
    model's dt: ``starts`` evenly spaced start points, ``rollout`` seconds, true inputs only.
    The swing scored is the one the model's output stands for (:func:`model_columns`: a
    model on the IMU's estimate is scored on the flight's IMU through its own estimator).
    ``test_span`` limits scoring to the first seconds of the data (default: all of it).
    Returns ``{"nmae": mean, "per_state": {name: nmae}}``."""
    if not (math.isfinite(rollout) and rollout > 0):
        raise ConfigError(f"rollout: must be a positive number of seconds, not {rollout}")
    cols = resample(model_columns(model, data), model.dt, names=[*model.states, *model.inputs])
    x = np.column_stack([cols[s] for s in model.states])
    u = np.column_stack([cols[s] for s in model.inputs])
    if test_span is not None:
        k = int(round(test_span / model.dt))
        x, u = x[:k], u[:k]
    per, mean = _core.evaluate(
        model,
        np.ascontiguousarray(x),
        np.ascontiguousarray(u),
        rollout_samples=max(1, int(round(rollout / model.dt))),
        starts=starts,
    )
    return {"nmae": mean, "per_state": {s: per[i] for i, s in enumerate(model.states)}}


# --------------------------------------------------------------------------- sweeps


def sweep_training_length(
    data: Any,
    lengths: Sequence[float],
    *,
    axes: str = "n",
    test_span: float = 40.0,
    delays: Sequence[int] | None = None,
    fine: tuple[int, int] | None = None,
    **settings: Any,
) -> list[dict[str, Any]]:
    """Error vs training length (section 4.6.8): for each length [s] the training data
    (after the test span) are cut to that length and a search picks (q, p). Rows:
    ``train_length, delays, rank, nmae``."""
    cols = dict(_columns(data))
    t = np.asarray(cols["t"], dtype=float)
    rows: list[dict[str, Any]] = []
    for length in lengths:
        end = t[0] + test_span + float(length)
        keep = t <= end + 1e-9
        sub = {k: np.asarray(v)[keep] for k, v in cols.items() if np.shape(v) == t.shape}
        try:
            res = search(sub, axes=axes, test_span=test_span, delays=delays, fine=fine, **settings)
            sel = res.model.diagnostics["selected"]
            rows.append(
                {
                    "train_length": float(length),
                    "delays": sel["delays"],
                    "rank": sel["rank"],
                    "nmae": sel["nmae"],
                }
            )
        except (DataError, IdentificationError) as exc:
            rows.append(
                {
                    "train_length": float(length),
                    "delays": None,
                    "rank": None,
                    "nmae": math.inf,
                    "error": str(exc),
                }
            )
    return rows


def sweep_sample_time(
    data: Any,
    dts: Sequence[float],
    *,
    axes: str = "n",
    delays: Sequence[int] | None = None,
    **settings: Any,
) -> list[dict[str, Any]]:
    """Error vs sample time (section 4.6.4): resample at each Ts and search. Rows:
    ``dt, delays, rank, nmae``."""
    rows = []
    for dt in dts:
        res = search(data, axes=axes, dt=float(dt), delays=delays, fine=None, **settings)
        sel = res.model.diagnostics["selected"]
        rows.append(
            {"dt": float(dt), "delays": sel["delays"], "rank": sel["rank"], "nmae": sel["nmae"]}
        )
    return rows


def sweep_noise(
    data: Any,
    lengths: Sequence[float],
    *,
    noise_std: float = 0.01,
    seed: int = 0,
    method: str = "havokc",
    smooth: bool = True,
    **kwargs: Any,
) -> list[dict[str, Any]]:
    """Error vs training length with and without swing-sensor noise (section 4.6.6, figure
    4.11): seeded white noise of ``noise_std`` [rad] is added to the swing columns at the
    data's own rate (band-limited by the later resampling); the noisy runs are smoothed
    when ``smooth``. Rows: ``train_length, noise, delays, rank, nmae``."""
    cols = {k: np.asarray(v) for k, v in _columns(data).items()}
    rng = np.random.default_rng(seed)
    noisy = dict(cols)
    for name in ("swing_n", "swing_e"):
        if name in noisy:
            noisy[name] = noisy[name] + rng.normal(0.0, noise_std, size=noisy[name].shape)
    rows = []
    for flag, d, sm in ((False, cols, False), (True, noisy, smooth)):
        for row in sweep_training_length(d, lengths, method=method, smooth=sm, **kwargs):
            rows.append({**row, "noise": flag})
    return rows
