"""A live mission on the command line (`run`, `serve`), once its options are parsed: the console
beside it, the live progress line, Ctrl-C and SIGTERM (through `cli/stopping.py`), the summary
(`cli/summary.py`) and the exit. The mission itself is assembled and flown by
`isac_mission.service.assembly`; `run`'s world comes from `isac_mission.cli.embedded`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import typer
from rich.table import Table

from isac_mission.cli.app import console, err_console
from isac_mission.cli.ports import ZENOH_PORT_HINT

if TYPE_CHECKING:
    from isac_mission.config import Scenario
    from isac_mission.service.assembly import LiveOptions
    from isac_mission.service.mission_result import LiveResult

PLANNER_DRAIN_S = 60.0
"""How long `run` and `serve` wait at exit for a plan still being solved (wall seconds): a
timed-out plan's solve ends within IPOPT's iteration cap, seconds even for a large fleet."""


def fly(
    s: Scenario,
    opts: LiveOptions,
    *,
    embedded: bool,
    console_address: str | None,
    console_public: bool = False,
) -> None:
    """Fly the mission `opts` describes, with the console on `console_address` (None: none),
    the world in this process when `embedded` (`run`) or elsewhere (`serve`); then the summary
    and the plots, and no planner thread left solving. Exit 0 on SIGINT/SIGTERM, 2 when the
    Zenoh port was taken meanwhile, 1 when the mission failed."""
    console_server = None
    if console_address is not None:
        from isac_mission.cli.view import start_live_console
        from isac_mission.service.assembly import ground_endpoint

        console_server = start_live_console(
            s, opts.method, ground_endpoint(s, opts), console_address, public=console_public
        )
    code = 0
    try:
        result, last_slot = _fly_with_progress(s, opts, embedded)
        from isac_mission.cli.summary import print_summary

        print_summary(s, opts, result, opts.out_dir, last_slot)
    except typer.Exit as done:
        code = done.exit_code
        raise
    except BaseException:
        code = 1
        raise
    finally:
        if console_server is not None:
            console_server.stop()
        _wait_for_the_planners(code)


def _wait_for_the_planners(code: int) -> None:
    """No planner thread may be solving when the interpreter shuts down (a daemon thread in IPOPT
    then aborts the process: service/ground/planner_thread.py). Wait for them, bounded; past the
    bound, flush and leave at once with `code` (the trace and summary are already written)."""
    import os
    import sys

    from isac_mission.service.ground.planner_thread import drain_planner_threads, planner_threads

    if not planner_threads():
        return
    err_console.print("waiting for the planner to finish a solve before exiting")
    if drain_planner_threads(PLANNER_DRAIN_S):
        return
    err_console.print(
        f"a planner thread is still solving after {PLANNER_DRAIN_S:g} s; exiting without it"
    )
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _fly_with_progress(s: Scenario, opts: LiveOptions, embedded: bool) -> tuple[LiveResult, int]:
    """The mission with its live progress line and Ctrl-C; what it produced and the last slot
    the progress line showed."""
    import asyncio
    import signal

    import numpy as np
    from rich.live import Live

    from isac_mission.cli.stopping import StopRequests
    from isac_mission.errors import IsacError, PortInUseError
    from isac_mission.records.tracks import TracksSlot
    from isac_mission.service.assembly import TAKING_OFF, Progress, Stopping, run_mission
    from isac_mission.service.ground.report import SlotEvent

    status = {"phase": "starting", "line": ""}
    last_slot = [0]
    took_off = [False]

    def render() -> Table:
        t = Table.grid(padding=(0, 2))
        t.add_row(f"[bold]{s.mission_id}[/] {opts.method}", status["phase"])
        if status["line"]:
            t.add_row("", status["line"])
        return t

    with Live(render(), console=console, refresh_per_second=8, transient=False) as live:

        def on_status(msg: str) -> None:
            status["phase"] = msg
            took_off[0] = took_off[0] or msg == TAKING_OFF
            live.update(render())

        def on_tracks(o: TracksSlot, latency_s: float) -> None:
            last_slot[0] = o.slot
            confirmed = sum(t.confirmed for t in o.tracks)
            present = int(np.all(np.isfinite(o.truth), axis=1).sum())
            status["line"] = (
                f"slot {o.slot:3d}/{s.N}  targets {present}  tracks {confirmed} confirmed, "
                f"{len(o.tracks) - confirmed} tentative  planned for {o.planned_for or '-'}  "
                f"solve {o.plan.report.solve_s * 1e3:6.1f} ms  det->plan {latency_s * 1e3:6.1f} ms"
                f"  status {o.plan.report.status}"
            )
            live.update(render())

        def on_slot(ev: SlotEvent) -> None:
            r = ev.record
            last_slot[0] = r.slot
            err = "-" if ev.position_error_m is None else f"{ev.position_error_m:6.2f} m"
            links = " ".join(f"{m}:{v}" for m, v in sorted(ev.links.items())) or "-"
            status["line"] = (
                f"slot {r.slot:3d}/{s.N}  tr(PCRB) {r.pcrb_trace:8.4f}  position error {err}  "
                f"solve {r.solve_ms:6.1f} ms  det->plan {ev.latency_s * 1e3:6.1f} ms  "
                f"status {r.status}  links {links}"
            )
            live.update(render())

        requests = StopRequests(s.H, opts.speed, embedded=embedded)
        progress = Progress(on_status, on_slot, on_tracks)

        async def main_task() -> LiveResult:
            stopping = Stopping()
            loop = asyncio.get_running_loop()

            def on_signal(name: str) -> None:
                action, line = requests.on_signal(name, last_slot[0], s.N, took_off[0])
                live.console.print(line, highlight=False)
                if action == "stop":
                    stopping.stop.set()
                elif action == "leave":
                    stopping.leave.set()

            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, on_signal, sig.name)
            try:
                world = None
                if embedded:
                    from isac_mission.cli.embedded import embedded_world

                    world = embedded_world(s, opts)
                return await run_mission(s, opts, stopping, progress, world)
            finally:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    loop.remove_signal_handler(sig)

        try:
            result = asyncio.run(main_task())
        except PortInUseError as err:  # taken since the options were checked: as busy as then
            live.stop()
            err_console.print(f"{err}; {ZENOH_PORT_HINT}", highlight=False, markup=False)
            raise typer.Exit(2) from None
        except IsacError as err:
            err_console.print(f"[bold red]mission failed:[/] {err}")
            raise typer.Exit(1) from None
    console.print()
    return result, last_slot[0]
