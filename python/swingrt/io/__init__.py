"""Flight data in and out: the :class:`Trace` container and its files.

* :mod:`.flight` — :class:`Trace` (the one flight container), Parquet/CSV writing
  (:func:`write_columns`) and loading (:func:`load_flight`, also dispatching ULog), and
  :func:`require` (named columns present and finite);
* :mod:`.ulog` — the PX4 ULog reader (topics merged onto one timeline);
* :mod:`.atomic` — atomic file output used by every writer.
"""

from __future__ import annotations

from swingrt.io.flight import TRACE_COLUMNS, Trace, load_flight, require, write_columns

__all__ = ["TRACE_COLUMNS", "Trace", "load_flight", "require", "write_columns"]
