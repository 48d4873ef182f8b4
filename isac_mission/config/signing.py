"""MAVLink 2 signing: its config section, and the resolved key (from a file or the environment).

The scenario names where the key is, never the key itself; a resolved key's repr shows only a
fingerprint (docs/reliability.md).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from pydantic import Field

from isac_mission.config.sections import Section
from isac_mission.errors import ConfigError

DEFAULT_SIGNING_KEY_ENV = "ISAC_MAVLINK_SIGNING_KEY"
"""The environment variable that holds the MAVLink signing key unless the config names another."""
SIGNING_KEY_BYTES = 32
MIN_PASSPHRASE_CHARS = 8


class MavlinkSigningConfig(Section):
    """MAVLink 2 message signing between the vehicles and the service (docs/reliability.md).

    The file names where the key is, never the key itself: `key_file` if given, otherwise the
    environment variable `key_env`. The key text (surrounding whitespace stripped) is either
    64 hex digits, the 32-byte secret itself (`key_format: hex`), or a passphrase whose SHA-256
    is the secret (`key_format: passphrase`, as MAVProxy's `signing setup` derives it).
    """

    enabled: bool = Field(
        False, description="Sign every outgoing message; reject unsigned or badly signed ones."
    )
    key_file: Path | None = Field(
        None,
        description="File holding the key text (relative: from the working directory); "
        "takes precedence over key_env.",
    )
    key_env: str = Field(
        DEFAULT_SIGNING_KEY_ENV,
        pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
        description="Environment variable holding the key text, read when key_file is not set.",
    )
    key_format: Literal["hex", "passphrase"] = Field(
        "hex", description="hex: 64 hex digits; passphrase: secret = SHA-256(UTF-8 text)."
    )
    link_id: int = Field(0, ge=0, le=255, description="MAVLink link id in our signatures.")


@dataclass(frozen=True, repr=False)
class MavlinkSigningKey:
    """A resolved MAVLink signing key. Its repr and `fingerprint` never show the secret.

    Attributes:
        secret: The 32-byte secret key.
        link_id: Link id written into our signatures.
        source: Where the key came from ("environment variable X", "file P"), for logs.
    """

    secret: bytes
    link_id: int = 0
    source: str = ""

    def __post_init__(self) -> None:
        if len(self.secret) != SIGNING_KEY_BYTES:
            raise ValueError(f"a signing key has {SIGNING_KEY_BYTES} bytes, got {len(self.secret)}")
        if not 0 <= self.link_id <= 255:
            raise ValueError(f"link_id must be in [0, 255], got {self.link_id}")

    @property
    def fingerprint(self) -> str:
        """8 hex digits of SHA-256 over a label and the secret: tells keys apart in logs."""
        return hashlib.sha256(b"isac-mavlink-key-fingerprint:" + self.secret).hexdigest()[:8]

    def __repr__(self) -> str:
        return (
            f"MavlinkSigningKey(fingerprint={self.fingerprint}, link_id={self.link_id}, "
            f"source={self.source!r})"
        )


def _signing_key_text(cfg: MavlinkSigningConfig, where: str) -> tuple[str, str, str]:
    """(key text, its source for logs, the field to blame) from the file or the environment."""
    if cfg.key_file is not None:
        field_name = f"{where}.key_file"
        try:
            text = cfg.key_file.read_text(encoding="utf-8")
        except OSError as err:
            raise ConfigError(f"{field_name}: cannot read {cfg.key_file}: {err.strerror}") from None
        except UnicodeDecodeError:
            raise ConfigError(f"{field_name}: {cfg.key_file} is not UTF-8 text") from None
        return text.strip(), f"file {cfg.key_file}", field_name
    field_name = f"{where}.key_env"
    text = os.environ.get(cfg.key_env, "").strip()
    if not text:
        raise ConfigError(
            f"{field_name}: signing is enabled but the environment variable {cfg.key_env} "
            "is not set or empty (and no key_file is given)"
        )
    return text, f"environment variable {cfg.key_env}", field_name


def _secret_from_text(text: str, key_format: str, field_name: str) -> bytes:
    """The 32-byte secret of a key text; ConfigError naming the field (never the key)."""
    if not text:
        raise ConfigError(f"{field_name}: the key is empty")
    if key_format == "passphrase":
        if len(text) < MIN_PASSPHRASE_CHARS:
            raise ConfigError(
                f"{field_name}: a passphrase needs at least {MIN_PASSPHRASE_CHARS} characters "
                f"(got {len(text)})"
            )
        return hashlib.sha256(text.encode("utf-8")).digest()
    if len(text) != 2 * SIGNING_KEY_BYTES:
        raise ConfigError(
            f"{field_name}: a hex key has {2 * SIGNING_KEY_BYTES} hex digits "
            f"({SIGNING_KEY_BYTES} bytes), got {len(text)} characters"
        )
    try:
        secret = bytes.fromhex(text)
    except ValueError:
        raise ConfigError(f"{field_name}: the key has characters that are not hex digits") from None
    if not any(secret):
        raise ConfigError(f"{field_name}: an all-zero key is not a key (it disables signing)")
    return secret


def mavlink_signing_key(
    cfg: MavlinkSigningConfig, where: str = "security.mavlink_signing"
) -> MavlinkSigningKey | None:
    """The signing key `cfg` points at, or None when signing is off.

    Raises ConfigError naming the field (`where`.key_file or `where`.key_env) when the key is
    missing, unreadable or malformed; the message never contains the key.
    """
    if not cfg.enabled:
        return None
    text, source, field_name = _signing_key_text(cfg, where)
    secret = _secret_from_text(text, cfg.key_format, field_name)
    return MavlinkSigningKey(secret=secret, link_id=cfg.link_id, source=source)
