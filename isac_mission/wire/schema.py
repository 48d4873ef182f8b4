"""JSON Schema of every bus message (draft 2020-12, as pydantic writes it; docs/bus.md).

`message_schemas()` gives type -> schema; `write_schemas(out_dir)` writes one
`<type>.schema.json` per message and `isac-message.schema.json` (the union on `type`); the
`isac-mission schema` command calls them.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Final

from pydantic import TypeAdapter

from isac_mission.wire.envelope import SCHEMA
from isac_mission.wire.models import MODELS, WireMessage

UNION_NAME: Final = "isac-message"


def message_schemas() -> dict[str, dict[str, Any]]:
    """Message type -> its JSON Schema (validation mode, field names as on the wire)."""
    out: dict[str, dict[str, Any]] = {}
    for kind, model in MODELS.items():
        schema = model.model_json_schema(by_alias=True, mode="validation")
        schema["$id"] = f"{SCHEMA}/{kind}"
        out[kind] = schema
    return out


def union_schema() -> dict[str, Any]:
    """The JSON Schema of any payload: one of the messages, told apart by `type`."""
    schema = TypeAdapter(WireMessage).json_schema(by_alias=True, mode="validation")
    schema["$id"] = f"{SCHEMA}/{UNION_NAME}"
    schema["title"] = f"{SCHEMA} bus payload"
    return schema


def schema_text(schema: dict[str, Any]) -> str:
    """A schema as stable, indented JSON text (keys sorted, trailing newline)."""
    return json.dumps(schema, indent=2, sort_keys=True) + "\n"


def write_schemas(out_dir: Path) -> list[Path]:
    """Write `<type>.schema.json` for every message and the union into out_dir; the paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    items = [*message_schemas().items(), (UNION_NAME, union_schema())]
    for name, schema in items:
        path = out_dir / f"{name}.schema.json"
        path.write_text(schema_text(schema), encoding="utf-8")
        written.append(path)
    return written
