"""``swingrt bench``: the on-target performance suite."""

from __future__ import annotations

import argparse
import json
import platform
import statistics


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser("bench", help="measure simulation, identification and MPC speed here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quick", action="store_true", help="shorter runs (less precise)")
    return p


def sim_rtf(quick: bool) -> dict:
    """Real-time factor of the full loop with payload at 1 ms physics, median of runs."""
    from swingrt import _core
    from swingrt.scenario import resolve

    sc = resolve(None, default="step")
    seconds = 20.0 if quick else 60.0
    runs = [_core.sim_real_time_factor(sc, seconds) for _ in range(3 if quick else 5)]
    return {"median": statistics.median(runs), "runs": runs, "sim_seconds": seconds}


def _timeit(fn, repeat: int) -> list[float]:
    import time

    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def sysid(quick: bool) -> dict:
    """One DMDc fit (q = 50, 120 s at 0.03 s, one axis) and the reference grid (q = 2…60
    step 2 × p = 5…full rank step 5 with the affine column, 10 rollouts of 20 s), on a
    simulated flight, plus the default search of ``identify --search``."""
    import numpy as np

    from swingrt import _core
    from swingrt.sim import collect
    from swingrt.sysid import resample, search

    dt = 0.03
    trace = collect(duration=160.0, seed=11)
    cols = resample(trace.columns, dt, names=["vn", "swing_n", "acc_sp_n"])
    x = np.ascontiguousarray(np.column_stack([cols["vn"], cols["swing_n"]]))
    u = np.ascontiguousarray(cols["acc_sp_n"][:, None])
    k = int(round(40.0 / dt))
    names = (["vn", "swing_n"], ["acc_sp_n"])
    xtr, utr = np.ascontiguousarray(x[k:]), np.ascontiguousarray(u[k:])
    one_fit = {"delays": 50, "rank": 40, "offset": "affine", "dt": dt, "test_span": 0.0}
    fit = _timeit(lambda: _core.identify(xtr, utr, *names, one_fit), 10 if quick else 30)
    reference = {
        "search": True,
        "offset": "affine",
        "dt": dt,
        "test_span": 40.0,
        "rollout": 20.0,
        "starts": 10,
        "search_delays": list(range(2, 61, 2)),
        "rank_start": 5,
        "rank_step": 5,
        "fine": None,
    }
    grid = _timeit(lambda: _core.identify(x, u, *names, reference), 2 if quick else 5)
    _, found = _core.identify(x, u, *names, reference)
    candidates = len(found.table()) if found is not None else 0
    default = _timeit(lambda: search(trace, dt=dt), 1 if quick else 3)
    return {
        "dmdc_fit_ms": statistics.median(fit) * 1e3,
        "dmdc_search_s": statistics.median(grid),
        "dmdc_search_default_s": statistics.median(default),
        "dmdc_search_candidates": candidates,
        "training_samples": int(len(xtr)),
    }


def mpc(quick: bool) -> dict:
    """One MPC tick (Kalman update included) at q = 50, Np = 120, Nc = 20, one and two axes,
    unconstrained and with an active acceleration bound, active-set and Clarabel QP."""
    from swingrt import _core

    n = 500 if quick else 3000
    out: dict = {}
    for axes, key in ((1, "mpc_step_us"), (2, "mpc_step_us_two_axes")):
        model = _core.pendulum_model(delays=50, axes=axes)
        res: dict = {}
        for label, constrained, solver in (
            ("unconstrained", False, "active_set"),
            ("constrained", True, "active_set"),
            ("constrained_clarabel", True, "clarabel"),
        ):
            settings = {"horizon": 120, "control_horizon": 20, "solver": solver}
            t = _core.mpc_tick_timing(model, settings, n_ticks=n, constrained=constrained)
            res[label] = {"median": t["median"], "p99": t["p99"]}
        out[key] = res
    return out


def adaptive(quick: bool) -> dict:
    """The adaptive MPC at q = 20 (default MPC and adaptive settings, one axis): one tick with
    the online DMDc update, and one re-synthesis (model from the factor, MPC design,
    closed-loop check) off the tick path."""
    from swingrt import _core

    model = _core.pendulum_model(delays=20, axes=1)
    t = _core.adaptive_timing(model, n_ticks=500 if quick else 3000, repeats=3 if quick else 10)
    return {
        "adaptive_tick_us": {"median": t["tick_us"]["median"], "p99": t["tick_us"]["p99"]},
        "adaptive_resynthesis_ms": {
            "median": t["resynthesis_ms"]["median"],
            "max": t["resynthesis_ms"]["max"],
        },
    }


#: Benchmark sections: name → function(quick) -> dict. Other domains append theirs.
SECTIONS = {"sim_rtf": sim_rtf, "sysid": sysid, "mpc": mpc, "adaptive": adaptive}


def run(args) -> int:
    """Run the subcommand."""
    out: dict = {"machine": platform.machine(), "processor": platform.processor() or None}
    for name, fn in SECTIONS.items():
        res = fn(args.quick)
        # Flat figures (dmdc_fit_ms, …) sit at the top level, as the README names them.
        if name in ("sysid", "mpc", "adaptive"):
            out.update(res)
        else:
            out[name] = res
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        for name, res in out.items():
            if isinstance(res, dict) and "median" in res:
                print(f"{name}: {res['median']:.1f} (median)")
            elif isinstance(res, dict):
                print(f"{name}: {json.dumps(res)}")
            else:
                print(f"{name}: {res}")
    return 0
