"""Zenoh security from the scenario's `security.zenoh`: what the listening side enforces and who a
connecting process logs in as (docs/deployment.md, "Security").

Secrets come from files and environment variables only, never from the scenario, and are never
logged: a login is logged by its user name and where it came from. Every problem is a ConfigError
that names the config field (or the environment variable) at fault.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from isac_mission.bus.settings import (
    DEFAULT_PORT,
    BusAcl,
    BusMode,
    BusRole,
    BusSecurity,
    BusSettings,
)
from isac_mission.config import ZenohSecurityConfig, ZenohTopic
from isac_mission.errors import ConfigError
from isac_mission.wire.keys import Keys

log = logging.getLogger(__name__)

FIELD: Final = "security.zenoh"


@dataclass(frozen=True)
class Login:
    """A user name and password, and where they came from (for messages; never the password)."""

    user: str
    password: str = field(repr=False)
    source: str


def topic_key_expr(keys: Keys, topic: ZenohTopic) -> str:
    """The key expression of a topic name: `detections` -> `isac/<mission>/detections/*`."""
    per_uav = {"detections": keys.detections_all, "telemetry": keys.telemetry_all}
    return per_uav.get(topic, f"{keys.prefix}/{topic}")


def bus_acl(cfg: ZenohSecurityConfig, keys: Keys) -> BusAcl:
    """The listening side's access control: each role puts on its topics only."""
    roles = tuple(
        BusRole(
            name=name,
            users=tuple(role.users),
            publishes=tuple(topic_key_expr(keys, t) for t in dict.fromkeys(role.publishes)),
        )
        for name, role in cfg.roles.items()
    )
    return BusAcl(subscribe=keys.everything, roles=roles)


