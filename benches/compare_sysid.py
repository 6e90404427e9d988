"""Time DMDc identification: swingrt (Rust core) vs numpy vs PyDMD.

Same work in each: one DMDc fit (q = 50, rank 40, 120 s at Ts = 0.03 s, one axis
[vn, swing_n] <- acc_sp_n, input mean subtracted), and the reference grid q = 2..60 step 2
x p = 5..(2q+1) step 5 (366 candidates), each scored by 10 rollouts of 20 s on a held-out
40 s span with the per-q best candidate screened for stability. numpy uses one SVD per q
and batched rollouts over the 10 start points; PyDMD (if installed) refits every candidate
on the delay-embedded data. Data: a seeded pendulum-like flight (the white-box model under a
velocity P loop with random steps and a setpoint offset).

Run:  python benches/compare_sysid.py [--repeat N]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from swingrt import _core

DT = 0.03
Q_FIT, P_FIT = 50, 40
GRID_Q = list(range(2, 61, 2))
HORIZON = int(round(20.0 / DT))
STARTS = 10


def flight(seconds: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """States (N, 2) = [v, swing] and inputs (N, 1) of the synthetic flight."""
    g, mq, mp, length, c = 9.81, 0.952, 0.2, 1.0, 0.002
    a = np.array(
        [
            [0, c / (length * mq), g * mp / mq],
            [0, -c * (mq + mp) / (length**2 * mq * mp), -g * (mq + mp) / (length * mq)],
            [0, 1, 0],
        ]
    )
    b = np.array([1.0, -1.0 / length, 0.0])
    rng = np.random.default_rng(seed)
    steps = int(seconds / DT)
    s = np.zeros(3)
    vref, change = 0.0, 0
    xs, us = np.zeros((steps, 2)), np.zeros((steps, 1))
    for k in range(steps):
        if k >= change:
            vref = rng.uniform(0, 3)
            change = k + int(rng.uniform(10, 25) / DT)
        acc = float(np.clip(1.8 * (vref - s[0]), -4, 4) + 0.05 * rng.uniform(-1, 1))
        xs[k] = s[0] + 0.002 * rng.uniform(-1, 1), s[2] + 0.001 * rng.uniform(-1, 1)
        us[k] = acc + 0.1
        for _ in range(3):  # RK4 substeps of DT/3
            h = DT / 3
            k1 = a @ s + b * acc
            k2 = a @ (s + h / 2 * k1) + b * acc
            k3 = a @ (s + h / 2 * k2) + b * acc
            k4 = a @ (s + h * k3) + b * acc
            s = s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return xs, us


def omega(x: np.ndarray, u: np.ndarray, q: int, first: int):
    """Omega = [X; X_d; Upsilon] (features x samples) and X' for samples k >= first."""
    n = x.shape[1]
    ks = np.arange(first, len(x) - 1)
    rows = [x[ks - lag].T for lag in range(q)]
    om = np.vstack([*rows, u[ks].T])
    return om, x[ks + 1].T, n


def numpy_fit(x, u, q=Q_FIT, p=P_FIT):
    um = u - u.mean(axis=0)
    om, xp, n = omega(x, um, q, q - 1)
    U, S, Vt = np.linalg.svd(om, full_matrices=False)
    return xp @ Vt[:p].T @ np.diag(1 / S[:p]) @ U[:, :p].T


def starts_of(len_test: int, q_max: int) -> np.ndarray:
    lo, hi = q_max - 1, len_test - 1 - HORIZON
    return np.round(lo + (hi - lo) * np.arange(STARTS) / (STARTS - 1)).astype(int)


def rollout_nmae(g, q, n, m, x_test, u_test, starts, mean_u):
    """Batched rollouts of the delay model from all starts; mean NMAE over states."""
    a_top, b_top = g[:, : n * q], g[:, n * q :]
    # History buffer: (time, start, state), newest appended.
    buf = np.zeros((q + HORIZON, len(starts), n))
    for j, s in enumerate(starts):
        buf[:q, j] = x_test[s + 1 - q : s + 1]
    err = np.zeros(n)
    rng_ = x_test.max(axis=0) - x_test.min(axis=0)
    for k in range(HORIZON):
        z = buf[k : k + q][::-1].transpose(1, 0, 2).reshape(len(starts), -1)  # newest first
        uk = u_test[starts + k] - mean_u
        nxt = z @ a_top.T + uk @ b_top.T
        buf[q + k] = nxt
        err += np.abs(nxt - x_test[starts + k + 1]).sum(axis=0)
        if not np.all(np.isfinite(nxt)) or np.abs(nxt).max() > 1e6:
            return np.inf
    return float(np.mean(err / (len(starts) * HORIZON) / rng_))


