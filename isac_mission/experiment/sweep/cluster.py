"""The Dask runner of a sweep: a loopback LocalCluster (or an existing scheduler) and the task map.

Dask is optional (`pip install 'isac-mission[sweep]'`): it is imported only when a client is
made, and a missing Dask raises `MissingDependencyError` naming the extra (`sweep --serial` needs
no Dask).

Network: the default LocalCluster binds its scheduler, nannies and workers to 127.0.0.1 and has
no dashboard (scheduler or worker); another cluster is used only when the caller passes its
scheduler address explicitly.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from isac_mission import dask_cluster
from isac_mission.experiment.sweep.runs import SweepTask, TaskRow, run_task
from isac_mission.quiet import quiet_highs_banner

if TYPE_CHECKING:
    from distributed import Client

LOOPBACK = dask_cluster.LOOPBACK
SWEEP_EXTRA = dask_cluster.DASK_EXTRA


def require_dask() -> None:
    """Raise MissingDependencyError (naming the `sweep` extra) unless dask and distributed import."""
    dask_cluster.require_dask("a Dask sweep", "run the sweep without Dask (--serial)")


@contextmanager
def dask_client(scheduler: str | None = None, workers: int = 2) -> Iterator[Client]:
    """A Client of `scheduler` (e.g. tcp://HOST:8786) if given, else of a LocalCluster of
    `workers` single-threaded worker processes on 127.0.0.1 with the dashboards off
    (isac_mission/dask_cluster.py), HiGHS's banner quieted on its workers.

    Raises MissingDependencyError if Dask is not installed."""
    require_dask()
    with dask_cluster.dask_client(scheduler, workers) as client:
        if scheduler is None:
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
