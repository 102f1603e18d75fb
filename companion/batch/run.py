"""Run a batch on Dask: the inputs, the cluster, the progress bar, the table and summary.

A local cluster has ``workers`` worker processes of one thread each, bound to
127.0.0.1; with ``scheduler`` the tasks go to that cluster's workers instead (they
need the package installed, and the logs and the output folder at the same paths).
Each flight is one task (:func:`companion.batch.flight.score_flight`). A flight that
fails is an error row; a worker that dies in the middle of a flight has its task run
again on another (Dask's scheduler does this, up to its ``allowed-failures``; past
that the flight is an error row naming the cause).
"""

from __future__ import annotations

import math
import sys
import time
import uuid
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from companion.batch.flight import score_flight
from companion.batch.summary import write_summary
from companion.batch.table import normalise, write_table

LOG_SUFFIXES = (".tlog", ".bin", ".ulg")
"""What a folder given as input contributes (case-insensitive); a file named
explicitly is taken whatever its name (the format is told by content)."""


class BatchError(Exception):
    """The batch cannot run at all (no input, no cluster)."""


@dataclass
class BatchResult:
    """What a batch produced."""

    rows: list[dict[str, Any]]
    table: Path | None
    summary: list[Path]
    wall_s: float
    workers: int
    worker_peak_rss_mb: dict[str, float] = field(default_factory=dict)


def expand(paths: Iterable[Path | str], exclude: Path | None = None) -> list[str]:
    """Files given, and the logs under folders given, as absolute paths (a worker's
    working folder may be another), sorted and without repeats."""
    found: set[str] = set()
    ex = exclude.resolve() if exclude is not None else None
    for given in paths:
        p = Path(given).absolute()
        if p.is_dir():
            for f in p.rglob("*"):
                if f.is_file() and f.suffix.lower() in LOG_SUFFIXES:
                    if ex is not None and ex in f.resolve().parents:
                        continue
                    found.add(str(f))
        else:
            found.add(str(p))  # a missing file becomes an error row
    return sorted(found)


def _size(path: str) -> int:
    try:
        return Path(path).stat().st_size
    except OSError:
        return 0


def _peak_rss_mb() -> float:
    """This process's peak resident memory, MB."""
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 1024.0 if sys.platform != "darwin" else peak / 2**20


def run_batch(
    paths: Sequence[Path | str],
    out_dir: Path,
    workers: int = 2,
    scheduler: str | None = None,
    config_path: Path | None = None,
    table_format: str = "auto",
    plots: bool = True,
    progress: Callable[[bool], None] | None = None,
    write: bool = True,
    worker_setup: Callable[[], None] | None = None,
) -> BatchResult:
    """Replay and score every flight of ``paths`` (module docstring).

    ``progress`` is called once per flight done (True for an error row);
    ``worker_setup`` is run once on every worker first (e.g. its logging).

    Raises
    ------
    BatchError
        No input, or no cluster (the scheduler unreachable, Dask not installed).
    """
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        raise BatchError(
            f"companion batch needs Dask: pip install 'companion[batch]' (dask[distributed]); {exc}"
        ) from exc
    out_dir = Path(out_dir)
    flights = expand(paths, exclude=out_dir)
    if not flights:
        raise BatchError("no log to process (give .tlog/.bin/.ulg files or folders holding them)")
    if workers < 1:
        raise BatchError(f"--workers must be at least 1, got {workers}")
    if write:
        out_dir.mkdir(parents=True, exist_ok=True)
    config = str(Path(config_path).absolute()) if config_path is not None else None
    wall0 = time.perf_counter()
    cluster = None
    try:
        if scheduler:
            client = Client(scheduler, timeout="20s")
        else:
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
            )
            client = Client(cluster)
    except (OSError, TimeoutError) as exc:
        raise BatchError(f"no Dask cluster at {scheduler or 'a local cluster'}: {exc}") from exc
    try:
        if worker_setup is not None:
            client.run(worker_setup)
        n_workers = len(client.scheduler_info().get("workers", {}))
        # the biggest logs first, so that no long one is left for the end (the rows are
        # sorted afterwards: the order of submission changes nothing in the table)
        order = sorted(range(len(flights)), key=lambda i: (-_size(flights[i]), i))
        batch_id = uuid.uuid4().hex[:12]
        futures = client.map(
            score_flight,
            [flights[i] for i in order],
            config_path=config,
            # unique to this batch: a shared scheduler must not take another batch's flight
            key=[f"companion-flight-{batch_id}-{i}" for i in order],
            retries=1,
            pure=False,
        )
        by_key = {f.key: flights[i] for f, i in zip(futures, order, strict=True)}
        rows: list[dict[str, Any]] = []
        for fut in as_completed(futures):
            try:
                row = fut.result()
            except Exception as exc:  # noqa: BLE001 - KilledWorker and the like: an error row
                row = {"path": by_key[fut.key], "name": Path(by_key[fut.key]).name,
                       "error": f"{type(exc).__name__}: {exc}".splitlines()[0][:300]}  # fmt: skip
            rows.append(row)
            if progress is not None:
                progress(bool(row.get("error")))
            fut.release()
        # a worker lost during the batch must not hold this up: its error is left out
        peaks = {
            k: v
            for k, v in client.run(_peak_rss_mb, on_error="return").items()
            if isinstance(v, float)
        }
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    _, full = normalise(rows)
    wall = time.perf_counter() - wall0
    table = write_table(full, out_dir, table_format) if write else None
    summary = write_summary(full, out_dir, plots) if write else []
    return BatchResult(
        rows=full,
        table=table,
        summary=summary,
        wall_s=wall,
        workers=n_workers,
        worker_peak_rss_mb={str(k): float(v) for k, v in sorted(peaks.items())},
    )


def flights_per_minute(result: BatchResult) -> float:
    """Flights per minute of wall time."""
    return len(result.rows) / result.wall_s * 60.0 if result.wall_s > 0 else math.inf
