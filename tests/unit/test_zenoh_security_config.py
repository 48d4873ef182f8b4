"""security.zenoh: validation, where logins come from, and the zenoh config it produces."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from isac_mission.bus import BusSecurity, BusSettings, acl_json, make_config
from isac_mission.bus.certs import generate_users_file
from isac_mission.bus.security import (
    bus_acl,
    bus_security,
    default_endpoint,
    read_users_file,
    resolve_login,
    secured_settings,
)
from isac_mission.config import ZenohSecurityConfig, ZenohTlsConfig, load_scenario
from isac_mission.errors import ConfigError
from isac_mission.wire import Keys

ROOT = Path(__file__).resolve().parents[2]
SECRET = "s3cret-Passw0rd"
ENDPOINT = "tcp/127.0.0.1:7447"


@pytest.fixture
def users_file(tmp_path: Path) -> Path:
    path = tmp_path / "users.txt"
    path.write_text(f"ground:g-{SECRET}\nworld:w-{SECRET}\n\nobserver:o-{SECRET}\n")
    path.chmod(0o600)
    return path


def secured(users_file: Path, **changes: object) -> ZenohSecurityConfig:
    return ZenohSecurityConfig.model_validate(
        {"enabled": True, "users_file": users_file, **changes}
    )


def load_with(tmp_path: Path, zenoh: dict[str, object]) -> ZenohSecurityConfig:
    data = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    data.setdefault("security", {})["zenoh"] = zenoh
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_scenario(path).security.zenoh


def test_off_by_default_and_settings_stay_unsecured_loopback() -> None:
    cfg = ZenohSecurityConfig()
    assert not cfg.enabled
    s = secured_settings(cfg, "paper", "world", connect=(ENDPOINT,))
    assert s == BusSettings(connect=(ENDPOINT,)) and s.security is None
    assert default_endpoint(cfg) == ENDPOINT


def test_a_scenario_file_turns_it_on_with_the_default_roles(tmp_path: Path) -> None:
    cfg = load_with(tmp_path, {"enabled": True, "users_file": "secrets/users.txt"})
    assert cfg.enabled and cfg.users_file == Path("secrets/users.txt")
    assert cfg.roles["ground"].publishes == [
        "plan",
        "track",
        "health",
        "telemetry",
        "control/reply",
        "fleet",
    ]
    assert cfg.roles["world"].publishes == ["clock", "truth", "detections", "telemetry"]
    assert cfg.roles["operator"].publishes == ["control"]
    assert cfg.roles["observer"].publishes == []


@pytest.mark.parametrize(
    ("zenoh", "message"),
    [
        ({"password": "x"}, r"security\.zenoh\.password: unknown key"),
        ({"roles": {"world": {"users": ["world"]}}}, r"needs a ground role"),
        (
            {"roles": {"ground": {"users": ["a"]}, "world": {"users": ["a"]}}},
            r"user 'a' is in both ground and world",
        ),
        (
            {"roles": {"ground": {"users": ["g:x"]}, "world": {"users": ["w"]}}},
            r"security\.zenoh\.roles\.ground.*users: 'g:x' must use letters",
        ),
        (
            {
                "roles": {
                    "ground": {"users": ["g"], "publishes": ["everything"]},
                    "world": {"users": ["w"]},
                }
            },
            r"security\.zenoh\.roles\.ground\.publishes\.0",
        ),
        ({"roles": {"ground": {"users": []}, "world": {"users": ["w"]}}}, r"roles\.ground\.users"),
        ({"user_env": "NOT-A-NAME"}, r"security\.zenoh\.user_env"),
        (
            {"tls": {"ca_file": "ca.pem", "cert_file": "s.pem"}},
            r"cert_file and key_file go together",
        ),
        ({"tls": {"cert_file": "s.pem", "key_file": "k.pem"}}, r"security\.zenoh\.tls\.ca_file"),
    ],
)
def test_invalid_sections_name_the_field(
    tmp_path: Path, zenoh: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        load_with(tmp_path, {"enabled": True, **zenoh})


def test_login_comes_from_env_then_credentials_file_then_users_file(
    users_file: Path, tmp_path: Path
) -> None:
    creds = tmp_path / "world.cred"
    creds.write_text(f"world:from-file-{SECRET}\n")
    cfg = secured(users_file, credentials_file=creds)
    env = {"ISAC_ZENOH_USER": "world", "ISAC_ZENOH_PASSWORD": f"from-env-{SECRET}"}
    assert resolve_login(cfg, "world", env).password == f"from-env-{SECRET}"
    assert resolve_login(cfg, "world", {}).password == f"from-file-{SECRET}"
    from_users = resolve_login(secured(users_file), "world", {})
    assert (from_users.user, from_users.password) == ("world", f"w-{SECRET}")
    # The embedded world ignores this process's own login and uses the users file.
    embedded = resolve_login(cfg, "world", env, from_users_file=True)
    assert embedded.password == f"w-{SECRET}"
    assert SECRET not in repr(embedded)


def test_a_login_must_be_complete_and_hold_the_role(users_file: Path) -> None:
    cfg = secured(users_file)
    with pytest.raises(ConfigError, match="ISAC_ZENOH_PASSWORD is not set"):
        resolve_login(cfg, "world", {"ISAC_ZENOH_USER": "world"})
    env = {"ISAC_ZENOH_USER": "ground", "ISAC_ZENOH_PASSWORD": SECRET}
    with pytest.raises(ConfigError, match=r"roles\.world\.users: user 'ground'.*does not hold"):
        resolve_login(cfg, "world", env)
    with pytest.raises(ConfigError, match="no login for role world"):
        resolve_login(ZenohSecurityConfig(enabled=True), "world", {})
    with pytest.raises(ConfigError, match="no role 'pilot'"):
        resolve_login(cfg, "pilot", env)


def test_users_file_errors_name_the_field_and_line_but_no_secret(tmp_path: Path) -> None:
    bad = tmp_path / "users.txt"
    bad.write_text(f"ground:{SECRET}\nworld{SECRET}\n")
    with pytest.raises(ConfigError, match=r"users_file: .* line 2: expected `user:password`") as e:
        read_users_file(bad)
    assert SECRET not in str(e.value)
    bad.write_text(f"world:{SECRET}\nworld:{SECRET}2\n")
    with pytest.raises(ConfigError, match="line 2: user 'world' appears twice"):
        read_users_file(bad)
    with pytest.raises(ConfigError, match=r"security\.zenoh\.users_file: cannot read"):
        read_users_file(tmp_path / "missing.txt")


def test_the_listener_needs_a_users_file_and_its_tls_files(
    users_file: Path, tmp_path: Path
) -> None:
    with pytest.raises(ConfigError, match=r"security\.zenoh\.users_file: required"):
        bus_security(
            ZenohSecurityConfig(enabled=True), "paper", "ground", listens=True, connects=False
        )
    tls = ZenohTlsConfig(ca_file=tmp_path / "ca.pem")
    (tmp_path / "ca.pem").write_text("not checked here")
    with pytest.raises(ConfigError, match=r"tls\.cert_file / key_file: required"):
        bus_security(secured(users_file, tls=tls), "paper", "ground", listens=True, connects=False)
    missing = ZenohTlsConfig(ca_file=tmp_path / "nope.pem")
    with pytest.raises(ConfigError, match=r"security\.zenoh\.tls\.ca_file: cannot read"):
        bus_security(
            secured(users_file, tls=missing), "paper", "world", listens=False, connects=True
        )


def test_acl_denies_by_default_and_lets_each_role_put_on_its_keys(users_file: Path) -> None:
    acl = acl_json(bus_acl(secured(users_file), Keys("paper")))
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    assert rules["publish-ground"]["key_exprs"] == [
        "isac/paper/plan",
        "isac/paper/track",
        "isac/paper/health",
        "isac/paper/telemetry/*",
        "isac/paper/control/reply",
        "isac/paper/fleet",
    ]
    assert rules["publish-world"]["key_exprs"] == [
        "isac/paper/clock",
        "isac/paper/truth",
        "isac/paper/detections/*",
        "isac/paper/telemetry/*",
    ]
    assert all(r["flows"] == ["ingress"] for k, r in rules.items() if k.startswith("publish-"))
    assert "publish-observer" not in rules  # read only
    assert rules["subscribe"]["key_exprs"] == ["isac/paper/**"]
    policies = {p["id"]: p for p in acl["policies"]}
    assert policies["publish-world"]["subjects"] == ["role-world"]
    assert set(policies["everyone"]["subjects"]) == {
        "role-ground",
        "role-world",
        "role-operator",
        "role-observer",
    }
    subjects = {s["id"]: s["usernames"] for s in acl["subjects"]}
    assert subjects == {
        "role-ground": ["ground"],
        "role-world": ["world"],
        "role-operator": ["operator"],
        "role-observer": ["observer"],
    }
    assert rules["publish-operator"]["key_exprs"] == ["isac/paper/control"]


def test_secured_configs_keep_loopback_and_no_multicast(users_file: Path, tmp_path: Path) -> None:
    for name in ("ca.pem", "s.pem", "k.pem"):
        (tmp_path / name).write_text("pem")
    tls = ZenohTlsConfig(
        ca_file=tmp_path / "ca.pem", cert_file=tmp_path / "s.pem", key_file=tmp_path / "k.pem"
    )
    cfg = secured(users_file, tls=tls)
    assert default_endpoint(cfg) == "tls/127.0.0.1:7447"
    hub = secured_settings(cfg, "paper", "ground", listen=("tls/127.0.0.1:7447",))
    world = secured_settings(
        cfg, "paper", "world", connect=("tls/127.0.0.1:7447",), login_from_users_file=True
    )
    hub_cfg, world_cfg = make_config(hub), make_config(world)
    for zc in (hub_cfg, world_cfg):
        assert json.loads(zc.get_json("scouting/multicast/enabled")) is False
        assert json.loads(zc.get_json("transport/link/tls/root_ca_certificate")) == str(
            tmp_path / "ca.pem"
        )
    assert json.loads(hub_cfg.get_json("listen/endpoints")) == ["tls/127.0.0.1:7447"]
    assert json.loads(hub_cfg.get_json("transport/auth/usrpwd/dictionary_file")) == str(users_file)
    assert json.loads(hub_cfg.get_json("access_control/enabled")) is True
    assert json.loads(hub_cfg.get_json("transport/link/tls/listen_certificate")) == str(
        tmp_path / "s.pem"
    )
    assert json.loads(world_cfg.get_json("transport/auth/usrpwd/user")) == "world"
    assert json.loads(world_cfg.get_json("access_control/enabled")) is False
    assert SECRET not in repr(world) and SECRET not in repr(world.security)


@pytest.mark.parametrize(
    ("security", "endpoint", "message"),
    [
        (BusSecurity(tls=True, tls_ca_file=Path("ca.pem")), ENDPOINT, "with TLS on use tls/"),
        (BusSecurity(), "tls/127.0.0.1:7447", "with TLS off use tcp/"),
        (None, "tls/127.0.0.1:7447", "tls/ endpoints need security settings"),
        (BusSecurity(user="world"), ENDPOINT, "needs both a user and a password"),
    ],
)
def test_bus_settings_refuse_security_that_does_not_fit(
    security: BusSecurity | None, endpoint: str, message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        BusSettings(connect=(endpoint,), security=security)


def test_gen_users_writes_random_private_passwords(tmp_path: Path) -> None:
    path = tmp_path / "users.txt"
    assert generate_users_file(path, ["ground", "world", "world"]) == ["ground", "world"]
    users = read_users_file(path)
    assert set(users) == {"ground", "world"} and users["ground"] != users["world"]
    assert len(users["world"]) >= 32 and path.stat().st_mode & 0o077 == 0
    with pytest.raises(ConfigError, match="exists"):
        generate_users_file(path, ["ground"])
    with pytest.raises(ConfigError, match="must not be empty or hold ':'"):
        generate_users_file(tmp_path / "u2.txt", ["a:b"])


def test_gen_users_command_prints_the_users_but_no_password(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from isac_mission.cli import app

    path = tmp_path / "users.txt"
    result = CliRunner().invoke(app, ["gen-users", str(path)])
    assert result.exit_code == 0, result.output
    users = read_users_file(path)
    assert list(users) == ["ground", "world", "operator", "observer"]
    assert all(password not in result.output for password in users.values())
    again = CliRunner().invoke(app, ["gen-users", str(path)])
    assert again.exit_code == 1 and read_users_file(path) == users
