"""The white-box's cable length on flights with nothing on the cable, against the true one.

Flies the training flights of a campaign spec's samples (the spec's draws and seeds, as
``swingrt campaign`` flies them), identifies the white-box on each with the payload mass
from the thrust, and prints, by payload kind and mass band, the length's error over the
true first link: as the white-box takes it (``diagnostics.whitebox.length``) and as the
single pendulum fitted to the flown IMU estimate gives it
(``diagnostics.whitebox_length.swing_fit_length``, where the white-box took the scale fit's
length instead). Medians and 90th percentiles of the absolute error. For a double pendulum
the first link is not the single pendulum either length describes; its rows are printed for
completeness. Each cell: the median error, then the 90th percentile of its size.

    python benches/imu_cable_length.py examples/campaigns/robustness-imu.toml --samples 96
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec", help="a campaign spec whose flights have nothing on the cable")
    ap.add_argument("--samples", type=int, default=96, help="the spec's first N samples")
    ap.add_argument("--seed", type=int, help="the spec's seed replaced by this one")
    args = ap.parse_args()

    from swingrt import sysid
    from swingrt.campaign.spec import parse_spec
    from swingrt.experiments import training_scenario
    from swingrt.sim import _run

    raw = tomllib.loads(Path(args.spec).read_text(encoding="utf-8"))
    if args.seed is not None:
        raw["seed"] = args.seed
    spec = parse_spec(raw)
    rows = []
    for idx in range(min(args.samples, spec.samples)):
        values = spec.draw(idx)
        exp = spec.experiment(values, label=f"#{idx}")
        flight = _run(training_scenario(exp, {}, spec.flight_seed(idx)), False, "collect")
        if sysid.swing_source(flight) != "imu":
            raise SystemExit(f"sample {idx}: the flight has a swing sensor; give an IMU study")
        mass = sysid.estimate_payload_mass(flight, vehicle_mass=0.952, skip=60.0)
        wb = sysid.identify(flight, method="whitebox", payload_mass=mass)
        taken = wb.diagnostics["whitebox"]["length"]
        why = wb.diagnostics.get("whitebox_length") or {}
        swing_fit = why.get("swing_fit_length", taken)
        true = values["payload.length"]
        rows.append(
            (values["payload.kind"], values["payload.mass"], taken / true - 1, swing_fit / true - 1)
        )
        print(f"sample {idx:3d}: {values['payload.kind']:6s} {values['payload.mass']:.2f} kg on "
              f"{true:.2f} m: white-box {taken:.3f} m, swing's own fit {swing_fit:.3f} m",
              flush=True)  # fmt: skip
    print("\n| payload | mass [kg] | flights | white-box | swing's own fit |")
    print("|---|---|---:|---|---|")
    for kind in ("single", "double"):
        for lo, hi in ((0.05, 0.2), (0.2, 0.35), (0.35, 0.51)):
            sel = [r for r in rows if r[0] == kind and lo <= r[1] < hi]
            if not sel:
                continue
            cells = []
            for j in (2, 3):
                e = np.array([r[j] for r in sel])
                cells.append(f"{np.median(e):+.1%}, {np.quantile(np.abs(e), 0.9):.1%}")
            print(f"| {kind} | {lo}–{min(hi, 0.5)} | {len(sel)} | {cells[0]} | {cells[1]} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
