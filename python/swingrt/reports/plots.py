"""Every figure swingrt draws, with one way to save them (:func:`save_figure`).

* :func:`plot_pareto` — identification: lowest stable NMAE per delay count q (figure 4.6);
* :func:`plot_training_length` — NMAE vs training length (section 4.6.8, figure 4.11);
* :func:`plot_sample_time` — NMAE vs sample time (section 4.6.4);
* :func:`plot_case` — an experiment case: velocity, swing and acceleration setpoint against
  time, controllers overlaid (figures 5.11–5.22);
* :func:`plot_prediction` — the MPC's predicted trajectory at the step against the one flown
  (figures 5.20–5.21);
* :func:`plot_mission` — a mission: the vehicle's and the payload's paths seen from above,
  and the swing against time with the arrivals marked, flights overlaid.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from swingrt.io.atomic import atomic_path
from swingrt.metrics import swing_column
from swingrt.sysid import swing_source

if TYPE_CHECKING:
    from swingrt.io.flight import Trace
    from swingrt.sysid import LinearModel, SearchResult

__all__ = [
    "plot_case",
    "plot_mission",
    "plot_pareto",
    "plot_prediction",
    "plot_sample_time",
    "plot_training_length",
    "save_figure",
]


def _pyplot() -> Any:
    """matplotlib.pyplot on the non-interactive Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(
    fig: Any, path: str | os.PathLike[str], *, dpi: int = 120, tight: bool = True
) -> None:
    """Save ``fig`` atomically in the format of the file suffix (default PNG), then close it.

    ``tight`` crops the saved figure to its artists (``bbox_inches="tight"``); without it
    the figure keeps its own size (the caller has laid it out with ``tight_layout``).
    """
    suffix = Path(path).suffix or ".png"
    extra: dict[str, Any] = {"bbox_inches": "tight"} if tight else {}
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=suffix.lstrip("."), dpi=dpi, **extra)
    _pyplot().close(fig)


def plot_pareto(result: SearchResult, path: str | os.PathLike[str]) -> None:
    """Lowest stable NMAE per q (the Pareto elbow of figure 4.6), saved atomically."""
    plt = _pyplot()
    rows = result.best_per_delay()
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot([r["delays"] for r in rows], [r["nmae"] for r in rows], "o-")
    sel = result.model.diagnostics.get("selected")
    if sel:
        ax.plot([sel["delays"]], [sel["nmae"]], "r*", ms=12, label="selected")
        ax.legend()
    ax.set_xlabel("delays q")
    ax.set_ylabel("held-out NMAE (best stable p)")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    save_figure(fig, path)


def plot_training_length(rows: list[dict[str, Any]], path: str | os.PathLike[str]) -> None:
    """NMAE vs training length (the double descent of section 4.6.8), one line per
    ``noise`` flag when present, saved atomically."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    groups: dict[Any, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(r.get("noise"), []).append(r)
    for key, rs in groups.items():
        rs = [r for r in rs if math.isfinite(r["nmae"])]
        label = {None: "NMAE", True: "with noise", False: "without noise"}[key]
        ax.plot([r["train_length"] for r in rs], [r["nmae"] for r in rs], "o-", label=label)
    ax.set_xlabel("training length [s]")
    ax.set_ylabel("held-out NMAE")
    ax.grid(True, alpha=0.3)
    ax.legend()
    save_figure(fig, path)


def plot_sample_time(rows: list[dict[str, Any]], path: str | os.PathLike[str]) -> None:
    """NMAE vs sample time Ts (section 4.6.4), saved atomically."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot([r["dt"] for r in rows], [r["nmae"] for r in rows], "o-")
    ax.set_xlabel("sample time Ts [s]")
    ax.set_ylabel("held-out NMAE")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, tight=False)


_STYLE = {
    "pid": ("tab:gray", "PX4 PID"),
    "lqr": ("tab:blue", "LQR"),
    "mpc": ("tab:red", "MPC"),
    "px4": ("tab:gray", "PX4 mission mode"),
    "smooth": ("tab:green", "swingrt's legs under PX4"),
}


def plot_case(
    path: str | os.PathLike[str], title: str, traces: dict[str, Trace], axes: str
) -> None:
    """Velocity, swing angle and acceleration setpoint against time, controllers overlaid."""
    plt = _pyplot()
    names = ["n"] if axes == "n" else ["n", "e"]
    fig, ax = plt.subplots(3, len(names), figsize=(7 * len(names), 8), sharex=True, squeeze=False)
    for j, a in enumerate(names):
        for ctrl, tr in traces.items():
            color, label = _STYLE.get(ctrl, (None, ctrl))
            t = tr.t
            ax[0, j].plot(t, tr[f"v{a}"], color=color, label=label)
            ax[1, j].plot(t, np.degrees(tr[swing_column(tr, a)]), color=color, label=label)
            ax[2, j].plot(t, tr[f"acc_sp_{a}"], color=color, label=label)
        some = next(iter(traces.values()))
        ax[0, j].plot(some.t, some[f"vel_sp_{a}"], "k--", lw=0.8, label="setpoint")
        ax[0, j].set_ylabel(f"v_{a.upper()} [m/s]")
        ax[1, j].set_ylabel(f"{swing_column(some, a)} [deg]")
        ax[2, j].set_ylabel(f"acc_sp_{a} [m/s²]")
        ax[2, j].set_xlabel("t [s]")
        for k in range(3):
            ax[k, j].grid(alpha=0.3)
        ax[0, j].legend(loc="lower right")
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, tight=False)


