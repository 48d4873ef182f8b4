"""Dask clients for the project's two parallel jobs, the sweep's runs and the decomposed
horizon's groups: a loopback LocalCluster, or an existing scheduler given by its address.

Dask is optional (the extra `isac-mission[sweep]`): it is imported only when a client is made,
and a missing Dask raises `MissingDependencyError` with the caller's hint. Network: the local
cluster binds its scheduler, nannies and workers to 127.0.0.1 and serves no dashboard; another
cluster is used only when the caller passes its scheduler address explicitly.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import TYPE_CHECKING

from isac_mission.errors import MissingDependencyError

if TYPE_CHECKING:
    from distributed import Client

LOOPBACK = "127.0.0.1"
DASK_EXTRA = "isac-mission[sweep]"
"""The extra that installs Dask."""


def require_dask(needed_for: str, without: str) -> None:
    """Raise MissingDependencyError unless dask and distributed import: `needed_for` says what
    needs them, `without` how to do without (both phrases)."""
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError as err:
        raise MissingDependencyError(
            f"{needed_for} needs dask and distributed ({err}): install the extra with "
            f"`pip install '{DASK_EXTRA}'`, or {without}"
        ) from None


@contextmanager
def dask_client(
    scheduler: str | None, workers: int, config: Mapping[str, object] | None = None
) -> Iterator[Client]:
    """A Client of `scheduler` (e.g. tcp://127.0.0.1:8786) if given, else of a LocalCluster of
    `workers` single-threaded worker processes on 127.0.0.1, the dashboards off, the workers'
    statistical profiler off (it samples every thread's stack every 10 ms: CPU the jobs need)
    and `config` (Dask settings; nannies pass them on to the workers they start). Call
    `require_dask` first. ValueError for workers < 1 without a scheduler."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        with Client(scheduler) as client:  # type: ignore[no-untyped-call]
            yield client
        return
    if workers < 1:
        raise ValueError(f"workers must be >= 1 for a local cluster (got {workers})")
    import dask

    settings = {"distributed.worker.profile.enabled": False, **(config or {})}
    with dask.config.set(settings):
        cluster = LocalCluster(  # type: ignore[no-untyped-call]
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host=LOOPBACK,
            scheduler_port=0,
            dashboard_address=None,
            worker_dashboard_address=None,
            silence_logs=logging.ERROR,
            # The scheduler always serves health/metrics over HTTP: keep it on a random
            # loopback port (not 8787) and without the Bokeh dashboard.
            scheduler_kwargs={"dashboard": False, "dashboard_address": f"{LOOPBACK}:0"},
        )
    with cluster, Client(cluster) as client:  # type: ignore[no-untyped-call]
        yield client
