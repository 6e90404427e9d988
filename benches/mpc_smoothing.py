"""A campaign sample's MPC with a smoother command, on its own flight and on the heaviest
second link the swing's spectrum allows.

For each sample of a flown campaign (its folder), the sample is flown again as
``swingrt campaign --rerun`` does (the selected model lands in ``rerun/sample-N/``), then
its evaluation flight is flown by PX4 PID and by that model's MPC with the default
settings and with a smoother one: a larger input-rate weight (``w_acc_rate``) and a larger
swing measurement noise (``kf_swing_measurement_noise``: the filter trusts the swing less
above the first mode). The selected model may carry the selection's own smooth design
already (``control_check.spillover``, ``diagnostics.acc_rate_weight``); its settings are
floors, so "default" is the model as selected. Where the white-box recorded a second
peak of the swing's spectrum (``whitebox.second_peak``), both are also flown with the
payload replaced by the double pendulum whose modes with the vehicle held are the
white-box's √(g/l) and that peak, with the heaviest lower link those two rates allow
(equal lengths) and the white-box's total mass: a plant that carries the mode the MPC can
excite unseen.

Prints each flight's swing excess over PX4's (the campaign's ``swing_excess_vs_pid``), the
command's total variation, the velocity settle time and whether the campaign would count
it a failure.

Run:  python benches/mpc_smoothing.py RUN_DIR IDX[,IDX...] [--acc-rate 24] [--swing-noise 0.05]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from swingrt import _core
from swingrt.campaign.flight import EXCESS, RATIO, failure_reason, fly_noise_draws
from swingrt.campaign.results import stored_spec
from swingrt.campaign.spec import parse_spec
from swingrt.experiments import evaluation_scenario, simulate_controller, training_scenario
from swingrt.metrics import step_metrics


def heaviest_second_link(whitebox: dict[str, Any]) -> dict[str, Any] | None:
    """The double pendulum of the white-box's first mode and its spectrum's second peak
    with the heaviest lower link the two rates allow (equal lengths; the core's
    ``sysid::links::heaviest_links``, the plant the selection's second link flies), or None
    without a peak."""
    peak = whitebox.get("second_peak")
    if not peak:
        return None
    links = _core.sysid_heaviest_links(math.sqrt(_core.GRAVITY / whitebox["length"]), peak["omega"])
    if links is None:
        return None
    length, ratio = links
    mass = whitebox["payload_mass"]
    return {
        "kind": "double",
        "mass": mass / (1.0 + ratio),
        "mass2": mass * ratio / (1.0 + ratio),
        "length": length,
        "length2": length,
    }


def fly(
    folder: str, raw: dict[str, Any], spec: Any, index: int, smooth: dict[str, float]
) -> dict[str, Any]:
    """One sample of the campaign in ``folder`` (its stored spec ``raw``, parsed ``spec``):
    its MPC with the default and the smooth settings, on its own flight and (with a
    spectral peak) on the heaviest second link."""
    out_dir = Path(folder) / "rerun" / f"sample-{index:06d}"
    fly_noise_draws(raw, index, 1, out_dir)
    model = _core.LinearModel.load(str(out_dir / "model.json"))
    whitebox = json.loads((out_dir / "whitebox.json").read_text())["diagnostics"]["whitebox"]
    values = spec.draw(index)
    seed = spec.flight_seed(index)
    exp = spec.experiment(values, label=f"#{index}")
    own = evaluation_scenario(exp, {}, seed + 1, training_scenario(exp, {}, seed))
    plants = {"own flight": own}
    link = heaviest_second_link(whitebox)
    if link is not None:
        plants["heaviest second link"] = own.with_overrides({"payload": link})
    result: dict[str, Any] = {"kind": values.get("payload.kind"), "flights": {}}
    for plant, sc in plants.items():
        pid_trace, _ = simulate_controller(sc, "pid", axes=exp.axes)
        pid = step_metrics(pid_trace, t0=exp.step["t"], axis="n")[EXCESS]
        for name, settings in (("default", None), ("smooth", smooth)):
            trace, extras = simulate_controller(
                sc, "mpc", axes=exp.axes, model=model, mpc_settings=settings
            )
            m = step_metrics(trace, t0=exp.step["t"], axis="n")
            row = {
                **m,
                "controller": "mpc",
                RATIO: m[EXCESS] / pid if pid > 0 else math.inf,
                "fallback": extras.get("fallback") or "",
            }
            result["flights"][(plant, name)] = row | {"failure": failure_reason(row)}
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", help="a flown campaign's folder")
    ap.add_argument("samples", help="comma-separated sample indices")
    ap.add_argument("--acc-rate", type=float, default=24.0, help="smooth w_acc_rate")
    ap.add_argument("--swing-noise", type=float, default=0.05, help="smooth swing noise [rad]")
    args = ap.parse_args()
    smooth = {"w_acc_rate": args.acc_rate, "kf_swing_measurement_noise": args.swing_noise}
    print(f"smooth: {smooth}")
    print(
        "| sample | payload | plant | settings | swing vs PX4 | command TV | v settle [s] | fails |"
    )
    print("|---:|---|---|---|---:|---:|---:|---|")
    raw = stored_spec(args.run)
    spec = parse_spec(raw, f"{args.run}/campaign.json")
    for index in (int(i) for i in args.samples.split(",")):
        r = fly(args.run, raw, spec, index, smooth)
        for (plant, name), f in r["flights"].items():
            print(
                f"| {index} | {r['kind']} | {plant} | {name} | "
                f"{f[RATIO]:.3f}× | {f['acc_sp_tv']:.1f} | "
                f"{f['v_settle_s']:.2f} | {f['failure'] or '—'} |"
            )


if __name__ == "__main__":
    main()
