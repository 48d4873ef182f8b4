"""`isac-mission schema`: the JSON Schema of every bus message (isac_mission.wire.schema)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from isac_mission.cli.app import app, console


@app.command("schema")
def schema(
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help="Folder to write <type>.schema.json per message and isac-message.schema.json "
            "(the union on `type`) into; without it, print them all as one JSON object.",
        ),
    ] = None,
) -> None:
    """The JSON Schema (draft 2020-12) of every isac/1 bus message (docs/bus.md)."""
    from isac_mission.wire.schema import (
        UNION_NAME,
        message_schemas,
        schema_text,
        union_schema,
        write_schemas,
    )

    if out is None:
        every = {**message_schemas(), UNION_NAME: union_schema()}
        typer.echo(schema_text(every), nl=False)
        return
    for path in write_schemas(out):
        console.print(f"wrote {path}", highlight=False)