def numpy_grid(x_tr, u_tr, x_te, u_te):
    mean_u = u_tr.mean(axis=0)
    n, m = x_tr.shape[1], u_tr.shape[1]
    starts = starts_of(len(x_te), max(GRID_Q))
    best = (np.inf, None)
    count = 0
    for q in GRID_Q:
        om, xp, _ = omega(x_tr, u_tr - mean_u, q, max(GRID_Q) - 1)
        U, S, Vt = np.linalg.svd(om, full_matrices=False)
        T = xp @ Vt.T
        scored = []
        for p in range(5, n * q + m + 1, 5):
            g = (T[:, :p] / S[:p]) @ U[:, :p].T
            scored.append((rollout_nmae(g, q, n, m, x_te, u_te, starts, mean_u), p, g))
            count += 1
        for nm, p, g in sorted(scored, key=lambda r: r[0]):
            if not np.isfinite(nm):
                break
            nz = n * q
            a = np.zeros((nz, nz))
            a[:n] = g[:, :nz]
            a[n:, :-n] = np.eye(nz - n)
            if max(abs(np.linalg.eigvals(a))) <= 1 + 1e-3:
                if nm < best[0]:
                    best = (nm, (q, p))
                break
    assert count == 366
    return best


def pydmd_grid(x_tr, u_tr, x_te, u_te):
    """PyDMD DMDc refitted for every candidate on the delay-embedded snapshots."""
    from pydmd import DMDc

    mean_u = u_tr.mean(axis=0)
    n, m = x_tr.shape[1], u_tr.shape[1]
    starts = starts_of(len(x_te), max(GRID_Q))
    best = (np.inf, None)
    for q in GRID_Q:
        ks = np.arange(max(GRID_Q) - 1, len(x_tr))
        z = np.vstack([x_tr[ks - lag].T for lag in range(q)])
        for p in range(5, n * q + m + 1, 5):
            d = DMDc(svd_rank=p)
            d.fit(z, (u_tr[ks[:-1]] - mean_u).T)
            a_full = d.basis @ np.diag(d.eigs) @ np.linalg.pinv(d.basis)
            g = np.hstack([a_full.real[:n], d.B.real[:n]])
            nm = rollout_nmae(g, q, n, m, x_te, u_te, starts, mean_u)
            if nm < best[0]:
                best = (nm, (q, p))
    return best


def pydmd_fit(x, u):
    from pydmd import DMDc

    ks = np.arange(Q_FIT - 1, len(x))
    z = np.vstack([x[ks - lag].T for lag in range(Q_FIT)])
    d = DMDc(svd_rank=P_FIT)
    d.fit(z, (u[ks[:-1]] - u.mean(axis=0)).T)
    return d


def timeit(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="repetitions per timing (median)")
    args = ap.parse_args()
    x, u = flight(120.0, 1)
    x2, u2 = flight(160.0, 2)
    split = int(round(40.0 / DT))
    x_te, u_te, x_tr, u_tr = x2[:split], u2[:split], x2[split:], u2[split:]
    x, u = np.ascontiguousarray(x), np.ascontiguousarray(u)
    names = (["vn", "swing_n"], ["acc_sp_n"])

    one_fit = {"delays": Q_FIT, "rank": P_FIT, "offset": "mean", "dt": DT, "test_span": 0.0}
    grid = {
        "search": True,
        "offset": "mean",
        "dt": DT,
        "test_span": split * DT,
        "rollout": HORIZON * DT,
        "starts": STARTS,
        "search_delays": list(GRID_Q),
        "rank_start": 5,
        "rank_step": 5,
        "fine": None,
    }
    x2c, u2c = np.ascontiguousarray(x2), np.ascontiguousarray(u2)

    def rust_fit():
        _core.identify(x, u, *names, one_fit)

    def rust_grid():
        _, found = _core.identify(x2c, u2c, *names, grid)
        table = found.table()
        return table, found.best

    rows = []
    rows.append(("fit", "swingrt", timeit(rust_fit, args.repeat * 4)))
    rows.append(("fit", "numpy", timeit(lambda: numpy_fit(x, u), args.repeat * 4)))
    table, best = rust_grid()
    rows.append(("grid", "swingrt", timeit(rust_grid, args.repeat)))
    rows.append(("grid", "numpy", timeit(lambda: numpy_grid(x_tr, u_tr, x_te, u_te), 1)))
    try:
        import pydmd  # noqa: F401

        rows.append(("fit", "pydmd", timeit(lambda: pydmd_fit(x, u), args.repeat)))
        rows.append(("grid", "pydmd", timeit(lambda: pydmd_grid(x_tr, u_tr, x_te, u_te), 1)))
    except ImportError:
        print("PyDMD not installed: skipping its timings (pip install pydmd)")
    np_best = numpy_grid(x_tr, u_tr, x_te, u_te)
    print(
        f"swingrt grid selected q = {table[best]['delays']}, p = {table[best]['rank']}, "
        f"NMAE {table[best]['nmae']:.4f}; numpy selected {np_best[1]}, NMAE {np_best[0]:.4f}"
    )
    base = {task: t for task, who, t in rows if who == "swingrt"}
    print(f"{'task':<6}{'tool':<10}{'median':>12}{'vs swingrt':>12}")
    for task, who, t in rows:
        unit = f"{t * 1e3:9.2f} ms" if t < 1 else f"{t:9.3f} s "
        print(f"{task:<6}{who:<10}{unit:>12}{t / base[task]:>11.1f}x")


if __name__ == "__main__":
    main()
