"""The Zenoh bus: the only package of isac_mission that imports zenoh (docs/bus.md).

- `settings`: `BusSettings` (pydantic; ConfigError for anything invalid), `BusSecurity`, ACL;
- `zenoh_config`: the Zenoh config keys of a BusSettings (`config_entries`, `acl_json`);
- `session`: the one zenoh importer: `ZenohBus`, its `Subscription`s, `make_config`;
- `security`: the scenario's `security.zenoh` resolved into a BusSecurity (logins, users file);
- `certs`: a local CA, a TLS certificate for 127.0.0.1/localhost, a users file (cryptography).

Key expressions and payloads are `isac_mission.wire`'s.
"""

from isac_mission.bus.session import Subscription, ZenohBus, make_config
from isac_mission.bus.settings import (
    DEFAULT_ENDPOINT,
    DEFAULT_PORT,
    LOOPBACK_HOSTS,
    BusAcl,
    BusMode,
    BusRole,
    BusSecurity,
    BusSettings,
    endpoint_host,
    tcp_loopback,
)
from isac_mission.bus.zenoh_config import acl_json, config_entries

__all__ = [
    "DEFAULT_ENDPOINT",
    "DEFAULT_PORT",
    "LOOPBACK_HOSTS",
    "BusAcl",
    "BusMode",
    "BusRole",
    "BusSecurity",
    "BusSettings",
    "Subscription",
    "ZenohBus",
    "acl_json",
    "config_entries",
    "endpoint_host",
    "make_config",
    "tcp_loopback",
]
