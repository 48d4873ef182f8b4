"""The operator console on the command line: `--console` / `--no-console` of `run` and `serve`
(`start_live_console`), and `isac-mission view TRACE [TRACE ...]` (docs/console.md)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from isac_mission.cli.app import ConsoleOpt, PublicOpt, app, console, err_console

if TYPE_CHECKING:
    from isac_mission.config import Scenario
    from isac_mission.console import ConsoleServer


def start_live_console(
    s: Scenario, method: str, endpoint: str, address: str, *, public: bool = False
) -> ConsoleServer | None:
    """Start the live console for the mission whose ground loop listens on `endpoint`; None
    (with a message) when its port is busy or it cannot start: the mission runs without it.
    A malformed address exits with status 2."""
    from isac_mission.console import (
        BusAccess,
        ConsolePortBusyError,
        ConsoleServer,
        ConsoleService,
        MissionView,
        parse_address,
    )
    from isac_mission.errors import ConfigError

    try:
        where = parse_address(address, allow_non_loopback=public)
    except ConfigError as err:
        err_console.print(str(err), highlight=False)
        raise typer.Exit(2) from None
    view = MissionView(s.trace_config() | {"method": method})
    service = ConsoleService(view, BusAccess(s.mission_id, endpoint, s.security.zenoh))
    server = ConsoleServer(service, where)
    try:
        url = server.start()
    except ConsolePortBusyError as err:
        err_console.print(f"{err}; the mission runs without the console", highlight=False)
        return None
    except ConfigError as err:
        err_console.print(f"{err}; the mission runs without the console", highlight=False)
        return None
    console.print(f"console: {url}", highlight=False)
    return server


@app.command()
def view(
    traces: Annotated[list[Path], typer.Argument(help="Trace files (.jsonl) of one scenario.")],
    console_address: ConsoleOpt = "127.0.0.1:8080",
    public: PublicOpt = False,
) -> None:
    """Replay finished traces (`simulate`, `run` or `serve`) in the console page: a slot slider,
    play/pause, and several methods of one run side by side. Serves until Ctrl-C."""
    import signal
    import threading

    from isac_mission.console import ConsoleServer, ConsoleService, MissionView, parse_address
    from isac_mission.console.replay import load_replay, replay_config
    from isac_mission.errors import ConfigError, MessageError

    try:
        where = parse_address(console_address, allow_non_loopback=public)
        replay = load_replay(traces)
    except (ConfigError, MessageError) as err:
        err_console.print(str(err), highlight=False)
        raise typer.Exit(2) from None
    service = ConsoleService(MissionView(replay_config(replay)), None)
    server = ConsoleServer(service, where, replay=replay)
    try:
        url = server.start()
    except ConfigError as err:
        err_console.print(str(err), highlight=False)
        raise typer.Exit(1) from None
    console.print(f"console: {url} ({len(replay['runs'])} traces; Ctrl-C to stop)", highlight=False)
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    try:
        while not done.wait(0.5):
            pass
    finally:
        server.stop()
