"""Metric tables: ``metrics.csv`` and ``metrics.md`` of an experiment, and CSV text of rows."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

from swingrt.io.atomic import write_text_atomic
from swingrt.metrics import METRICS

__all__ = ["CSV_COLUMNS", "csv_text", "write_metrics"]

#: Columns of ``metrics.csv``.
CSV_COLUMNS = ("scenario", "controller", *METRICS)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "inf" if math.isinf(v) else f"{v:.4g}"
    return str(v)


def csv_text(rows: Iterable[Mapping[str, Any]], columns: Sequence[str]) -> str:
    """``rows`` as CSV text with a header line of ``columns`` (``\\n`` line ends)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


class Titled(Protocol):
    """What a report needs of its experiment: a name and a description."""

    name: str
    description: str


def write_metrics(out: Path, exp: Titled, rows: list[dict[str, Any]], notes: list[str]) -> None:
    """``metrics.csv`` and ``metrics.md`` (atomic)."""
    formatted = [{k: _fmt(r[k]) for k in CSV_COLUMNS} for r in rows]
    write_text_atomic(out / "metrics.csv", csv_text(formatted, CSV_COLUMNS))
    md = [f"# {exp.name}", "", exp.description, ""]
    md.append("| " + " | ".join(CSV_COLUMNS) + " |")
    md.append("|" + "---|" * len(CSV_COLUMNS))
    for r in rows:
        md.append("| " + " | ".join(_fmt(r[k]) for k in CSV_COLUMNS) + " |")
    if notes:
        md += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    write_text_atomic(out / "metrics.md", "\n".join(md) + "\n")
