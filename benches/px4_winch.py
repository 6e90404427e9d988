"""The adaptive MPC on real PX4 firmware when the cable is winched in: ``swingrt fly --adapt``'s
node, PX4 SITL with swingrt's physics in the loop (``swingrt hil``).

Three PX4 sessions, each started as ``swingrt run --px4`` starts them:

1. the 300 s random-step training flight with 0.2 kg on 1.0 m; the model is identified from
   PX4's own ULog and selected on the twin PX4's parameters describe (as ``run --px4``);
2. the same training flight on 0.4 m: the reference, "the MPC identified at 0.4 m";
3. the evaluation session on 1.0 m, the winch reeling the cable in to 0.4 m at 0.3 m/s 10 s
   after the vehicle holds in the air (the hil server counts payload events from then):
   - the adaptive MPC on the 1.0 m model (the offboard node's ``load_controller(adapt=True)``,
     the twin path from the model's own twin) hovers 40 s (the winch runs in it), then flies
     the 2 m/s North step for 18 s and back;
   - then on the 0.4 m cable, the same step with the MPC identified at 0.4 m, PX4's velocity
     control (PID), and the 1.0 m model without adaptation (what the winch does to a fixed
     MPC; the swing watchdog at 30° is its last resort).

Every flight is judged on the physics trace's true swing. Prints each flight's swing excess
IAE over its step window, the adaptive MPC's ratio to the 0.4 m MPC's (the issue's bar:
≤ 1.5x) and its events (adopted models, with the cable length the twin re-identified for).

    python benches/px4_winch.py PX4_BUILD_DIR [--out DIR] [--training 300] [--instance 5] [--reuse]
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from pathlib import Path

#: The adaptive flight: hover 40 s (the winch runs in it), 2 m/s North for 18 s, back.
ADAPT_STEP_AT = 40.0
ADAPT_MISSION = [(0.0, 0.0, 0.0), (ADAPT_STEP_AT, 2.0, 0.0), (ADAPT_STEP_AT + 18.0, 0.0, 0.0)]
ADAPT_DURATION = ADAPT_STEP_AT + 28.0
#: The winch: from 10 s after the take-off hold, 1.0 → 0.4 m at 0.3 m/s.
WINCH = {"t": 10.0, "action": "winch", "length": 0.4, "rate": 0.3}


def _scenario(path: Path, length: float, winch: bool) -> Path:
    text = f"[payload]\nmass = 0.2\nlength = {length}\n"
    if winch:
        text += "\n[[payload.events]]\n" + "".join(
            f"{k} = {json.dumps(v)}\n" for k, v in WINCH.items()
        )
    path.write_text(text, encoding="utf-8")
    return path


def _train(px4, out: Path, name: str, length: float, args) -> Path:
    """One training session and the model selected from PX4's ULog on its twin."""
    from swingrt import sysid
    from swingrt.hil.params import vehicle_from_px4
    from swingrt.hil.session import HilSession
    from swingrt.io import load_flight
    from swingrt.io.px4_params import read_px4_parameters
    from swingrt.mavlink.training import collect_over_mavlink

    sc = _scenario(out / f"{name}.toml", length, winch=False)
    print(f"[ px4 ] training flight on {length} m ({args.training:g} s)", file=sys.stderr)
    with HilSession(
        px4, scenario=sc, instance=args.instance, workdir=out / f"px4-{name}", seed=args.seed
    ) as hil:
        collect_over_mavlink(
            hil.onboard_url,
            duration=args.training,
            seed=args.seed,
            out=out / f"{name}__node.parquet",
        )
    ulog = out / f"{name}.ulg"
    shutil.copyfile(hil.ulogs[-1], ulog)
    data = load_flight(ulog)
    twin, _notes = vehicle_from_px4(read_px4_parameters(ulog))
    model = sysid.select_for_control(data, sysid.search(data), twin=twin).model
    path = out / f"{name}__model.json"
    model.save(path)
    print(f"[ identification ] {name}: q = {model.delays}, p = {model.rank}", file=sys.stderr)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("px4", help="PX4 SITL build folder")
    ap.add_argument("--out", default="runs/px4-winch")
    ap.add_argument("--training", type=float, default=300.0)
    ap.add_argument("--instance", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--reuse", action="store_true", help="fly the models an earlier run left in --out"
    )
    args = ap.parse_args(argv)

    from swingrt.hil.pipeline import (
        SETTLE_S,
        STEP_DURATION,
        STEP_MISSION,
        fly_offboard,
        judge_on_truth,
    )
    from swingrt.hil.px4 import check_px4_dir
    from swingrt.hil.session import HilSession
    from swingrt.io.flight import Trace
    from swingrt.mavlink.offboard import Mission, load_controller
    from swingrt.mavlink.training import fly_velocity_mission
    from swingrt.metrics import step_metrics

    check_px4_dir(args.px4)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    at_1m, at_04m = (out / f"train-{m}__model.json" for m in ("1.0m", "0.4m"))
    if not (args.reuse and at_1m.is_file() and at_04m.is_file()):
        at_1m = _train(args.px4, out, "train-1.0m", 1.0, args)
        at_04m = _train(args.px4, out, "train-0.4m", 0.4, args)

    sc = _scenario(out / "winch.toml", 1.0, winch=True)
    step = Mission(list(STEP_MISSION), STEP_DURATION)
    flights: dict[str, tuple[Path, float, str | None]] = {}
    adaptive = None
    with HilSession(
        args.px4,
        scenario=sc,
        instance=args.instance,
        workdir=out / "px4-flights",
        log=out / "flights_physics.parquet",
        seed=args.seed + 1,
    ) as hil:
        url = hil.onboard_url
        print("[ px4 ] adaptive MPC (1.0 m model), winch to 0.4 m in hover", file=sys.stderr)
        adaptive, ts, axes = load_controller(at_1m, adapt=True)
        path = out / "mpc_adaptive.parquet"
        mission = Mission(list(ADAPT_MISSION), ADAPT_DURATION)
        why = fly_offboard(url, adaptive, ts=ts, axes=axes, mission=mission, path=path)
        flights["mpc_adaptive"] = (path, ADAPT_STEP_AT, why)
        for name, model in (("mpc_0.4m", at_04m), ("mpc_fixed_1.0m", at_1m)):
            time.sleep(SETTLE_S)
            print(f"[ px4 ] {name} on the 0.4 m cable", file=sys.stderr)
            ctrl, ts, axes = load_controller(model)
            path = out / f"{name}.parquet"
            why = fly_offboard(url, ctrl, ts=ts, axes=axes, mission=step, path=path)
            flights[name] = (path, 2.0, why)
            if name == "mpc_0.4m":
                time.sleep(SETTLE_S)
                print("[ px4 ] pid on the 0.4 m cable", file=sys.stderr)
                path = out / "pid.parquet"
                fly_velocity_mission(url, step, out=path)
                flights["pid"] = (path, 2.0, None)
    physics = Trace.from_parquet(out / "flights_physics.parquet")
    rows = {}
    for name, (path, t0, why) in flights.items():
        if not path.exists():
            rows[name] = {"aborted": why}
            continue
        tr = Trace.from_parquet(path)
        judge_on_truth(tr, physics)
        m = step_metrics(tr, t0=t0, axis="n", t_end=t0 + 18.0)
        rows[name] = {**m, "aborted": why}
    ref = rows.get("mpc_0.4m", {}).get("swing_excess_iae_deg_s", math.nan)
    print("| flight | swing excess IAE [deg·s] | x MPC at 0.4 m | peak swing [deg] | aborted |")
    print("|---|---:|---:|---:|---|")
    for name, r in rows.items():
        e = r.get("swing_excess_iae_deg_s", math.nan)
        print(
            f"| {name} | {e:.3g} | {e / ref:.3g} | {r.get('peak_swing_deg', math.nan):.3g} "
            f"| {r['aborted'] or ''} |"
        )
    events = adaptive.events() if adaptive is not None else []
    print("adaptive events (tick, what, value):", events)
    if adaptive is not None and adaptive.last_rejection:
        print("last rejection:", adaptive.last_rejection)
    (out / "summary.json").write_text(
        json.dumps({"rows": rows, "events": events}, indent=1, default=str), encoding="utf-8"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
