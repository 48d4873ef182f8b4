"""The neutral wire layer: bus payloads as typed messages, their envelope and key expressions,
strict JSON, and the JSON Schema of every message (docs/bus.md). Imports neither the service nor
`sim`, and no network library.

- `envelope`: limits, the size guard, strict parsing, the common fields, `rejection_reason`;
- `models`: the pydantic model of each payload type and the union `WireMessage`;
- `messages`: the domain dataclasses (numpy arrays, NaN for missing);
- `codec`: bytes <-> domain messages (`encode_*`, `decode_*`, `decode_any`);
- `keys`: `Keys(mission)`, the key expressions; `schema`: JSON Schema export;
- `strict_json`: strict JSON shared with `records/`.
"""

from isac_mission.wire.codec import (
    collect_detections,
    decode_any,
    decode_clock,
    decode_control,
    decode_detection,
    decode_health,
    decode_plan,
    decode_telemetry,
    decode_track,
    decode_truth,
    detection_messages,
    encode_clock,
    encode_control,
    encode_detection,
    encode_health,
    encode_plan,
    encode_telemetry,
    encode_track,
    encode_truth,
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
    dumps,
    envelope,
    loads,
    rejection_reason,
)
from isac_mission.wire.keys import Keys, uav_index
from isac_mission.wire.messages import (
    AnyMsg,
    ClockMsg,
    ControlMsg,
    DetectionMsg,
    HealthMsg,
    PlanMsg,
    TelemetryMsg,
    TrackMsg,
    TruthMsg,
)
from isac_mission.wire.models import (
    CONTROL_PARAMS,
    LINK_STATES,
    MAX_COUNTERS,
    TELEMETRY_MODES,
    WireMessage,
)

__all__ = [
    "CONTROL_PARAMS",
    "LINK_STATES",
    "MAX_ABS",
    "MAX_ABS_COVARIANCE",
    "MAX_COUNTERS",
    "MAX_PAYLOAD_BYTES",
    "MAX_REASON_CHARS",
    "MAX_SLOT",
    "MAX_STATUS_CHARS",
    "MAX_UAVS",
    "SCHEMA",
    "SHARE_SUM_TOL",
    "TELEMETRY_MODES",
    "AnyMsg",
    "ClockMsg",
    "ControlMsg",
    "DetectionMsg",
    "HealthMsg",
    "Keys",
    "PlanMsg",
    "TelemetryMsg",
    "TrackMsg",
    "TruthMsg",
    "WireMessage",
    "collect_detections",
    "decode_any",
    "decode_clock",
    "decode_control",
    "decode_detection",
    "decode_health",
    "decode_plan",
    "decode_telemetry",
    "decode_track",
    "decode_truth",
    "detection_messages",
    "dumps",
    "encode_clock",
    "encode_control",
    "encode_detection",
    "encode_health",
    "encode_plan",
    "encode_telemetry",
    "encode_track",
    "encode_truth",
    "envelope",
    "loads",
    "rejection_reason",
    "uav_index",
]
