"""Reports: figures (:mod:`.plots`) and metric tables (:mod:`.tables`).

Everything here writes files atomically (a failed run leaves no half-written figure or
table) and draws with matplotlib's non-interactive ``Agg`` backend.
"""

from __future__ import annotations

from swingrt.reports.plots import (
    plot_case,
    plot_pareto,
    plot_prediction,
    plot_sample_time,
    plot_training_length,
    save_figure,
)
from swingrt.reports.tables import CSV_COLUMNS, csv_text, write_metrics

__all__ = [
    "CSV_COLUMNS",
    "plot_case",
    "plot_pareto",
    "plot_prediction",
    "plot_sample_time",
    "plot_training_length",
    "save_figure",
    "csv_text",
    "write_metrics",
]
