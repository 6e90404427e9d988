"""What a campaign's MPC would score if, where no candidate passed the selection's check, it
flew another law instead of the least-violating model: the counterfactual read from one run.

The campaign must fly both: ``controllers`` holds ``mpc`` and the law (say ``shaper``, the
ZVD input shaper of PX4's velocity setpoint, with ``[base.shaper] source = "whitebox"``: the
pendulum the white-box fitted to the training flight). Every controller of a sample flies the
same evaluation (the same noise seed, judged against the same PX4 PID flight), so the rule's
row of a sample is the MPC's row where its model passed the check and the law's row where
none passed: no flight is simulated here. Prints, for the MPC, the law and the rule, the
failures with their 95 % Wilson interval and the median swing excess over PX4's, split by
whether the check passed and by the payload's kind, and every sample the rule changes
(righted or broken).

The selection now takes the ZVD shaper itself where no candidate's MPC passes and the shaper
passes on the twin (``[selection] fallback``, the ``law`` column): a run that flew it has no
counterfactual to read, so this reads runs flown with ``fallback = "none"`` (or before the
rule) and refuses the others.

Run:  python benches/fallback_law.py RUN [--law shaper]
"""

from __future__ import annotations

import argparse
import math
import statistics
from collections import Counter
from pathlib import Path
from typing import Any

from swingrt.campaign import read_rows
from swingrt.campaign.flight import RATIO
from swingrt.campaign.report import wilson


def _line(name: str, rows: list[dict[str, Any]]) -> str:
    n = len(rows)
    failed = [r for r in rows if r["failure"]]
    lo, hi = wilson(len(failed), n) if n else (math.nan, math.nan)
    ratios = [r[RATIO] for r in rows if not math.isnan(r.get(RATIO, math.nan))]
    why = Counter(r["failure"] for r in failed)
    return (
        f"{name:34s} {len(failed):3d} of {n:3d} ({100 * len(failed) / max(n, 1):.1f} % "
        f"[{100 * lo:.1f}, {100 * hi:.1f}])  median excess {statistics.median(ratios):.3f}x  "
        + ", ".join(f"{k} {v}" for k, v in sorted(why.items()))
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", help="a campaign's output folder")
    ap.add_argument("--law", default="shaper", help="the controller flown where none passed")
    args = ap.parse_args()
    if not (Path(args.run) / "results").is_dir():
        raise SystemExit(f"{args.run}: not a campaign's output folder (no results/ in it)")
    by: dict[int, dict[str, dict[str, Any]]] = {}
    for r in read_rows(args.run):
        by.setdefault(int(r["sample"]), {})[r["controller"]] = r
    pairs = [
        (i, c["mpc"], c[args.law]) for i, c in sorted(by.items()) if {"mpc", args.law} <= c.keys()
    ]
    if not pairs:
        raise SystemExit(f"{args.run}: no sample has both an mpc and a {args.law} row")
    ruled = [i for i, m, _ in pairs if m.get("law") not in (None, "mpc")]
    if ruled:
        raise SystemExit(
            f"{args.run}: its selection flew a fallback law already (samples {ruled[:5]}...); "
            'fly the study with [selection] fallback = "none" to read the counterfactual'
        )
    none = [(i, m, w) for i, m, w in pairs if m.get("control_check_passed") is False]
    rule = [w if m.get("control_check_passed") is False else m for _, m, w in pairs]
    print(f"{args.run}: {len(pairs)} samples, {len(none)} where no candidate passed the check")
    print(_line("mpc", [m for _, m, _ in pairs]))
    print(_line("mpc, no candidate passed", [m for _, m, _ in none]))
    print(
        _line("mpc, passed", [m for _, m, _ in pairs if m.get("control_check_passed") is not False])
    )
    print(_line(f"{args.law}", [w for _, _, w in pairs]))
    print(_line(f"{args.law}, no candidate passed", [w for _, _, w in none]))
    print(_line(f"rule: {args.law} where none passed", rule))
    if "pid" in next(iter(by.values())):
        print(_line("pid", [c["pid"] for c in by.values() if "pid" in c]))
    kinds = sorted({str(m.get("payload.kind")) for _, m, _ in pairs})
    if len(kinds) > 1:
        for k in kinds:
            mine = [(m, w) for _, m, w in pairs if str(m.get("payload.kind")) == k]
            print(_line(f"mpc, payload {k}", [m for m, _ in mine]))
            print(_line(f"{args.law}, payload {k}", [w for _, w in mine]))
    for i, m, w in none:
        if bool(m["failure"]) != bool(w["failure"]):
            what = "righted" if m["failure"] else "broken "
            print(
                f"  {what} sample {i}: mpc {m[RATIO]:.3f}x {m['failure'] or 'ok'} -> "
                f"{args.law} {w[RATIO]:.3f}x {w['failure'] or 'ok'}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
