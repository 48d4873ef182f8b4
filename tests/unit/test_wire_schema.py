"""isac_mission/wire/schema.py and `isac-mission schema`: the JSON Schema of every bus message."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from isac_mission.cli import app
from isac_mission.wire import MAX_UAVS, SCHEMA, DetectionMsg, encode
from isac_mission.wire.models import MODELS
from isac_mission.wire.schema import UNION_NAME, message_schemas, union_schema, write_schemas

KINDS = (
    "detection",
    "detection_set",
    "clock",
    "truth",
    "truth_set",
    "plan",
    "telemetry",
    "track",
    "track_set",
    "health",
    "control",
    "control_reply",
    "fleet",
)


def test_every_message_type_has_a_schema_with_the_envelope() -> None:
    schemas = message_schemas()
    assert sorted(schemas) == sorted(KINDS) == sorted(MODELS)
    for kind, schema in schemas.items():
        props = schema["properties"]
        assert props["schema"]["const"] == SCHEMA
        assert props["type"]["const"] == kind
        assert {"schema", "type", "slot", "t"} <= set(schema["required"])
        assert schema["$id"] == f"{SCHEMA}/{kind}"


def test_the_schemas_carry_the_bounds_the_decoders_enforce() -> None:
    det = message_schemas()["detection"]["properties"]
    assert det["bandwidth_share"]["minimum"] == 0.0 and det["bandwidth_share"]["maximum"] == 1.0
    assert det["uav"]["maximum"] == MAX_UAVS - 1
    assert det["uav_xy_m"]["minItems"] == det["uav_xy_m"]["maxItems"] == 2
    assert {"type": "null"} in det["range_m"]["anyOf"]  # a miss is sent as null
    plan = message_schemas()["plan"]
    assert "reason" not in plan["required"]  # optional on the wire
    tele = message_schemas()["telemetry"]["properties"]
    assert "offboard" in tele["mode"]["enum"] and tele["link"]["enum"] == ["ok", "lost"]


def test_the_union_is_discriminated_on_type() -> None:
    schema = union_schema()
    assert schema["discriminator"]["propertyName"] == "type"
    assert sorted(schema["discriminator"]["mapping"]) == sorted(KINDS)
    assert len(schema["oneOf"]) == len(KINDS)


def test_the_schema_command_writes_one_file_per_message(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["schema", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == sorted([f"{k}.schema.json" for k in KINDS] + [f"{UNION_NAME}.schema.json"])
    plan = json.loads((tmp_path / "plan.schema.json").read_text())
    assert plan == json.loads(json.dumps(message_schemas()["plan"]))
    assert write_schemas(tmp_path / "again")[-1].name == f"{UNION_NAME}.schema.json"


def test_the_schema_command_prints_every_schema_as_json() -> None:
    result = CliRunner().invoke(app, ["schema"])
    assert result.exit_code == 0, result.output
    printed = json.loads(result.output)
    assert sorted(printed) == sorted([*KINDS, UNION_NAME])
    # A payload the encoder writes has exactly the fields the schema names (plus none unknown).
    payload = json.loads(encode(DetectionMsg(1, 1.0, 0, 10.0, 0.5, np.array([1.0, 2.0]), 0.5)))
    assert set(payload) == set(printed["detection"]["properties"])
