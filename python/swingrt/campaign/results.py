"""A campaign's output folder: the stored spec and the Parquet dataset of results.

::

    DIR/spec.toml                       the spec as given (for reading)
    DIR/campaign.json                   the canonical spec and its SHA-256 (for resuming)
    DIR/results/batch-SSSSSS-N.parquet  one file per finished batch (first sample, count)
    DIR/report.md, DIR/*.png            the report (swingrt.campaign.report)

A batch file is written to a hidden temporary file beside it, then renamed
(:func:`swingrt.io.atomic.atomic_path`), so the folder holds only whole batches; a sample's
rows are all in one batch. Reading the dataset therefore says which samples are finished.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from swingrt.campaign.spec import CampaignSpec, spec_difference
from swingrt.errors import ConfigError, DataError
from swingrt.io.atomic import atomic_path, write_text_atomic

#: Columns of known type, the rest (sampled parameters) are inferred.
_TYPES = {
    "sample": "int64",
    "controller": "string",
    "flight_seed": "int64",
    "q": "int64",
    "p": "int64",
    "test_nmae": "float64",
    "control_check_passed": "bool",
    "law": "string",
    "wb_payload_mass": "float64",
    "wb_length": "float64",
    "wb_attitude_lag": "float64",
    "spillover": "string",
    "fallback": "string",
    "error": "string",
    "failure": "string",
}


def results_dir(out: str | os.PathLike[str]) -> Path:
    """The dataset folder of a campaign folder."""
    return Path(out) / "results"


def store_spec(spec: CampaignSpec, out: str | os.PathLike[str], text: str | None = None) -> None:
    """Record the spec in ``out``, or check it against the one recorded there: a different
    spec is refused (:class:`ConfigError` naming the first difference); only ``samples``
    may grow, which extends the study."""
    out = Path(out)
    meta = out / "campaign.json"
    new = spec.canonical()
    if meta.is_file():
        old = json.loads(meta.read_text(encoding="utf-8"))["spec"]
        diff = spec_difference(
            {k: v for k, v in old.items() if k != "samples"},
            {k: v for k, v in new.items() if k != "samples"},
        )
        if diff is None and new["samples"] < old["samples"]:
            diff = f"samples changed from {old['samples']} to {new['samples']} (may only grow)"
        if diff is not None:
            raise ConfigError(
                f"{out}: holds a different campaign ({diff}); use another --out", field="spec"
            )
        if new == old:
            return
    out.mkdir(parents=True, exist_ok=True)
    from swingrt import __version__

    record = {"spec": new, "sha256": spec.digest(), "swingrt": __version__}
    write_text_atomic(meta, json.dumps(record, indent=1, sort_keys=True) + "\n")
    if text is not None:
        write_text_atomic(out / "spec.toml", text)


def stored_spec(out: str | os.PathLike[str]) -> dict[str, Any]:
    """The canonical spec recorded in a campaign folder."""
    meta = Path(out) / "campaign.json"
    if not meta.is_file():
        raise DataError(f"{out}: not a campaign folder (no campaign.json)", path=str(out))
    return dict(json.loads(meta.read_text(encoding="utf-8"))["spec"])


def _table(rows: Sequence[dict[str, Any]]) -> Any:
    import pyarrow as pa

    columns: list[str] = []
    for r in rows:
        for k in r:
            if k not in columns:
                columns.append(k)
    arrays = {}
    for c in columns:
        values = [r.get(c) for r in rows]
        typ = _TYPES.get(c)
        if typ is None and c not in _TYPES:
            from swingrt.campaign.flight import metric_columns

            if c in metric_columns() or c in metric_columns(True):
                typ = "float64"
        arrays[c] = pa.array(values, type=pa.type_for_alias(typ) if typ else None)
    return pa.table(arrays)


def write_batch(out: str | os.PathLike[str], rows: Sequence[dict[str, Any]]) -> Path:
    """Write one batch's rows atomically; returns the file."""
    import pyarrow.parquet as pq

    samples = sorted({int(r["sample"]) for r in rows})
    path = results_dir(out) / f"batch-{samples[0]:06d}-{len(samples)}.parquet"
    with atomic_path(path) as tmp:
        pq.write_table(_table(rows), tmp)
    return path


def clean_partial(out: str | os.PathLike[str]) -> int:
    """Remove the temporary files of batches a killed run left half-written."""
    d = results_dir(out)
    n = 0
    if d.is_dir():
        for f in d.glob(".*.tmp"):
            f.unlink()
            n += 1
    return n


def read_results(out: str | os.PathLike[str]) -> Any:
    """Every finished row as one pyarrow Table sorted by (sample, controller); None when
    the folder has none."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    files = sorted(results_dir(out).glob("batch-*.parquet"))
    if not files:
        return None
    tables = [pq.read_table(f) for f in files]
    table = pa.concat_tables(tables, promote_options="permissive")
    return table.sort_by([("sample", "ascending"), ("controller", "ascending")])


def read_rows(out: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """:func:`read_results` as a list of dicts (empty when none)."""
    t = read_results(out)
    return [] if t is None else list(t.to_pylist())


def finished_samples(out: str | os.PathLike[str]) -> set[int]:
    """The samples with rows in the dataset."""
    import pyarrow.parquet as pq

    done: set[int] = set()
    for f in results_dir(out).glob("batch-*.parquet"):
        done.update(int(s) for s in pq.read_table(f, columns=["sample"])["sample"].to_pylist())
    return done
