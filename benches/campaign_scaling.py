"""Campaign throughput with 1 and 2 (or N) local Dask workers on the same study.

Runs SPEC (optionally cut to --samples) into fresh folders once per worker count, prints
samples/s and flights/s (one flight = one controller flown on one sample; the training
flight and identification of a sample count towards its flights) of each run, the speedup
over one worker, and checks every run produced the same rows.

    python benches/campaign_scaling.py examples/campaigns/robustness.toml            # 500 samples
    python benches/campaign_scaling.py examples/campaigns/robustness.toml --samples 16

Measure on an otherwise idle machine: the issue's bar is >= 1.7x with 2 workers on a
2-core machine for the 500-sample robustness study.
"""

from __future__ import annotations

import argparse
import copy
import math
import tempfile
from pathlib import Path

from swingrt.campaign import parse_spec, read_rows, run_campaign
from swingrt.campaign.spec import check_spec
from swingrt.scenario import read_toml


def _same(a: list[dict], b: list[dict]) -> bool:
    if len(a) != len(b):
        return False
    for ra, rb in zip(a, b, strict=True):
        for k, v in ra.items():
            w = rb.get(k)
            nan = isinstance(v, float) and isinstance(w, float) and math.isnan(v) and math.isnan(w)
            if not nan and v != w:
                return False
    return True


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec", help="campaign spec (TOML)")
    ap.add_argument("--samples", type=int, help="fly only this many samples")
    ap.add_argument("--workers", default="1,2", help="worker counts to compare (default 1,2)")
    ap.add_argument("--keep", help="keep the runs in this folder (default: a temp folder)")
    args = ap.parse_args()
    raw = copy.deepcopy(read_toml(args.spec))
    if args.samples:
        raw["samples"] = args.samples
    spec = parse_spec(raw, args.spec)
    check_spec(spec, args.spec)
    counts = [int(w) for w in args.workers.split(",")]
    per = len(spec.controllers)
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(args.keep or tmp)
        results = {}
        for n in counts:
            out = base / f"workers-{n}"
            s = run_campaign(spec, out, workers=n, progress=False, report=False)
            rate = s["flown"] / s["seconds"]
            results[n] = (rate, read_rows(out))
            print(
                f"workers {n}: {s['flown']} samples in {s['seconds']:.1f} s = {rate:.3f} "
                f"samples/s = {rate * per:.3f} flights/s (batch {s.get('batch')}, workers "
                f"busy {s.get('utilisation', 0.0):.0%})",
                flush=True,
            )
        one = results[counts[0]]
        for n in counts[1:]:
            same = _same(one[1], results[n][1])
            print(
                f"speedup {n} vs {counts[0]} worker(s): {results[n][0] / one[0]:.2f}x; "
                f"rows {'identical' if same else 'DIFFER'}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
