"""Scenarios: pydantic sections that validate a YAML file, and its SI-unit resolution.

Files carry dB and dBm where engineers expect them; `load_scenario` (a path, or the name of a
shipped scenario: `load_scenario("paper")`) validates once and returns a frozen `Scenario` in SI
units (W, Hz, m, s, linear ratios) under the paper's symbols. Every choice the paper leaves open
is a field whose description points at docs/model.md.

One schema (docs/decisions/0001-one-scenario-schema.md): the targets as a list under `targets:`,
their motion under `target_motion:`, one `tracker:` section (`kind`, and the multi-target
tracker under `multi:`); the deprecated `target:` and `multi_target:` are read until 0.5.0.

Modules: `units` (dB/dBm), `sections` (timing ... planner, the tracker and the targets' motion),
`targets` (`targets:` entries, `detection:`), `signing` (MAVLink signing and its key),
`security` (Zenoh users, roles, TLS), `priorities` (`priorities:`, the scripted changes of the
tracks' priorities), `scenario` (`ScenarioFile`, `Scenario`), `resolve` (derived constants and
cross-field checks), `loading` (files, mappings, names).
"""

from isac_mission.config.impairment import (
    ChannelImpairmentConfig,
    ImpairmentConfig,
    LinkImpairmentConfig,
    apply_impairment_flags,
)
from isac_mission.config.links import LinksConfig
from isac_mission.config.loading import (
    SCENARIOS_DIR,
    load_scenario,
    parse_scenario,
    read_scenario_data,
    scenario_names,
    scenario_path,
)
from isac_mission.config.priorities import PriorityEntry
from isac_mission.config.resolve import radar_crb_alphas, random_bs_layout, resolve
from isac_mission.config.scenario import (
    SCHEMA_REMOVAL_VERSION,
    Scenario,
    ScenarioFile,
    multi_target_reasons,
    single_target_problem,
)
from isac_mission.config.sections import (
    AreaConfig,
    BaseStationConfig,
    MultiTrackerConfig,
    PlannerConfig,
    RadioConfig,
    SensingConfig,
    TargetConfig,
    TargetMotionConfig,
    TimingConfig,
    TrackerConfig,
    UavConfig,
)
from isac_mission.config.security import (
    SecurityConfig,
    ZenohRoleConfig,
    ZenohSecurityConfig,
    ZenohTlsConfig,
    ZenohTopic,
)
from isac_mission.config.signing import (
    DEFAULT_SIGNING_KEY_ENV,
    MIN_PASSPHRASE_CHARS,
    SIGNING_KEY_BYTES,
    MavlinkSigningConfig,
    MavlinkSigningKey,
    mavlink_signing_key,
)
from isac_mission.config.targets import DetectionConfig, TargetEntry
from isac_mission.config.units import SPEED_OF_LIGHT_MPS, db_to_linear, dbm_to_w

__all__ = [
    "DEFAULT_SIGNING_KEY_ENV",
    "MIN_PASSPHRASE_CHARS",
    "SCENARIOS_DIR",
    "SCHEMA_REMOVAL_VERSION",
    "SIGNING_KEY_BYTES",
    "SPEED_OF_LIGHT_MPS",
    "AreaConfig",
    "BaseStationConfig",
    "ChannelImpairmentConfig",
    "DetectionConfig",
    "ImpairmentConfig",
    "LinkImpairmentConfig",
    "LinksConfig",
    "MavlinkSigningConfig",
    "MavlinkSigningKey",
    "MultiTrackerConfig",
    "PlannerConfig",
    "PriorityEntry",
    "RadioConfig",
    "Scenario",
    "ScenarioFile",
    "SecurityConfig",
    "SensingConfig",
    "TargetConfig",
    "TargetEntry",
    "TargetMotionConfig",
    "TimingConfig",
    "TrackerConfig",
    "UavConfig",
    "ZenohRoleConfig",
    "ZenohSecurityConfig",
    "ZenohTlsConfig",
    "ZenohTopic",
    "apply_impairment_flags",
    "db_to_linear",
    "dbm_to_w",
    "load_scenario",
    "mavlink_signing_key",
    "multi_target_reasons",
    "parse_scenario",
    "radar_crb_alphas",
    "random_bs_layout",
    "read_scenario_data",
    "resolve",
    "scenario_names",
    "scenario_path",
    "single_target_problem",
]
