"""``swingrt bench``: the on-target performance suite (DESIGN §8)."""

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

    sc = json.dumps(resolve(None, default="step"))
    seconds = 20.0 if quick else 60.0
    runs = [_core.sim_real_time_factor(sc, seconds) for _ in range(3 if quick else 5)]
    return {"median": statistics.median(runs), "runs": runs, "sim_seconds": seconds}


#: Benchmark sections: name → function(quick) -> dict. Other domains append theirs.
SECTIONS = {"sim_rtf": sim_rtf}


def run(args) -> int:
    """Run the subcommand."""
    out: dict = {"machine": platform.machine(), "processor": platform.processor() or None}
    for name, fn in SECTIONS.items():
        out[name] = fn(args.quick)
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
