"""JSON Schema of every bus message (draft 2020-12, as pydantic writes it; docs/bus.md).

`message_schemas()` gives type -> schema; `write_schemas(out_dir)` writes one
`<type>.schema.json` per message and `isac-message.schema.json` (the union on `type`); the
`isac-mission schema` command calls them. A model's description is the first paragraph of its
docstring (the rest is about its use in code), and a definition is named by its title
(`TrackEntryWire`), as the schemas have always been published.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Final

from pydantic import TypeAdapter

from isac_mission.wire.envelope import SCHEMA
from isac_mission.wire.models import MODELS, WireMessage

UNION_NAME: Final = "isac-message"
_REFS: Final = "#/$defs/"


def _published(schema: dict[str, Any]) -> dict[str, Any]:
    """`schema` with each model's description cut to its first paragraph and its definitions
    keyed by their titles (the references follow)."""
    names = {key: d["title"] for key, d in schema.get("$defs", {}).items()}

    def fix(node: Any) -> Any:
        if isinstance(node, list):
            return [fix(item) for item in node]
        if not isinstance(node, dict):
            return node
        out = {k: fix(v) for k, v in node.items()}
        ref = out.get("$ref")
        if isinstance(ref, str) and ref.startswith(_REFS):
            out["$ref"] = _REFS + names[ref.removeprefix(_REFS)]
        if isinstance(out.get("description"), str) and "properties" in out:
            out["description"] = out["description"].split("\n\n")[0]
        return out

    fixed: dict[str, Any] = fix(schema)
    if "$defs" in fixed:
        fixed["$defs"] = {names[key]: d for key, d in fixed["$defs"].items()}
    if "discriminator" in fixed:
        mapping = fixed["discriminator"]["mapping"]
        for kind, ref in mapping.items():
            mapping[kind] = _REFS + names[ref.removeprefix(_REFS)]
    return fixed


def message_schemas() -> dict[str, dict[str, Any]]:
    """Message type -> its JSON Schema (validation mode, field names as on the wire)."""
    out: dict[str, dict[str, Any]] = {}
    for kind, model in MODELS.items():
        schema = _published(model.model_json_schema(by_alias=True, mode="validation"))
        schema["$id"] = f"{SCHEMA}/{kind}"
        out[kind] = schema
    return out


def union_schema() -> dict[str, Any]:
    """The JSON Schema of any payload: one of the messages, told apart by `type`."""
    schema = _published(TypeAdapter(WireMessage).json_schema(by_alias=True, mode="validation"))
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