def plot_prediction(
    path: str | os.PathLike[str], prediction: dict[str, Any], flown: Trace, model: LinearModel
) -> None:
    """The MPC's predicted velocity and swing at the step against the flight actually flown.

    The prediction is Np steps × axes × [v, swing rate, swing] (``MpcController``'s layout)
    from the tick at ``prediction['t0']``, at the model's dt.
    """
    plt = _pyplot()
    outs = np.asarray(prediction["outputs"])
    axes = len(model.inputs)
    steps = len(outs) // (3 * axes)
    pred = outs[: steps * 3 * axes].reshape(steps, axes, 3)
    tp = prediction["t0"] + model.dt * np.arange(1, steps + 1)
    mask = (flown.t >= tp[0] - model.dt) & (flown.t <= tp[-1])
    fig, ax = plt.subplots(2, 1, figsize=(7, 5.6), sharex=True)
    ax[0].plot(flown.t[mask], flown["vn"][mask], "k", label="flown")
    ax[0].plot(tp, pred[:, 0, 0], "tab:red", ls="--", label="MPC prediction")
    ax[0].set_ylabel("v_N [m/s]")
    # The model predicts the swing it flies on: on the IMU, the estimate.
    swing = "swing_est_n" if swing_source(flown) == "imu" else "swing_n"
    ax[1].plot(flown.t[mask], np.degrees(flown[swing][mask]), "k", label="flown")
    ax[1].plot(tp, np.degrees(pred[:, 0, 2]), "tab:red", ls="--", label="MPC prediction")
    ax[1].set_ylabel(f"{swing} [deg]")
    ax[1].set_xlabel("t [s]")
    for a in ax:
        a.grid(alpha=0.3)
    ax[0].legend()
    fig.suptitle(f"MPC prediction at t = {prediction['t0']:.2f} s vs flown")
    fig.tight_layout()
    save_figure(fig, path, dpi=110, tight=False)


def plot_mission(
    path: str | os.PathLike[str],
    title: str,
    items: list[dict[str, Any]],
    flights: dict[str, tuple[dict[str, Any], list[tuple[float, int, str]]]],
) -> None:
    """A mission seen from above (East right, North up: the vehicle solid, the payload thin,
    each waypoint with its acceptance circle) and the swing from vertical against time with
    each flight's arrivals marked; ``flights``: name → (trace columns, mission events)."""
    from swingrt.mission import true_swing

    plt = _pyplot()
    fig, (top, swing) = plt.subplots(
        1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [1, 1.4]}
    )
    for name, (tr, events) in flights.items():
        color, label = _STYLE.get(name, (None, name))
        line = top.plot(tr["pe"], tr["pn"], color=color, lw=1.4, label=f"{label}: vehicle")
        color = line[0].get_color()
        top.plot(
            tr["payload_pe"],
            tr["payload_pn"],
            color=color,
            lw=0.7,
            alpha=0.7,
            ls="--",
            label=f"{label}: payload",
        )
        sn, se = true_swing(tr)
        swing.plot(tr["t"], np.degrees(np.hypot(sn, se)), color=color, lw=1.0, label=label)
        for t_in, i, kind in events:
            if kind == "reached" and i > 0:
                swing.axvline(t_in, color=color, lw=0.8, ls=":")
    for i, it in enumerate(items):
        n, e = it["position"][0], it["position"][1]
        top.plot(e, n, "kx", ms=7)
        top.annotate(str(i), (e, n), textcoords="offset points", xytext=(5, 5), fontsize=8)
        r = float(it.get("acceptance_radius") or 0.0)
        if r > 0:
            top.add_patch(plt.Circle((e, n), r, fill=False, color="k", lw=0.6))
    top.set_xlabel("East [m]")
    top.set_ylabel("North [m]")
    top.set_aspect("equal", adjustable="datalim")
    top.grid(alpha=0.3)
    top.legend(fontsize=7, loc="best")
    swing.axhline(1.0, color="k", lw=0.6, ls="--")
    swing.set_xlabel("t [s] (dotted: arrival at a waypoint)")
    swing.set_ylabel("swing from vertical [deg]")
    swing.grid(alpha=0.3)
    swing.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, path, dpi=110, tight=False)