def _read_text(path: Path, field_name: str) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{field_name}: cannot read {path}: {err.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{field_name}: {path} is not UTF-8 text") from None


def _parse_login_line(line: str, where: str) -> tuple[str, str]:
    user, sep, password = line.partition(":")
    if not sep or not user.strip() or not password:
        raise ConfigError(f"{where}: expected `user:password`")
    return user.strip(), password


def read_users_file(path: Path, field_name: str = f"{FIELD}.users_file") -> dict[str, str]:
    """User -> password from a zenoh dictionary file (`user:password` lines, blank lines skipped).

    ConfigError names the field and the line number, never the line.
    """
    users: dict[str, str] = {}
    for i, raw in enumerate(_read_text(path, field_name).splitlines(), start=1):
        line = raw.rstrip("\r\n")
        if not line.strip():
            continue
        user, password = _parse_login_line(line, f"{field_name}: {path} line {i}")
        if user in users:
            raise ConfigError(f"{field_name}: {path} line {i}: user {user!r} appears twice")
        users[user] = password
    if not users:
        raise ConfigError(f"{field_name}: {path} holds no `user:password` line")
    _warn_if_readable_by_others(path, field_name)
    return users


def _warn_if_readable_by_others(path: Path, field_name: str) -> None:
    try:
        mode = path.stat().st_mode
    except OSError:
        return
    if mode & 0o077:
        log.warning("%s: %s is readable by other users (chmod 600 it)", field_name, path)


def resolve_login(
    cfg: ZenohSecurityConfig,
    role: str,
    env: Mapping[str, str] | None = None,
    *,
    from_users_file: bool = False,
) -> Login:
    """The login of a process that holds `role`.

    Order: the environment (`user_env` and `password_env`, both or neither), then
    `credentials_file`, then the role's first user in `users_file`. `from_users_file` goes
    straight to the last (an embedded world in the ground loop's process). The user must hold
    `role` (ConfigError otherwise: its puts would be refused).
    """
    env = os.environ if env is None else env
    if role not in cfg.roles:
        raise ConfigError(f"{FIELD}.roles: no role {role!r} (have {', '.join(cfg.roles)})")
    login = None if from_users_file else _login_from_env(cfg, env)
    if login is None and not from_users_file and cfg.credentials_file is not None:
        text = _read_text(cfg.credentials_file, f"{FIELD}.credentials_file").strip()
        user, password = _parse_login_line(
            text, f"{FIELD}.credentials_file: {cfg.credentials_file}"
        )
        login = Login(user, password, f"file {cfg.credentials_file}")
    if login is None:
        login = _login_from_users_file(cfg, role)
    if login.user not in cfg.roles[role].users:
        raise ConfigError(
            f"{FIELD}.roles.{role}.users: user {login.user!r} ({login.source}) does not hold "
            f"role {role}; its puts would be refused"
        )
    return login


def _login_from_env(cfg: ZenohSecurityConfig, env: Mapping[str, str]) -> Login | None:
    user, password = env.get(cfg.user_env, ""), env.get(cfg.password_env, "")
    if not user and not password:
        return None
    if not user or not password:
        missing = cfg.user_env if not user else cfg.password_env
        raise ConfigError(
            f"{FIELD}.user_env / password_env: {cfg.user_env} and {cfg.password_env} go "
            f"together; {missing} is not set or empty"
        )
    return Login(user, password, f"environment {cfg.user_env}/{cfg.password_env}")


def _login_from_users_file(cfg: ZenohSecurityConfig, role: str) -> Login:
    if cfg.users_file is None:
        raise ConfigError(
            f"{FIELD}: no login for role {role}: set {cfg.user_env} and {cfg.password_env}, "
            "or credentials_file, or users_file"
        )
    users = read_users_file(cfg.users_file)
    for user in cfg.roles[role].users:
        if user in users:
            return Login(user, users[user], f"users file {cfg.users_file}")
    raise ConfigError(
        f"{FIELD}.users_file: {cfg.users_file} has no password for role {role} "
        f"(users {', '.join(cfg.roles[role].users)})"
    )


def _readable(path: Path, field_name: str) -> Path:
    _read_text(path, field_name)
    return path


def bus_security(
    cfg: ZenohSecurityConfig,
    mission: str,
    role: str,
    *,
    listens: bool,
    connects: bool,
    env: Mapping[str, str] | None = None,
    login_from_users_file: bool = False,
) -> BusSecurity | None:
    """The BusSecurity of a process holding `role` (None when security is off).

    A listening process checks logins against `users_file` and enforces the ACL; a connecting
    process logs in (`resolve_login`). With `tls`, a listener needs `cert_file` / `key_file` and
    a connecting process `ca_file`.
    """
    if not cfg.enabled:
        return None
    users_file: Path | None = None
    acl: BusAcl | None = None
    if listens:
        if cfg.users_file is None:
            raise ConfigError(f"{FIELD}.users_file: required by the process that listens")
        known = read_users_file(cfg.users_file)
        _warn_about_users_without_password(cfg, known)
        users_file, acl = cfg.users_file, bus_acl(cfg, Keys(mission))
    login = (
        resolve_login(cfg, role, env, from_users_file=login_from_users_file) if connects else None
    )
    tls = cfg.tls
    cert = key = ca = None
    if tls is not None:
        ca = _readable(tls.ca_file, f"{FIELD}.tls.ca_file")
        if listens:
            if tls.cert_file is None or tls.key_file is None:
                raise ConfigError(
                    f"{FIELD}.tls.cert_file / key_file: required by the process that listens"
                )
            cert = _readable(tls.cert_file, f"{FIELD}.tls.cert_file")
            key = _readable(tls.key_file, f"{FIELD}.tls.key_file")
    if login is not None:
        log.info("zenoh: logging in as %r (role %s, from %s)", login.user, role, login.source)
    return BusSecurity(
        user=login.user if login else None,
        password=login.password if login else None,
        users_file=users_file,
        acl=acl,
        tls_ca_file=ca,
        tls_cert_file=cert,
        tls_key_file=key,
        tls=tls is not None,
    )


def _warn_about_users_without_password(cfg: ZenohSecurityConfig, known: dict[str, str]) -> None:
    for name, role in cfg.roles.items():
        for user in role.users:
            if user not in known:
                log.warning(
                    "%s.roles.%s: user %r has no line in %s: it cannot log in",
                    FIELD,
                    name,
                    user,
                    cfg.users_file,
                )


def default_endpoint(cfg: ZenohSecurityConfig) -> str:
    """Where the ground loop listens by default: `tls/127.0.0.1:7447` with TLS on, else tcp."""
    proto = "tls" if cfg.enabled and cfg.tls is not None else "tcp"
    return f"{proto}/127.0.0.1:{DEFAULT_PORT}"


def secured_settings(
    cfg: ZenohSecurityConfig,
    mission: str,
    role: str,
    *,
    mode: BusMode = "peer",
    listen: tuple[str, ...] = (),
    connect: tuple[str, ...] = (),
    env: Mapping[str, str] | None = None,
    login_from_users_file: bool = False,
) -> BusSettings:
    """BusSettings for a process holding `role`, with `cfg`'s security when it is enabled."""
    security = bus_security(
        cfg,
        mission,
        role,
        listens=bool(listen),
        connects=bool(connect),
        env=env,
        login_from_users_file=login_from_users_file,
    )
    return BusSettings(mode=mode, listen=listen, connect=connect, security=security)
