"""Flight data: the :class:`Trace` container, its files (Parquet, CSV) and the loaders.

Every loader returns a :class:`Trace` of raw columns named as in :data:`TRACE_COLUMNS`
(``t`` in seconds from the first sample, NED positions/velocities, ZYX Euler angles, swing
angles, acceleration and velocity setpoints); resampling to the identification sample time
Ts is the caller's job (thesis 4.6.1: the logs come at uneven rates, identification works
on a uniform grid).
Only the columns a caller asks for are required: :func:`require` checks them and names what
is missing or broken (column, file, time of the first NaN).

A :class:`Trace` is both what the simulator and the MAVLink node record and what the
loaders return: a mapping of column name to float array (``t[...]``, ``in``, ``len``,
``keys()``/``items()``/``get()``), with ``meta`` (e.g. the scenario it was flown with),
``source`` (the file it came from) and ``notes`` (why an expected column is absent).
PX4 ULog logs are read by :mod:`swingrt.io.ulog`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator, Mapping, MutableMapping
from pathlib import Path
from typing import Any

import numpy as np

from swingrt import _core
from swingrt.errors import DataError, MissingColumnError
from swingrt.io.atomic import atomic_path

__all__ = [
    "TRACE_COLUMNS",
    "Trace",
    "load_flight",
    "require",
    "write_columns",
]

#: Columns every flight log has, in their canonical order (units: SI, angles in rad): the
#: core's schema (``_core.FLIGHT_COLUMNS``; the simulator logs ``_core.TRACE_COLUMNS``).
TRACE_COLUMNS: tuple[str, ...] = _core.FLIGHT_COLUMNS

_SUFFIXES = (".parquet", ".csv", ".ulg")


class Trace(MutableMapping[str, np.ndarray]):
    """A flight: equal-length float columns named as in the trace schema, plus metadata.

    Dict-like: ``trace["vn"]``, ``"vn" in trace``, iteration over the column names,
    ``keys()``, ``items()``, ``get()``, assignment and ``pop``; ``len(trace)`` is the number
    of rows. A missing column raises :class:`~swingrt.errors.MissingColumnError` (both a
    ``DataError`` and a ``KeyError``). ``columns`` is the underlying ``dict``.
    """

    def __init__(
        self,
        columns: Mapping[str, Any] | None = None,
        meta: Mapping[str, Any] | None = None,
        *,
        source: str = "",
        notes: Mapping[str, str] | None = None,
    ):
        cols = {k: np.asarray(v, dtype=float) for k, v in (columns or {}).items()}
        lengths = {len(v) for v in cols.values()}
        if len(lengths) > 1:
            where = f"{source}: " if source else ""
            raise DataError(f"{where}trace columns differ in length: {sorted(lengths)}")
        #: The columns, by name (float64 arrays of equal length).
        self.columns: dict[str, np.ndarray] = cols
        #: Metadata saved with the trace (Parquet schema metadata), e.g. the scenario.
        self.meta: dict[str, Any] = dict(meta or {})
        #: Where the data came from (file path), used in error messages.
        self.source = source
        #: Why an expected column is absent, by column name (filled by the loaders).
        self.notes: dict[str, str] = dict(notes or {})

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.columns[name]
        except KeyError:
            raise MissingColumnError(f"trace has no column {name!r}") from None

    def __setitem__(self, name: str, values: Any) -> None:
        arr = np.asarray(values, dtype=float)
        n = self._rows(exclude=name)
        if n is not None and len(arr) != n:
            raise DataError(f"column {name!r} has {len(arr)} rows, the trace {n}")
        self.columns[name] = arr

    def __delitem__(self, name: str) -> None:
        try:
            del self.columns[name]
        except KeyError:
            raise MissingColumnError(f"trace has no column {name!r}") from None

    def __contains__(self, name: object) -> bool:
        return name in self.columns

    def __iter__(self) -> Iterator[str]:
        return iter(self.columns)

    def _rows(self, exclude: str | None = None) -> int | None:
        for k, v in self.columns.items():
            if k != exclude:
                return len(v)
        return None

    def __len__(self) -> int:
        """Number of rows (samples)."""
        return self._rows() or 0

    def __repr__(self) -> str:
        t = self.columns.get("t")
        span = f"{t[0]:.2f}–{t[-1]:.2f} s" if t is not None and len(t) else "empty"
        return f"Trace({len(self)} rows, {len(self.columns)} columns, {span})"

    @property
    def t(self) -> np.ndarray:
        """Time [s]."""
        if "t" not in self.columns:
            raise MissingColumnError("trace has no time column 't'")
        return self.columns["t"]

    def to_parquet(self, path: str | os.PathLike[str]) -> None:
        """Write as Parquet (atomically); metadata goes into the schema metadata."""
        write_columns(self.columns, path, meta=self.meta, suffix=".parquet")

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write as CSV with a header row (atomically); metadata is not kept."""
        write_columns(self.columns, path, suffix=".csv")

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write by extension: ``.parquet`` (with metadata) or ``.csv``."""
        write_columns(self.columns, path, meta=self.meta)

    @classmethod
    def from_parquet(cls, path: str | os.PathLike[str]) -> Trace:
        """Read a Parquet trace written by :meth:`to_parquet` (or any table of floats)."""
        import pyarrow.parquet as pq

        table = pq.read_table(path)
        cols = {n: table.column(n).to_numpy().astype(float) for n in table.column_names}
        return cls(cols, _parquet_meta(table, Path(path)), source=str(path))


def load_flight(
    path: str | os.PathLike[str],
    *,
    ulog_swing: Mapping | None = None,
    estimator: Mapping | None = None,
    body: Mapping | None = None,
    columns: Iterable[str] | None = None,
) -> Trace:
    """Load a flight from ``.parquet``, ``.csv`` or a PX4 ``.ulg`` into raw trace columns.

    ``ulog_swing`` configures the swing sensor topic of a ULog (module doc), ``estimator``
    its swing estimated from the IMU and ``body`` its cable sensor on the airframe read from
    ``adc_report`` (:mod:`swingrt.io.ulog`); all are ignored for the other formats.
    ``columns``, if given, are checked with :func:`require`.
    Raises :class:`DataError` with one line for an unknown extension, an empty or unreadable
    file, non-increasing time, or (with ``columns``) a missing column or NaN gap.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in _SUFFIXES:
        raise DataError(
            f"{p}: unknown data format '{p.suffix or '(none)'}' (expected .parquet, .csv or .ulg)",
            path=p,
        )
    if not p.is_file():
        raise DataError(f"{p}: no such file", path=p)
    if p.stat().st_size == 0:
        raise DataError(f"{p}: file is empty", path=p)
    # Hostile content (huge, non-finite, zero-norm quaternions) gives NaN/inf columns that
    # `require` names, not numpy warnings.
    with np.errstate(all="ignore"):
        if suffix == ".ulg":
            from swingrt.io.ulog import load_ulog

            data = load_ulog(p, ulog_swing, estimator, body)
        else:
            data = _load_table(p, suffix)
        _finish_time(data, str(p))
    if columns is not None:
        require(data, columns, str(p))
    return data


