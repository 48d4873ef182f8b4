"""The Zenoh configuration of a `BusSettings` as key -> JSON5 text (`bus.session.make_config`
puts them into a zenoh.Config): every network-relevant key set explicitly, and the security keys
(login, users dictionary, access control, TLS) of its `BusSecurity` (docs/bus.md).
"""

from __future__ import annotations

import json
from typing import Any

from isac_mission.bus.settings import BusAcl, BusSecurity, BusSettings


def acl_json(acl: BusAcl) -> dict[str, Any]:
    """The `access_control` section for `acl` (zenoh 1.x schema): default deny."""
    rules: list[dict[str, Any]] = [
        {
            "id": "subscribe",
            "messages": ["declare_subscriber"],
            "flows": ["ingress", "egress"],
            "permission": "allow",
            "key_exprs": [acl.subscribe],
        },
        {
            "id": "receive",
            "messages": ["put"],
            "flows": ["egress"],
            "permission": "allow",
            "key_exprs": [acl.subscribe],
        },
    ]
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    every = [f"role-{r.name}" for r in acl.roles]
    for r in acl.roles:
        subjects.append({"id": f"role-{r.name}", "usernames": list(r.users)})
        if r.publishes:
            rules.append(
                {
                    "id": f"publish-{r.name}",
                    "messages": ["put"],
                    "flows": ["ingress"],
                    "permission": "allow",
                    "key_exprs": list(r.publishes),
                }
            )
            policies.append(
                {
                    "id": f"publish-{r.name}",
                    "rules": [f"publish-{r.name}"],
                    "subjects": [f"role-{r.name}"],
                }
            )
    policies.append({"id": "everyone", "rules": ["subscribe", "receive"], "subjects": every})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def config_entries(settings: BusSettings) -> dict[str, str]:
    """Zenoh config key -> JSON5 value text for `settings`, in insertion order: every
    network-relevant key set explicitly, then the security keys that are set."""
    out = {
        "mode": json.dumps(settings.mode),
        "scouting/multicast/enabled": json.dumps(settings.multicast_scouting),
        "listen/endpoints": json.dumps(list(settings.listen)),
        "connect/endpoints": json.dumps(list(settings.connect)),
    }
    if settings.connect_timeout_ms is not None:
        out["connect/timeout_ms"] = json.dumps(settings.connect_timeout_ms)
    if settings.security is not None:
        out.update(_security_entries(settings.security))
    return out


def _security_entries(sec: BusSecurity) -> dict[str, str]:
    """Login, users dictionary, ACL and TLS keys of `sec` (only those that are set)."""
    entries: dict[str, Any] = {
        "transport/auth/usrpwd/user": sec.user,
        "transport/auth/usrpwd/password": sec.password,
        "transport/auth/usrpwd/dictionary_file": sec.users_file,
        "transport/link/tls/root_ca_certificate": sec.tls_ca_file,
        "transport/link/tls/listen_certificate": sec.tls_cert_file,
        "transport/link/tls/listen_private_key": sec.tls_key_file,
    }
    out = {key: json.dumps(str(value)) for key, value in entries.items() if value is not None}
    if sec.tls:
        # The listener's certificate names 127.0.0.1 and localhost: check the name too.
        out["transport/link/tls/verify_name_on_connect"] = "true"
    if sec.acl is not None:
        out["access_control"] = json.dumps(acl_json(sec.acl))
    return out
