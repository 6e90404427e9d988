"""Flight traces: named numpy columns (DESIGN §2) with Parquet and CSV on disk."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from swingrt.io.atomic import atomic_path
from swingrt.errors import DataError


class Trace:
    """A flight log: equal-length float columns named as in DESIGN §2, plus metadata."""

    def __init__(self, columns: Mapping[str, Any], meta: dict[str, Any] | None = None):
        cols = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
        lengths = {len(v) for v in cols.values()}
        if len(lengths) > 1:
            raise DataError(f"trace columns differ in length: {sorted(lengths)}")
        if "t" not in cols:
            raise DataError("trace has no time column 't'")
        self.columns: dict[str, np.ndarray] = cols
        self.meta: dict[str, Any] = dict(meta or {})

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.columns[name]
        except KeyError:
            raise DataError(f"trace has no column {name!r}") from None

    def __contains__(self, name: object) -> bool:
        return name in self.columns

    def __len__(self) -> int:
        return len(self.columns["t"])

    def __repr__(self) -> str:
        t = self.columns["t"]
        span = f"{t[0]:.2f}–{t[-1]:.2f} s" if len(t) else "empty"
        return f"Trace({len(self)} rows, {len(self.columns)} columns, {span})"

    @property
    def t(self) -> np.ndarray:
        """Time [s]."""
        return self.columns["t"]

    def to_parquet(self, path: str | os.PathLike) -> None:
        """Write as Parquet (atomically); metadata goes into the schema metadata."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table(self.columns)
        table = table.replace_schema_metadata({"swingrt": json.dumps(self.meta)})
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp)

    def to_csv(self, path: str | os.PathLike) -> None:
        """Write as CSV with a header row (atomically)."""
        names = list(self.columns)
        data = np.column_stack([self.columns[n] for n in names]) if names else np.empty((0, 0))
        with atomic_path(path) as tmp:
            np.savetxt(tmp, data, delimiter=",", header=",".join(names), comments="", fmt="%.9g")

    def save(self, path: str | os.PathLike) -> None:
        """Write by extension: ``.parquet`` or ``.csv``."""
        p = str(path)
        if p.endswith(".parquet"):
            self.to_parquet(p)
        elif p.endswith(".csv"):
            self.to_csv(p)
        else:
            raise DataError(f"{p}: output must end in .parquet or .csv")

    @classmethod
    def from_parquet(cls, path: str | os.PathLike) -> Trace:
        """Read a Parquet trace written by :meth:`to_parquet` (or any table of floats)."""
        import pyarrow.parquet as pq

        table = pq.read_table(path)
        meta_raw = (table.schema.metadata or {}).get(b"swingrt")
        meta = json.loads(meta_raw) if meta_raw else {}
        cols = {n: table.column(n).to_numpy().astype(float) for n in table.column_names}
        return cls(cols, meta)
