"""Monte Carlo campaigns (``swingrt campaign``): many samples of an experiment on Dask.

A TOML spec (:mod:`swingrt.campaign.spec`) gives a base experiment, distributions for any
scenario / identification / MPC / LQR field (:mod:`swingrt.campaign.sampling`), the
controllers, the number of samples and a seed. Each sample is flown as an experiment case
is (:mod:`swingrt.campaign.flight`), on an embedded Dask cluster or an existing scheduler
(:mod:`swingrt.campaign.runner`), into a resumable Parquet dataset
(:mod:`swingrt.campaign.results`) with a report (:mod:`swingrt.campaign.report`).
"""

from __future__ import annotations

from swingrt.campaign.flight import (
    failure_reason,
    fly_batch,
    fly_noise_draws,
    fly_sample,
    metric_columns,
)
from swingrt.campaign.results import read_results, read_rows
from swingrt.campaign.runner import run_campaign
from swingrt.campaign.spec import CampaignSpec, load_spec, parse_spec

__all__ = [
    "CampaignSpec",
    "failure_reason",
    "fly_batch",
    "fly_noise_draws",
    "fly_sample",
    "load_spec",
    "metric_columns",
    "parse_spec",
    "read_results",
    "read_rows",
    "run_campaign",
]
