"""The neutral wire layer: bus payloads as typed messages, their envelope and key expressions,
strict JSON, and the JSON Schema of every message (docs/bus.md). Imports neither the service nor
`sim`, and no network library.

- `envelope`: limits, the size guard, strict parsing, the base of every message,
  `rejection_reason`;
- `fields`: the field types messages are made of (JSON shape and bounds, how code holds them);
- `models` and `control_models`: one pydantic model per payload type, at once its schema and
  the message the code uses (`DetectionMsg`, ..., `ControlMsg`, `FleetMsg`), the union
  `WireMessage`;
- `codec`: bytes <-> messages for every type (`encode`, `decode`, `decode_any`, and
  `read_request` for the operator's requests); `refusal`: a validation error in the project's
  words;
- `keys`: `Keys(mission)`, the key expressions; `schema`: JSON Schema export;
- `strict_json`: strict JSON shared with `records/`.
"""

from isac_mission.tracking.priorities import DEFAULT_PRIORITY, MAX_PRIORITY
from isac_mission.wire.codec import (
    RequestRead,
    collect_detections,
    decode,
    decode_any,
    decode_control_reply,
    detection_messages,
    detection_set_messages,
    encode,
    encode_control,
    read_request,
)
from isac_mission.wire.control_models import (
    CONTROL_COMMANDS,
    FLEET_COMMANDS,
    MAX_ID_CHARS,
    PRIORITY_PARAMS,
    ControlMsg,
    ControlReplyMsg,
    FleetMsg,
)
from isac_mission.wire.envelope import (
    MAX_ABS,
    MAX_ABS_COVARIANCE,
    MAX_PAYLOAD_BYTES,
    MAX_REASON_CHARS,
    MAX_SLOT,
    MAX_STATUS_CHARS,
    MAX_UAVS,
    SCHEMA,
    SHARE_SUM_TOL,
    Message,
    dumps,
    envelope,
    loads,
    rejection_reason,
)
from isac_mission.wire.keys import Keys, uav_index
from isac_mission.wire.models import (
    CONTROL_PARAMS,
    LINK_STATES,
    MAX_COUNTERS,
    MAX_MEASUREMENTS,
    MAX_TARGETS,
    MAX_TRACKS,
    TELEMETRY_MODES,
    AnyMsg,
    ClockMsg,
    DetectionMsg,
    DetectionSetMsg,
    HealthMsg,
    PlanMsg,
    TelemetryMsg,
    TrackEntry,
    TrackMsg,
    TrackSetMsg,
    TruthMsg,
    TruthSetMsg,
    WireMessage,
)

__all__ = [
    "CONTROL_COMMANDS",
    "CONTROL_PARAMS",
    "DEFAULT_PRIORITY",
    "FLEET_COMMANDS",
    "LINK_STATES",
    "MAX_ABS",
    "MAX_ABS_COVARIANCE",
    "MAX_COUNTERS",
    "MAX_ID_CHARS",
    "MAX_MEASUREMENTS",
    "MAX_PAYLOAD_BYTES",
    "MAX_PRIORITY",
    "MAX_REASON_CHARS",
    "MAX_SLOT",
    "MAX_STATUS_CHARS",
    "MAX_TARGETS",
    "MAX_TRACKS",
    "MAX_UAVS",
    "PRIORITY_PARAMS",
    "SCHEMA",
    "SHARE_SUM_TOL",
    "TELEMETRY_MODES",
    "AnyMsg",
    "ClockMsg",
    "ControlMsg",
    "ControlReplyMsg",
    "DetectionMsg",
    "DetectionSetMsg",
    "FleetMsg",
    "HealthMsg",
    "Keys",
    "Message",
    "PlanMsg",
    "RequestRead",
    "TelemetryMsg",
    "TrackEntry",
    "TrackMsg",
    "TrackSetMsg",
    "TruthMsg",
    "TruthSetMsg",
    "WireMessage",
    "collect_detections",
    "decode",
    "decode_any",
    "decode_control_reply",
    "detection_messages",
    "detection_set_messages",
    "dumps",
    "encode",
    "encode_control",
    "envelope",
    "loads",
    "read_request",
    "rejection_reason",
    "uav_index",
]
