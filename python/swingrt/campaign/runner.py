"""Run a campaign on Dask: an embedded local cluster, or an existing scheduler.

The samples not yet in the dataset are cut into batches (one Dask task each, see
:func:`batch_size`); the client writes every finished batch to the dataset as it arrives
(:func:`swingrt.campaign.results.write_batch`), so a crash loses at most the batches in
flight, and a rerun skips what is there.

Workers need only ``swingrt`` installed: they receive the spec as plain data and return
plain rows, and never touch the output folder.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from swingrt.campaign.flight import fly_batch
from swingrt.campaign.results import (
    clean_partial,
    finished_samples,
    read_rows,
    store_spec,
    write_batch,
)
from swingrt.campaign.spec import CampaignSpec
from swingrt.errors import ConfigError, SimulationError

#: Largest batch: past this, the scheduler's overhead (milliseconds per task) is already far
#: below 5 % of a batch's work (a sample is ~0.3-3 s) and bigger batches only delay results.
MAX_BATCH = 8


class Progress:
    """A one-line progress bar on stderr with the rate and the ETA, only on a terminal."""

    def __init__(self, total: int, label: str, enabled: bool | None = None):
        self.total = total
        self.label = label
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.t0 = time.perf_counter()

    def update(self, done: int) -> None:
        """Show ``done`` of ``total`` samples."""
        if not self.enabled:
            return
        elapsed = max(time.perf_counter() - self.t0, 1e-9)
        frac = min(done / self.total, 1.0) if self.total else 1.0
        rate = done / elapsed
        eta = (self.total - done) / rate if rate > 0 else math.inf
        eta_s = f"{eta:5.0f} s" if math.isfinite(eta) else "    ? s"
        bar = "#" * int(frac * 30)
        sys.stderr.write(
            f"\r{self.label} [{bar:<30}] {done}/{self.total}  {rate:6.2f} samples/s  ETA {eta_s}"
        )
        sys.stderr.flush()

    def close(self) -> None:
        """End the line."""
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()


def batch_size(spec: CampaignSpec, todo: int, workers: int) -> int:
    """Samples per task: the spec's ``batch_size`` if set, else enough tasks for four per
    worker (load balance), at most :data:`MAX_BATCH` samples each."""
    if spec.batch_size:
        return spec.batch_size
    return max(1, min(MAX_BATCH, math.ceil(todo / (4 * max(workers, 1)))))


@contextlib.contextmanager
def dask_client(workers: int | None, scheduler: str | None) -> Iterator[Any]:
    """A ``distributed.Client``: on ``scheduler`` if given, else on an embedded
    ``LocalCluster`` of ``workers`` single-threaded processes (default: one per core)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a declared dependency
        raise ConfigError(
            "campaign: needs dask[distributed] (pip install 'dask[distributed]')"
        ) from None
    if scheduler:
        try:
            client = Client(scheduler, timeout="20s")
        except OSError as exc:
            raise ConfigError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = workers or os.cpu_count() or 1
    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        host="127.0.0.1",
    )
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def run_campaign(
    spec: CampaignSpec,
    out: str | os.PathLike[str],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool | None = None,
    spec_text: str | None = None,
    report: bool = True,
) -> dict[str, Any]:
    """Run (or resume) ``spec`` into ``out``; returns a summary: ``samples``, ``flown``
    (samples flown by this call), ``skipped`` (already finished), ``rows``, ``seconds``
    (wall time of this call's flying, cluster start excluded), ``workers``, ``batch``
    (samples per task), ``busy`` (worker seconds spent flying) and ``utilisation`` (busy /
    (seconds × workers): what scheduling, transfer and writing leave of the workers' time)."""
    out = Path(out)
    store_spec(spec, out, spec_text)
    clean_partial(out)
    done = finished_samples(out)
    todo = [i for i in range(spec.samples) if i not in done]
    summary: dict[str, Any] = {
        "samples": spec.samples,
        "skipped": spec.samples - len(todo),
        "flown": 0,
        "seconds": 0.0,
        "workers": 0,
    }
    if todo:
        with dask_client(workers, scheduler) as client:
            from distributed import as_completed

            n_workers = sum(client.nthreads().values()) or 1
            size = batch_size(spec, len(todo), n_workers)
            batches = [todo[i : i + size] for i in range(0, len(todo), size)]
            tag = spec.digest()[:10]
            keys = [f"swingrt-campaign-{tag}-{b[0]}-{len(b)}" for b in batches]
            bar = Progress(len(todo), spec.name, progress)
            t0 = time.perf_counter()
            futures = client.map(fly_batch, [spec.raw] * len(batches), batches, key=keys)
            first = {f.key: b[0] for f, b in zip(futures, batches, strict=True)}
            finished = 0
            busy_total = 0.0
            try:
                for fut in as_completed(futures):
                    try:
                        rows, busy = fut.result()
                    except Exception as exc:  # a worker died (KilledWorker), a lost scheduler
                        raise SimulationError(
                            f"batch from sample {first[fut.key]}: {type(exc).__name__}: {exc} "
                            "(finished batches are kept; rerun to resume)"
                        ) from None
                    write_batch(out, rows)
                    busy_total += busy
                    finished += len({r["sample"] for r in rows})
                    bar.update(finished)
            finally:
                bar.close()
                for f in futures:
                    f.cancel()
            wall = time.perf_counter() - t0
            summary.update(
                flown=finished,
                seconds=wall,
                workers=n_workers,
                batch=size,
                busy=busy_total,
                utilisation=busy_total / (wall * n_workers) if wall > 0 else 0.0,
            )
    summary["rows"] = len(read_rows(out))
    if report:
        from swingrt.campaign.report import write_report

        write_report(out, spec)
    return summary