def require(columns: Mapping[str, np.ndarray], names: Iterable[str], source: str) -> None:
    """Check that every column in ``names`` is present and finite.

    Raises :class:`DataError` naming the missing column(s) and ``source`` (with the reason if
    the loader recorded one), or the first column holding NaN and the time where it starts.
    """
    names = list(names)
    notes = getattr(columns, "notes", {})
    path = getattr(columns, "source", "") or None
    missing = [n for n in names if n not in columns]
    if missing:
        why = "; ".join(sorted({notes[n] for n in missing if n in notes}))
        plural = "s" if len(missing) > 1 else ""
        msg = f"{source}: missing column{plural} {', '.join(missing)}"
        raise DataError(msg + (f" ({why})" if why else ""), path=path)
    t = columns.get("t")
    for n in names:
        bad = ~np.isfinite(np.asarray(columns[n], dtype=float))
        if bad.any():
            i = int(np.argmax(bad))
            j = i + int(np.argmin(bad[i:])) if not bad[i:].all() else len(bad)
            where = (
                f"t = {float(t[i]):.3f} s" if t is not None and np.isfinite(t[i]) else f"row {i}"
            )
            raise DataError(
                f"{source}: column {n} has a NaN gap at {where} ({j - i} sample(s))", path=path
            )


