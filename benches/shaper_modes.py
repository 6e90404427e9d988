"""The fallback shaper on a double pendulum: one mode against two, flown on campaign samples.

For each sample of a campaign spec (the seed given), the training flight is flown and the
white-box identified from it as the campaign does; then the sample's evaluation flight is
flown by PX4 PID and by the white-box model carrying each law in ``control_check.law`` (the
path every flight of a selected model takes): the ZVD shaper of the first mode alone, the two
ZVDs in series for the links the white-box found (when it found them), and the two with the
payload's true second mode (the sample's drawn links, their rate with the vehicle held) in
place of the estimate, and the two with the second peak of the swing's spectrum where the
white-box reports one high enough (``second_peak``, an IMU swing's). Prints each law's
swing excess over PX4's (the campaign's ``swing_excess_vs_pid``) and final velocity error.
``--swing sensor`` flies the samples with the swing sensor instead of the spec's swing
source.

Run:  python benches/shaper_modes.py SPEC.toml SEED IDX[,IDX...] [--swing sensor]
"""

from __future__ import annotations

import argparse
import tomllib
from typing import Any

from swingrt import _core
from swingrt.campaign.flight import EXCESS
from swingrt.campaign.spec import parse_spec
from swingrt.experiments import evaluation_scenario, simulate_controller, training_scenario
from swingrt.experiments.identification import case_vehicle_mass
from swingrt.metrics import step_metrics
from swingrt.sim import collect
from swingrt.sysid import identify


def fly(spec: Any, index: int) -> dict[str, Any]:
    """One sample's laws on its evaluation flight."""
    values = spec.draw(index)
    seed = spec.flight_seed(index)
    exp = spec.experiment(values, label=f"#{index}")
    train_sc = training_scenario(exp, {}, seed)
    train = collect(train_sc, progress=False)
    known = case_vehicle_mass(exp, train_sc)
    mass = {} if known is None else {"vehicle_mass": known}
    wb = identify(train, method="whitebox", axes=exp.axes, **mass)
    w = wb.diagnostics["whitebox"]
    pendulum = {"m_q": w["vehicle_mass"], "m_p": w["payload_mass"], "l": w["length"]}
    omega, zeta = _core.swing_mode(
        params={**pendulum, "c": w["friction"]}, dt=wb.dt, px4=train_sc.to_dict()["controller"]
    )
    one = {
        "kind": "shaper",
        "mode": {"omega": omega, "zeta": zeta},
        "settings": {"kind": "zvd", "period": 0.02},
    }
    laws = {"one mode": one}
    if w.get("links"):
        laws["two, estimated"] = {**one, "second": {"omega": w["links"]["second_mode"], "zeta": 0}}
    peak = w.get("second_peak")
    if peak and peak["shown"]:
        laws["two, spectral"] = {**one, "second": {"omega": peak["omega"], "zeta": 0.0}}
    if values.get("payload.kind") == "double":
        mu = values["payload.mass2"] / values["payload.mass"]
        _, true, _ = _core.sysid_link_modes(values["payload.length"], values["payload.length2"], mu)
        laws["two, true"] = {**one, "second": {"omega": true, "zeta": 0.0}}
    ev = evaluation_scenario(exp, {}, seed + 1, train_sc)
    pid_trace, _ = simulate_controller(ev, "pid", axes=exp.axes)
    pid = step_metrics(pid_trace, t0=exp.step["t"], axis="n")[EXCESS]
    out: dict[str, Any] = {"kind": values.get("payload.kind"), "links": bool(w.get("links"))}
    for name, law in laws.items():
        model = wb.with_diagnostics({"control_check": {"passed": True, "law": law}})
        trace, _ = simulate_controller(ev, "mpc", axes=exp.axes, model=model)
        m = step_metrics(trace, t0=exp.step["t"], axis="n")
        out[name] = (m[EXCESS] / pid, m["ss_error"])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec")
    ap.add_argument("seed", type=int)
    ap.add_argument("samples", help="comma-separated sample indices")
    ap.add_argument("--swing", choices=["sensor", "imu"], help="override the swing source")
    args = ap.parse_args()
    with open(args.spec, "rb") as f:
        raw = tomllib.load(f)
    raw["seed"] = args.seed
    if args.swing:
        raw["base"].setdefault("common", {}).setdefault("sensors", {})["swing"] = args.swing
    spec = parse_spec(raw)
    names = ("one mode", "two, estimated", "two, spectral", "two, true")
    print("| sample | payload | links found | " + " | ".join(names) + " |")
    print("|---:|---|---|" + "---|" * len(names))
    for index in (int(i) for i in args.samples.split(",")):
        r = fly(spec, index)
        cells = [f"{r[n][0]:.3f}× ({r[n][1]:.4f} m/s)" if n in r else "—" for n in names]
        print(
            f"| {index} | {r['kind']} | {'yes' if r['links'] else 'no'} | "
            + " | ".join(cells)
            + " |"
        )


if __name__ == "__main__":
    main()
