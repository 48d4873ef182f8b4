"""The planner's Dask cluster: the decomposed horizon's groups solved in parallel, on a loopback
LocalCluster of this machine's cores or on an existing scheduler (planning/decomposed.py,
"Where the groups are solved").

planning/ stays pure: it defines what a group's job is (`GroupJob`), what runs it
(`solve_group_job`) and the port it is handed to (`GroupExecutor`); this module is the I/O
adapter behind that port. `group_executor` makes a Dask `Client` (a `LocalCluster` of
`workers` single-threaded processes, or the client of a scheduler the user names) and a
`DaskGroupExecutor` on it, which a caller sets on the fleet kit
(`planning.decomposed.use_group_executor`): `simulate`, `run` and `serve` with
`--planner-workers/--planner-scheduler/--planner-deadline` (cli/planner_options.py, one
definition of the options for the three), which resolve into a `PlannerCluster`; `simulate`
opens it around its runs (cli/offline.py), `run` and `serve` around the mission
(service/assembly.py, whose planner deadline defaults to `live_deadline_s` of the slot's
planning budget).

On a worker, a job runs `solve_on_worker`: this process's sub-kits (SolverKit of the group's
sub-scenario; its IPOPT NLPs take seconds to build) are cached by the sub-scenario's
fingerprint in the worker process (`decomposed.worker_sub_kit`), built once, never shipped;
only the job (sub-scenario, SlotInput, settings) and the plan (SlotPlan) cross the wire.
Workers load compiled solvers from their NLP cache where it has them and never compile
(`CompiledNlpCache(compile="never")`, as `simulate` plans), and run BLAS single-threaded (as
`sweep`'s workers do), so a group's plan on a worker is the serial path's.

A failed slot costs that slot, never the mission: a job that raises, a worker that dies
(`KilledWorker`; the local cluster's scheduler does not retry a job whose worker died,
`distributed.scheduler.allowed-failures: 0`, and the nanny restarts the worker), a lost
scheduler (`CommClosedError`, a cancelled future) or a slot whose jobs are not all back
within `deadline_s` makes `DaskGroupExecutor.map` raise, and the planner flies the slot's
centralized per-slot plan with the fallback `horizon: decomposed worker lost`.

Dask is optional (`pip install 'isac-mission[sweep]'`): imported only when a client is made;
a missing Dask raises `MissingDependencyError` naming the extra.

Network: the LocalCluster binds its scheduler, nannies and workers to 127.0.0.1 and serves no
dashboard (scheduler or worker); another cluster is used only when the caller passes its
scheduler address explicitly (a non-loopback address is the user's opt-in: `is_loopback`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, suppress
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

from isac_mission import dask_cluster
from isac_mission.planning.decomposed import GroupJob, solve_group_job
from isac_mission.planning.nlp_model import IpoptFactory
from isac_mission.types import SlotPlan

if TYPE_CHECKING:
    from distributed import Client


DEFAULT_DEADLINE_S = 120.0
"""How long (s) a slot waits for its groups' jobs before it flies the per-slot plan: generous,
for offline missions (a cold worker builds a group's NLPs, seconds each); a live mission
passes its slot budget."""

LIVE_DEADLINE_FRACTION = 0.5
"""A live slot's planner deadline as a fraction of its planning budget (`live_deadline_s`): the
rest of the budget is left for what the slot plans around the jobs (the groups, the
association, the recombination and its exact check) and, when the cluster is late, for the
centralized per-slot plan it then flies, so that a late cluster costs the slot a fallback
(`horizon: decomposed worker lost`), not a plan past its budget (a hold, status `timeout`)."""

LOOPBACK_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})

GroupSolve = Callable[[GroupJob], SlotPlan]
"""What a worker runs for one job (default `solve_on_worker`; must pickle by reference)."""


def require_dask() -> None:
    """Raise MissingDependencyError (naming the extra) unless dask and distributed import."""
    dask_cluster.require_dask(
        "solving the planner's groups on Dask", "plan without it (the default)"
    )


def is_loopback(address: str) -> bool:
    """Whether a scheduler address (tcp://HOST:PORT, or HOST:PORT) is on this machine's
    loopback interface."""
    host = urlsplit(address if "://" in address else f"tcp://{address}").hostname or ""
    return host in LOOPBACK_HOSTS or host.startswith("127.")


@contextmanager
def planner_client(scheduler: str | None = None, workers: int = 2) -> Iterator[Client]:
    """A Client of `scheduler` (e.g. tcp://127.0.0.1:8786) if given, else of a LocalCluster
    of `workers` single-threaded worker processes on 127.0.0.1 with the dashboards off and no
    retry of a job whose worker died (module doc; isac_mission/dask_cluster.py). Raises
    MissingDependencyError without Dask, ValueError for workers < 1 without a scheduler."""
    require_dask()
    # A job whose worker died is not retried: the slot flies its per-slot plan instead, and a
    # job that kills its worker (a crash in IPOPT on this input) cannot take the others with it.
    no_retry = {"distributed.scheduler.allowed-failures": 0}
    with dask_cluster.dask_client(scheduler, workers, no_retry) as client:
        yield client


_WORKER_IPOPT: list[IpoptFactory] = []
"""This process's IPOPT factory for the jobs it runs (made on the first job)."""


def worker_ipopt() -> IpoptFactory:
    """This process's IPOPT factory: compiled solvers loaded from its NLP cache where there
    are some, interpreted otherwise, never compiled here (isac_mission/nlp_cache.py). On the
    first call, BLAS is set to one thread in this process (results independent of the BLAS
    thread count, as sweep/runs.limit_blas_threads argues) and HiGHS's banner silenced."""
    if not _WORKER_IPOPT:
        from threadpoolctl import ThreadpoolController

        from isac_mission.nlp_cache import CompiledNlpCache
        from isac_mission.quiet import quiet_highs_banner

        ThreadpoolController().select(user_api="blas").limit(limits=1)
        quiet_highs_banner()
        _WORKER_IPOPT.append(CompiledNlpCache(compile="never"))
    return _WORKER_IPOPT[0]


def solve_on_worker(job: GroupJob) -> SlotPlan:
    """One group's plan in a worker process (`decomposed.solve_group_job` with this
    process's sub-kit cache and `worker_ipopt`)."""
    return solve_group_job(job, worker_ipopt())


class DaskGroupExecutor:
    """A `GroupExecutor` (planning/decomposed.py) on a Dask Client: a slot's jobs submitted
    together, gathered in order, within deadline_s (s) of their submission; raises whatever
    stopped one (module doc). Counts what it did: `slots` (slots whose jobs all came back),
    `failures` (slots it raised for) and the last failure's text (`last_error`). It may be
    called from several threads (the Client is thread-safe; the counts are then best-effort)."""

    def __init__(
        self,
        client: Client,
        deadline_s: float = DEFAULT_DEADLINE_S,
        solve: GroupSolve = solve_on_worker,
    ) -> None:
        """solve: what a worker runs per job (a test passes one that kills its worker)."""
        if deadline_s <= 0:
            raise ValueError(f"the deadline must be > 0 s (got {deadline_s})")
        self.client = client
        self.deadline_s = deadline_s
        self.solve = solve
        self.slots = 0
        self.failures = 0
        self.last_error = ""

    def map(self, jobs: Sequence[GroupJob]) -> list[SlotPlan]:
        """Each job's plan, in the jobs' order (module doc); TimeoutError after deadline_s,
        else the first error a job met (KilledWorker, CommClosedError, its own exception)."""
        from distributed import wait

        futures: list[Any] = []
        try:
            futures = self.client.map(self.solve, list(jobs), pure=False)
            try:
                wait(futures, timeout=self.deadline_s)  # type: ignore[no-untyped-call]
            except TimeoutError:
                late = sum(not f.done() for f in futures)  # type: ignore[no-untyped-call]
                raise TimeoutError(
                    f"{late} of {len(futures)} groups not solved within the slot's deadline "
                    f"of {self.deadline_s:g} s"
                ) from None
            plans: list[SlotPlan] = self.client.gather(futures)  # type: ignore[no-untyped-call]
        except Exception as err:
            self.failures += 1
            self.last_error = f"{type(err).__name__}: {err}"
            unfinished = [f for f in futures if not f.done()]  # type: ignore[no-untyped-call]
            with suppress(Exception):  # a lost scheduler: nothing left to cancel
                self.client.cancel(unfinished)  # type: ignore[no-untyped-call]
            raise
        self.slots += 1
        return plans


def cluster_description(client: Client) -> str:
    """Where the jobs run: the scheduler's address and its workers' count and threads."""
    info: dict[str, Any] = client.scheduler_info()
    workers = info.get("workers", {})
    threads = sum(int(w.get("nthreads", 0)) for w in workers.values())
    return f"scheduler {info['address']}, {len(workers)} workers ({threads} threads)"


def live_deadline_s(plan_budget_s: float | None) -> float:
    """The default planner deadline (s) of a live slot whose planning may take plan_budget_s
    wall seconds: LIVE_DEADLINE_FRACTION of it; without a budget (None) DEFAULT_DEADLINE_S, as
    offline (a cold worker builds a group's NLPs; a dead cluster still costs a fallback, never
    a mission stuck on a slot)."""
    if plan_budget_s is None:
        return DEFAULT_DEADLINE_S
    return LIVE_DEADLINE_FRACTION * plan_budget_s


@dataclass(frozen=True)
class PlannerCluster:
    """Where a command solves the decomposed horizon's groups, as its options gave it
    (`--planner-workers`, `--planner-scheduler`, `--planner-deadline`): the scheduler at
    `scheduler` (tcp://HOST:PORT) if given, else a local cluster of `workers` (>= 1)
    single-threaded processes on 127.0.0.1; deadline_s: seconds a slot waits for its groups
    (None: the command's default, `deadline_for`)."""

    workers: int = 2
    scheduler: str | None = None
    deadline_s: float | None = None

    def __post_init__(self) -> None:
        if self.scheduler is None and self.workers < 1:
            raise ValueError(f"workers must be >= 1 for a local cluster (got {self.workers})")
        if self.deadline_s is not None and not self.deadline_s > 0:
            raise ValueError(f"the deadline must be > 0 s (got {self.deadline_s})")

    @property
    def leaves_the_machine(self) -> bool:
        """Whether the groups' inputs and plans leave this machine (a non-loopback scheduler,
        the user's explicit opt-in)."""
        return self.scheduler is not None and not is_loopback(self.scheduler)

    @property
    def where(self) -> str:
        """Where the groups are solved, in words (naming a scheduler off this machine)."""
        if self.scheduler is None:
            return f"a local cluster of {self.workers} workers on {dask_cluster.LOOPBACK}"
        if self.leaves_the_machine:
            return (
                f"the scheduler {self.scheduler} (not loopback: the groups' inputs and plans "
                "leave this machine, unencrypted)"
            )
        return f"the scheduler {self.scheduler}"

    def deadline_for(self, plan_budget_s: float | None = None) -> float:
        """The deadline (s) a slot waits for its groups: deadline_s if given, else
        `live_deadline_s(plan_budget_s)` (None, offline or a live slot without a budget:
        DEFAULT_DEADLINE_S)."""
        return self.deadline_s if self.deadline_s is not None else live_deadline_s(plan_budget_s)

    def executor(
        self, plan_budget_s: float | None = None
    ) -> AbstractContextManager[DaskGroupExecutor]:
        """`group_executor` of this cluster with `deadline_for(plan_budget_s)` (a context
        manager yielding a DaskGroupExecutor; the local cluster stopped on exit)."""
        return group_executor(self.scheduler, self.workers, self.deadline_for(plan_budget_s))


@contextmanager
def group_executor(
    scheduler: str | None = None, workers: int = 2, deadline_s: float = DEFAULT_DEADLINE_S
) -> Iterator[DaskGroupExecutor]:
    """A `DaskGroupExecutor` on `planner_client(scheduler, workers)` with deadline_s (s) per
    slot, closed (the local cluster stopped) on exit."""
    with planner_client(scheduler, workers) as client:
        yield DaskGroupExecutor(client, deadline_s)
