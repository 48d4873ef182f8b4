"""security.mavlink_signing: where the key comes from, how its text becomes the 32-byte secret,
and clear errors (naming the field, never the key) when it is missing or malformed."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from isac_mission.config import (
    DEFAULT_SIGNING_KEY_ENV,
    MavlinkSigningKey,
    load_scenario,
    parse_scenario,
)
from isac_mission.errors import ConfigError

HEX_KEY = "0f1e2d3c4b5a69788796a5b4c3d2e1f00112233445566778899aabbccddeeff0"
OTHER_HEX_KEY = "ff" * 31 + "01"


@pytest.fixture(autouse=True)
def no_key_in_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each test starts without the default key variable, whatever the shell has."""
    monkeypatch.delenv(DEFAULT_SIGNING_KEY_ENV, raising=False)


def signing(**fields: Any) -> dict[str, Any]:
    """A scenario mapping with these security.mavlink_signing fields."""
    return {"security": {"mavlink_signing": fields}}


def test_signing_is_off_by_default_and_needs_no_key() -> None:
    s = parse_scenario({})
    assert not s.security.mavlink_signing.enabled
    assert s.mavlink_signing_key is None
    # A key in the environment does not turn signing on by itself.
    assert parse_scenario(signing(enabled=False, key_env="PATH")).mavlink_signing_key is None


def test_hex_key_from_the_default_environment_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(DEFAULT_SIGNING_KEY_ENV, f"  {HEX_KEY}\n")
    key = parse_scenario(signing(enabled=True, link_id=7)).mavlink_signing_key
    assert key is not None
    assert key.secret == bytes.fromhex(HEX_KEY)
    assert key.link_id == 7
    assert key.source == f"environment variable {DEFAULT_SIGNING_KEY_ENV}"


def test_key_from_a_named_environment_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MY_FLEET_KEY", HEX_KEY.upper())
    key = parse_scenario(signing(enabled=True, key_env="MY_FLEET_KEY")).mavlink_signing_key
    assert key is not None and key.secret == bytes.fromhex(HEX_KEY)


def test_key_file_takes_precedence_over_the_environment(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(DEFAULT_SIGNING_KEY_ENV, OTHER_HEX_KEY)
    path = tmp_path / "mavlink.key"
    path.write_text(HEX_KEY + "\n")
    key = parse_scenario(signing(enabled=True, key_file=str(path))).mavlink_signing_key
    assert key is not None
    assert key.secret == bytes.fromhex(HEX_KEY)
    assert key.source == f"file {path}"


def test_passphrase_secret_is_its_sha256(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(DEFAULT_SIGNING_KEY_ENV, "correct horse battery staple\n")
    key = parse_scenario(signing(enabled=True, key_format="passphrase")).mavlink_signing_key
    assert key is not None
    assert key.secret == hashlib.sha256(b"correct horse battery staple").digest()


def test_yaml_file_with_signing_loads(tmp_path: Path) -> None:
    key_path = tmp_path / "key.hex"
    key_path.write_text(HEX_KEY)
    cfg = tmp_path / "s.yaml"
    cfg.write_text(yaml.safe_dump(signing(enabled=True, key_file=str(key_path))))
    key = load_scenario(cfg).mavlink_signing_key
    assert key is not None and key.secret == bytes.fromhex(HEX_KEY)


@pytest.mark.parametrize(
    ("fields", "env", "expected"),
    [
        (
            {"enabled": True},
            None,
            "security.mavlink_signing.key_env: signing is enabled but the environment variable "
            f"{DEFAULT_SIGNING_KEY_ENV} is not set or empty (and no key_file is given)",
        ),
        ({"enabled": True}, "   \n", f"{DEFAULT_SIGNING_KEY_ENV} is not set or empty"),
        (
            {"enabled": True},
            HEX_KEY[:10],
            "security.mavlink_signing.key_env: a hex key has 64 hex digits (32 bytes), "
            "got 10 characters",
        ),
        (
            {"enabled": True},
            "zz" + HEX_KEY[2:],
            "security.mavlink_signing.key_env: the key has characters that are not hex digits",
        ),
        ({"enabled": True}, "00" * 32, "an all-zero key is not a key"),
        (
            {"enabled": True, "key_format": "passphrase"},
            "short",
            "security.mavlink_signing.key_env: a passphrase needs at least 8 characters (got 5)",
        ),
        ({"enabled": True, "key_format": "base64"}, HEX_KEY, "security.mavlink_signing.key_format"),
        ({"enabled": True, "link_id": 256}, HEX_KEY, "security.mavlink_signing.link_id"),
        ({"enabled": True, "key_env": "NOT-A-NAME"}, HEX_KEY, "security.mavlink_signing.key_env"),
        # The key itself has no place in the file.
        ({"enabled": True, "key": HEX_KEY}, HEX_KEY, "security.mavlink_signing.key: unknown key"),
    ],
)
def test_bad_signing_config_names_the_field_and_never_the_key(
    monkeypatch: pytest.MonkeyPatch, fields: dict[str, Any], env: str | None, expected: str
) -> None:
    if env is not None:
        monkeypatch.setenv(DEFAULT_SIGNING_KEY_ENV, env)
    with pytest.raises(ConfigError) as err:
        parse_scenario(signing(**fields), "x.yaml")
    text = str(err.value)
    assert text.startswith("x.yaml: ")
    assert expected in text
    assert HEX_KEY not in text and HEX_KEY[:10] not in text


def test_missing_or_unreadable_key_file_names_the_field(tmp_path: Path) -> None:
    missing = tmp_path / "nope.key"
    with pytest.raises(ConfigError) as err:
        parse_scenario(signing(enabled=True, key_file=str(missing)), "x.yaml")
    assert str(err.value) == (
        f"x.yaml: security.mavlink_signing.key_file: cannot read {missing}: "
        "No such file or directory"
    )
    with pytest.raises(ConfigError, match=r"key_file: cannot read .*: Is a directory"):
        parse_scenario(signing(enabled=True, key_file=str(tmp_path)), "x.yaml")
    binary = tmp_path / "binary.key"
    binary.write_bytes(b"\xff\xfe\x00" * 20)
    with pytest.raises(ConfigError, match=r"key_file: .* is not UTF-8 text"):
        parse_scenario(signing(enabled=True, key_file=str(binary)), "x.yaml")
    short = tmp_path / "short.key"
    short.write_text(HEX_KEY[:-2])
    with pytest.raises(ConfigError, match="key_file: a hex key has 64 hex digits"):
        parse_scenario(signing(enabled=True, key_file=str(short)), "x.yaml")


def test_the_secret_is_not_in_the_scenario_repr_nor_its_trace_config(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv(DEFAULT_SIGNING_KEY_ENV, HEX_KEY)
    s = parse_scenario(signing(enabled=True))
    key = s.mavlink_signing_key
    assert key is not None
    for text in (repr(s), str(s), repr(key), json.dumps(s.trace_config())):
        assert HEX_KEY not in text.lower()
        assert key.secret.hex() not in text and repr(key.secret) not in text
    assert key.fingerprint in repr(key)
    assert "mavlink_signing" not in json.dumps(s.trace_config())


def test_fingerprints_tell_keys_apart_and_keys_have_32_bytes() -> None:
    a = MavlinkSigningKey(bytes.fromhex(HEX_KEY))
    b = MavlinkSigningKey(bytes.fromhex(OTHER_HEX_KEY))
    assert a.fingerprint != b.fingerprint
    assert len(a.fingerprint) == 8
    with pytest.raises(ValueError, match="32 bytes, got 31"):
        MavlinkSigningKey(bytes(31))
