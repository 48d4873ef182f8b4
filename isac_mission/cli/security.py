"""`isac-mission gen-certs` and `gen-users`: local TLS material and a Zenoh users file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from isac_mission.cli.app import app, console, err_console, load_or_exit
from isac_mission.errors import ConfigError

MAX_CERT_DAYS = 36500
"""The longest validity `gen-certs` makes (100 years; X.509 dates end in 9999)."""


@app.command("gen-certs")
def gen_certs(
    out_dir: Annotated[Path, typer.Argument(help="Folder for ca.pem, server.pem and their keys.")],
    days: Annotated[
        int, typer.Option(min=1, max=MAX_CERT_DAYS, help="Validity in days (at most 100 years).")
    ] = 365,
    force: Annotated[bool, typer.Option(help="Replace existing files.")] = False,
) -> None:
    """A local CA and a TLS certificate for 127.0.0.1 / localhost (made with the
    cryptography library), for security.zenoh.tls (docs/deployment.md, "Security")."""
    from isac_mission.bus.certs import generate_certs

    try:
        files = generate_certs(out_dir, days=days, force=force)
    except ConfigError as err:
        err_console.print(f"[bold red]{err}[/]", highlight=False)
        raise typer.Exit(1) from None
    console.print(
        "security.zenoh.tls:\n"
        f"  ca_file: {files.ca_file}\n  cert_file: {files.cert_file}\n  key_file: {files.key_file}\n"
        f"(keep {files.ca_key_file} elsewhere: it signs certificates)",
        highlight=False,
    )


@app.command("gen-users")
def gen_users(
    users_file: Annotated[Path, typer.Argument(help="The users file to write (mode 0600).")],
    config: Annotated[
        Path | None, typer.Option(help="Take the users from this scenario's security.zenoh.roles.")
    ] = None,
    force: Annotated[bool, typer.Option(help="Replace an existing file.")] = False,
) -> None:
    """A Zenoh users file (`user:password` lines, random passwords) for security.zenoh.users_file;
    by default the users ground, world, operator and observer. Prints the users, never the
    passwords."""
    from isac_mission.bus.certs import generate_users_file
    from isac_mission.config import ZenohSecurityConfig

    cfg = load_or_exit(config).security.zenoh if config is not None else ZenohSecurityConfig()
    try:
        names = generate_users_file(
            users_file, (u for role in cfg.roles.values() for u in role.users), force=force
        )
    except ConfigError as err:
        err_console.print(f"[bold red]{err}[/]", highlight=False)
        raise typer.Exit(1) from None
    console.print(f"{users_file}: users {', '.join(names)}", highlight=False)
