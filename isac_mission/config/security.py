"""Security settings: Zenoh users, roles (access control) and TLS, and the `security` section
that holds them beside MAVLink signing (docs/deployment.md, "Security"; docs/reliability.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from isac_mission.config.sections import Section
from isac_mission.config.signing import MavlinkSigningConfig

ZenohTopic = Literal[
    "plan",
    "track",
    "health",
    "clock",
    "truth",
    "detections",
    "telemetry",
    "control",
    "control/reply",
    "fleet",
]
"""The key expressions of docs/bus.md by name: `isac/<mission>/<topic>[/<m>]`."""
_NAME_PATTERN = r"^[A-Za-z0-9_.-]+$"
_ENV_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*$"


class ZenohRoleConfig(Section):
    """One role of the Zenoh access control: who holds it and what they may publish."""

    users: list[str] = Field(
        min_length=1, description="Usernames (of the users file) that hold this role."
    )
    publishes: list[ZenohTopic] = Field(
        default_factory=list,
        description="Topics this role may put on (every role may subscribe); [] = read only.",
    )

    @model_validator(mode="after")
    def _names(self) -> ZenohRoleConfig:
        import re

        for user in self.users:
            if not re.match(_NAME_PATTERN, user):
                raise ValueError(f"users: {user!r} must use letters, digits, '_', '.' or '-'")
        return self


def _default_roles() -> dict[str, ZenohRoleConfig]:
    return {
        "ground": ZenohRoleConfig(
            users=["ground"],
            publishes=["plan", "track", "health", "telemetry", "control/reply", "fleet"],
        ),
        "world": ZenohRoleConfig(
            users=["world"], publishes=["clock", "truth", "detections", "telemetry"]
        ),
        "operator": ZenohRoleConfig(users=["operator"], publishes=["control"]),
        "observer": ZenohRoleConfig(users=["observer"], publishes=[]),
    }


class ZenohTlsConfig(Section):
    """TLS on the Zenoh links (endpoints `tls/127.0.0.1:PORT`); `isac-mission gen-certs DIR`
    writes a local CA and a certificate for 127.0.0.1 and localhost."""

    ca_file: Path = Field(description="CA certificate (PEM) the connecting side trusts.")
    cert_file: Path | None = Field(
        None, description="The listening side's certificate (PEM), signed by ca_file."
    )
    key_file: Path | None = Field(None, description="The private key of cert_file (PEM).")

    @model_validator(mode="after")
    def _pair(self) -> ZenohTlsConfig:
        if (self.cert_file is None) != (self.key_file is None):
            raise ValueError("cert_file and key_file go together (set both or neither)")
        return self


class ZenohSecurityConfig(Section):
    """Zenoh user/password authentication, role-based access control and TLS
    (docs/deployment.md, "Security"; docs/reliability.md). Files only: no password is ever
    written in the scenario.

    The listening side (the ground loop) checks logins against `users_file` and lets each role
    put only on its `publishes` topics; a connecting process logs in with the credentials of
    `user_env` / `password_env`, else `credentials_file`, else its role's first user in
    `users_file`. Relative paths are relative to the working directory.
    """

    enabled: bool = Field(False, description="Turn on user/password auth and the ACL (and TLS).")
    users_file: Path | None = Field(
        None,
        description="`user:password` lines (zenoh's dictionary_file) the listening side checks; "
        "`isac-mission gen-users FILE` writes one with random passwords.",
    )
    credentials_file: Path | None = Field(
        None, description="This process's own login: one `user:password` line."
    )
    user_env: str = Field(
        "ISAC_ZENOH_USER", pattern=_ENV_PATTERN, description="Env variable: this process's user."
    )
    password_env: str = Field(
        "ISAC_ZENOH_PASSWORD",
        pattern=_ENV_PATTERN,
        description="Env variable: this process's password.",
    )
    roles: dict[str, ZenohRoleConfig] = Field(
        default_factory=_default_roles,
        description="Role name -> users and the topics they may publish; needs ground and world.",
    )
    tls: ZenohTlsConfig | None = Field(None, description="TLS on every Zenoh link (null: tcp).")

    @model_validator(mode="after")
    def _roles(self) -> ZenohSecurityConfig:
        import re

        for name in self.roles:
            if not re.match(_NAME_PATTERN, name):
                raise ValueError(f"roles: name {name!r} must use letters, digits, '_', '.' or '-'")
        missing = [r for r in ("ground", "world") if r not in self.roles]
        if missing:
            raise ValueError(f"roles: needs a {' and a '.join(missing)} role (the processes' own)")
        seen: dict[str, str] = {}
        for name, role in self.roles.items():
            for user in role.users:
                if user in seen:
                    raise ValueError(f"roles: user {user!r} is in both {seen[user]} and {name}")
                seen[user] = name
        return self


class SecurityConfig(Section):
    """Who may command the vehicles and publish on the bus. Off by default (loopback only)."""

    mavlink_signing: MavlinkSigningConfig = MavlinkSigningConfig()
    zenoh: ZenohSecurityConfig = ZenohSecurityConfig()