def write_columns(
    columns: Mapping[str, Any],
    path: str | os.PathLike[str],
    *,
    meta: Mapping[str, Any] | None = None,
    suffix: str | None = None,
) -> None:
    """Write columns to ``.parquet`` or ``.csv`` atomically (a failed write leaves no file).

    The one writer of flight data: ``suffix`` (default: the file's) picks the format;
    ``meta`` goes into the Parquet schema metadata (key ``swingrt``, JSON).
    """
    p = Path(path)
    suffix = (suffix or p.suffix).lower()
    arrays = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
    lengths = {len(v) for v in arrays.values()}
    if len(lengths) > 1:
        raise DataError(f"{p}: columns have different lengths {sorted(lengths)}", path=p)
    if suffix not in (".parquet", ".csv"):
        raise DataError(f"{p}: cannot write '{p.suffix}' (use .parquet or .csv)", path=p)
    import pyarrow as pa

    table = pa.table(arrays)
    with atomic_path(p) as tmp:
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            if meta is not None:
                table = table.replace_schema_metadata({"swingrt": json.dumps(meta)})
            pq.write_table(table, tmp)
        else:
            import pyarrow.csv as pcsv

            pcsv.write_csv(table, tmp, pcsv.WriteOptions(quoting_style="none"))


# --------------------------------------------------------------------------- tables


def _parquet_meta(table: Any, p: Path) -> dict[str, Any]:
    """The metadata :meth:`Trace.to_parquet` wrote into a Parquet file's schema ({} when
    there is none); DataError when it is not a JSON object."""
    raw = (table.schema.metadata or {}).get(b"swingrt")
    if not raw:
        return {}
    try:
        meta = json.loads(raw)
    except (ValueError, UnicodeDecodeError):
        raise DataError(f"{p}: its swingrt metadata is not JSON", path=p) from None
    if not isinstance(meta, dict):
        raise DataError(f"{p}: its swingrt metadata is not a JSON object", path=p)
    return meta


def _load_table(p: Path, suffix: str) -> Trace:
    import pyarrow as pa

    try:
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            table = pq.read_table(p)
        else:
            import pyarrow.csv as pcsv

            table = pcsv.read_csv(p)
    except (pa.ArrowInvalid, pa.ArrowException, OSError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if "Empty CSV file" in first:
            raise DataError(f"{p}: file is empty", path=p) from None
        raise DataError(f"{p}: cannot read {suffix[1:]} file: {first}", path=p) from None
    if table.num_rows == 0:
        raise DataError(f"{p}: file holds no rows", path=p)
    try:
        names = table.column_names
    except UnicodeDecodeError:
        raise DataError(f"{p}: the header is not UTF-8 text", path=p) from None
    # A Parquet flight written here keeps what made it (the scenario, the swing estimator):
    # identification reads it, e.g. the estimator settings a model on the IMU must fly with.
    meta = _parquet_meta(table, p) if suffix == ".parquet" else {}
    out = Trace(meta=meta, source=str(p))
    for name in names:
        col = table.column(name)
        if pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
            out[name] = col.to_numpy(zero_copy_only=False).astype(float)
        elif pa.types.is_boolean(col.type):
            out[name] = col.to_numpy(zero_copy_only=False).astype(float)
        elif pa.types.is_null(col.type):
            out[name] = np.full(table.num_rows, np.nan)
        else:
            out.notes[name] = f"column {name} is not numeric ({col.type})"
    return out


def _finish_time(data: Trace, source: str) -> None:
    """Shift ``t`` to start at 0 and check it increases strictly."""
    if "t" not in data:
        return
    t = data["t"]
    if len(t) == 0:
        raise DataError(f"{source}: file holds no samples", path=source)
    if not np.all(np.isfinite(t)):
        i = int(np.argmax(~np.isfinite(t)))
        raise DataError(f"{source}: column t is not finite at row {i}", path=source)
    if not np.isfinite(t[-1] - t[0]):
        raise DataError(
            f"{source}: time spans more than a float can hold ({t[0]:.6g} to {t[-1]:.6g} s)",
            path=source,
        )
    # Checked after the shift: times far from 0 (t = -1.4e14, then 0.02, 0.04) collapse
    # onto one value when they are made relative to the first sample.
    shifted = t - t[0]
    dt = np.diff(shifted)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0)) + 1
        raise DataError(
            f"{source}: time does not increase at row {i} (t = {t[i]:.6g} s)", path=source
        )
    data["t"] = shifted
