"""The Dask runner of a sweep: a loopback LocalCluster (or an existing scheduler) and the task map.

Dask is optional (`pip install 'isac-mission[sweep]'`): it is imported only when a client is
made, and a missing Dask raises `MissingDependencyError` naming the extra (`sweep --serial` needs
no Dask).

Network: the default LocalCluster binds its scheduler, nannies and workers to 127.0.0.1 and has
no dashboard (scheduler or worker); another cluster is used only when the caller passes its
scheduler address explicitly.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from isac_mission.errors import MissingDependencyError
from isac_mission.experiment.sweep.runs import SweepTask, TaskRow, run_task
from isac_mission.quiet import quiet_highs_banner

if TYPE_CHECKING:
    from distributed import Client

LOOPBACK = "127.0.0.1"
SWEEP_EXTRA = "isac-mission[sweep]"


def require_dask() -> None:
    """Raise MissingDependencyError (naming the `sweep` extra) unless dask and distributed import."""
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError as err:
        raise MissingDependencyError(
            f"a Dask sweep needs dask and distributed ({err}): install the extra with "
            f"`pip install '{SWEEP_EXTRA}'`, or run the sweep without Dask (--serial)"
        ) from None


@contextmanager
def dask_client(scheduler: str | None = None, workers: int = 2) -> Iterator[Client]:
    """A Client of `scheduler` (e.g. tcp://HOST:8786) if given, else of a LocalCluster of
    `workers` single-threaded worker processes on 127.0.0.1 with the dashboards off.

    Raises MissingDependencyError if Dask is not installed."""
    require_dask()
    from distributed import Client, LocalCluster

    if scheduler is not None:
        with Client(scheduler) as client:  # type: ignore[no-untyped-call]
            yield client
        return
    if workers < 1:
        raise ValueError(f"workers must be >= 1 for a local cluster (got {workers})")
    import dask

    # The workers' statistical profiler samples every thread's stack every 10 ms; it costs the
    # CPU-bound missions several per cent and nobody reads it here. Nannies pass this config on
    # to the worker processes they start.
    with dask.config.set({"distributed.worker.profile.enabled": False}):
        cluster = LocalCluster(  # type: ignore[no-untyped-call]
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host=LOOPBACK,
            scheduler_port=0,
            dashboard_address=None,
            worker_dashboard_address=None,
            silence_logs=logging.ERROR,
            # The scheduler always serves health/metrics over HTTP: keep it on a random loopback
            # port (not 8787) and without the Bokeh dashboard.
            scheduler_kwargs={"dashboard": False, "dashboard_address": f"{LOOPBACK}:0"},
        )
    with cluster, Client(cluster) as client:  # type: ignore[no-untyped-call]
        client.run(quiet_highs_banner)
        yield client


def cluster_addresses(client: Client) -> list[str]:
    """The scheduler's and every worker's address (e.g. tcp://127.0.0.1:40123)."""
    info: dict[str, Any] = client.scheduler_info()
    return [str(info["address"]), *(str(a) for a in info["workers"])]


def run_dask(
    client: Client,
    tasks: Sequence[SweepTask],
    on_done: Callable[[TaskRow], None] | None = None,
) -> list[TaskRow]:
    """Map `run_task` over the cluster; rows come back in task order (on_done as each finishes)."""
    from distributed import as_completed

    futures = client.map(run_task, list(tasks), pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    rows: list[TaskRow | None] = [None] * len(futures)
    for fut in as_completed(futures):  # type: ignore[no-untyped-call]
        row: TaskRow = fut.result()
        rows[index[fut.key]] = row
        if on_done is not None:
            on_done(row)
    assert all(r is not None for r in rows)
    return [r for r in rows if r is not None]
