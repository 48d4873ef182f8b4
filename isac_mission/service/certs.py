"""Local secrets for a secured Zenoh bus: a CA and a TLS certificate for 127.0.0.1 / localhost
(through the `openssl` command), and a users file with random passwords.

`isac-mission gen-certs DIR` and `isac-mission gen-users FILE` call these; the tests call them too,
into temporary folders. Private keys and the users file are written with mode 0600.
"""

from __future__ import annotations

import os
import secrets
import shutil
import subprocess
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from isac_mission.errors import ConfigError

SERVER_SAN: Final = "IP:127.0.0.1,DNS:localhost"
"""The names the listener's certificate holds: the loopback address and its name."""
PASSWORD_BYTES: Final = 24


@dataclass(frozen=True)
class CertFiles:
    """What `generate_certs` wrote (PEM): the CA (certificate and key) and the listener's pair."""

    ca_file: Path
    ca_key_file: Path
    cert_file: Path
    key_file: Path


def _openssl(args: list[str], openssl: str) -> None:
    exe = shutil.which(openssl)
    if exe is None:
        raise ConfigError(f"gen-certs: {openssl!r} is not on PATH (install OpenSSL)")
    proc = subprocess.run([exe, *args], capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise ConfigError(f"gen-certs: openssl {args[0]} failed: {proc.stderr.strip()[-500:]}")


def _new_key(path: Path, openssl: str) -> None:
    """A P-256 private key (PKCS#8 PEM), readable by its owner only."""
    _openssl(
        ["genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", str(path)],
        openssl,
    )
    path.chmod(0o600)


def generate_certs(
    out_dir: Path, *, days: int = 365, force: bool = False, openssl: str = "openssl"
) -> CertFiles:
    """Write ca.pem, ca-key.pem, server.pem and server-key.pem into `out_dir`.

    The CA is self-signed; server.pem is signed by it for 127.0.0.1 and localhost (subject
    alternative names), for both server and client use. Refuses to overwrite existing files
    unless `force`.
    """
    if days < 1:
        raise ConfigError(f"gen-certs: days must be >= 1, got {days}")
    out_dir.mkdir(parents=True, exist_ok=True)
    files = CertFiles(
        out_dir / "ca.pem",
        out_dir / "ca-key.pem",
        out_dir / "server.pem",
        out_dir / "server-key.pem",
    )
    existing = [p for p in vars(files).values() if p.exists()]
    if existing and not force:
        raise ConfigError(f"gen-certs: {existing[0]} exists (use --force to replace)")
    _new_key(files.ca_key_file, openssl)
    _openssl(
        [
            "req", "-x509", "-new", "-key", str(files.ca_key_file), "-sha256", "-days", str(days),
            "-subj", "/CN=isac-mission local CA", "-out", str(files.ca_file),
            "-addext", "basicConstraints=critical,CA:TRUE",
            "-addext", "keyUsage=critical,keyCertSign,cRLSign",
        ],
        openssl,
    )  # fmt: skip
    _new_key(files.key_file, openssl)
    csr, ext = out_dir / "server.csr", out_dir / "server-ext.cnf"
    ext.write_text(
        f"subjectAltName={SERVER_SAN}\n"
        "basicConstraints=critical,CA:FALSE\n"
        "keyUsage=critical,digitalSignature\n"
        "extendedKeyUsage=serverAuth,clientAuth\n"
    )
    try:
        _openssl(
            ["req", "-new", "-key", str(files.key_file), "-subj", "/CN=localhost",
             "-out", str(csr)],
            openssl,
        )  # fmt: skip
        _openssl(
            [
                "x509", "-req", "-in", str(csr), "-CA", str(files.ca_file),
                "-CAkey", str(files.ca_key_file), "-set_serial", str(secrets.randbits(63)),
                "-days", str(days), "-sha256", "-extfile", str(ext), "-out", str(files.cert_file),
            ],
            openssl,
        )  # fmt: skip
    finally:
        csr.unlink(missing_ok=True)
        ext.unlink(missing_ok=True)
    return files


def generate_users_file(path: Path, users: Iterable[str], *, force: bool = False) -> list[str]:
    """Write `user:password` lines with random passwords (mode 0600); returns the users.

    Refuses to overwrite an existing file unless `force`.
    """
    names = list(dict.fromkeys(users))
    if not names:
        raise ConfigError("gen-users: no users to write")
    for name in names:
        if not name or ":" in name or any(c.isspace() for c in name):
            raise ConfigError(f"gen-users: user name {name!r} must not be empty or hold ':'")
    if path.exists() and not force:
        raise ConfigError(f"gen-users: {path} exists (use --force to replace)")
    path.parent.mkdir(parents=True, exist_ok=True)
    text = "".join(f"{u}:{secrets.token_urlsafe(PASSWORD_BYTES)}\n" for u in names)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    path.chmod(0o600)
    return names
