"""``swingrt evaluate``: held-out k-step rollout NMAE of a model on a flight."""

from __future__ import annotations

import argparse
import json


def add_parser(sub) -> argparse.ArgumentParser:
    """Register the subcommand."""
    p = sub.add_parser(
        "evaluate",
        help="score a model on a flight: k-step rollout NMAE per state and mean",
        description="Resamples DATA to the model's dt and runs the model from 10 evenly "
        "spaced start points for a 20 s horizon on the recorded inputs (thesis 4.6.2). A "
        "model identified on the IMU's swing estimate is scored on DATA's IMU run through "
        "the model's own estimator (its scale and observer), whatever DATA's swing source.",
    )
    p.add_argument("model", metavar="MODEL", help="model file (.json)")
    p.add_argument("data", metavar="DATA", help="flight log (.parquet, .csv, .ulg)")
    p.add_argument("--rollout", "--horizon", type=float, default=20.0, help="rollout length [s]")
    p.add_argument("--starts", type=int, default=10, help="number of start points")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    return p


def run(args) -> int:
    """Run the subcommand."""
    from swingrt import sysid
    from swingrt.errors import ConfigError
    from swingrt.io import load_flight

    if args.starts < 1:
        raise ConfigError(f"--starts: must be at least 1 (got {args.starts})")
    model = sysid.LinearModel.load(args.model)
    # A ULog's swing is estimated from its raw IMU by the model's own estimator, when the
    # model's swing is the IMU's estimate (sysid.model_columns).
    data = load_flight(args.data, estimator=sysid.model_estimator(model))
    res = sysid.evaluate(model, data, rollout=args.rollout, starts=args.starts)
    if args.json:
        print(json.dumps(res))
    else:
        per = ", ".join(f"{k} {v:.4f}" for k, v in res["per_state"].items())
        print(f"NMAE {res['nmae']:.4f} ({per})")
    return 0
