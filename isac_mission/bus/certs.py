"""Local secrets for a secured Zenoh bus: a CA and a TLS certificate for 127.0.0.1 / localhost
(made with the `cryptography` library, no external program), and a users file with random
passwords.

`isac-mission gen-certs DIR` and `isac-mission gen-users FILE` call these; the tests call them too,
into temporary folders. Private keys and the users file are written with mode 0600.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
import secrets
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from isac_mission.errors import ConfigError

SERVER_SAN: Final = "IP:127.0.0.1,DNS:localhost"
"""The names the listener's certificate holds: the loopback address and its name."""
PASSWORD_BYTES: Final = 24
CA_NAME: Final = "isac-mission local CA"


@dataclass(frozen=True)
class CertFiles:
    """What `generate_certs` wrote (PEM): the CA (certificate and key) and the listener's pair."""

    ca_file: Path
    ca_key_file: Path
    cert_file: Path
    key_file: Path


def _write_private(path: Path, data: bytes) -> None:
    """Write bytes readable by their owner only (mode 0600, also when replacing a file)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    path.chmod(0o600)


def _new_key(path: Path) -> ec.EllipticCurvePrivateKey:
    """A P-256 private key, written as unencrypted PKCS#8 PEM readable by its owner only."""
    key = ec.generate_private_key(ec.SECP256R1())
    pem = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )
    _write_private(path, pem)
    return key


def _name(common_name: str) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def _ca_certificate(key: ec.EllipticCurvePrivateKey, days: int) -> x509.Certificate:
    """The self-signed CA: may sign certificates (keyCertSign, cRLSign), nothing else."""
    now = dt.datetime.now(dt.UTC)
    public = key.public_key()
    return (
        x509.CertificateBuilder()
        .subject_name(_name(CA_NAME))
        .issuer_name(_name(CA_NAME))
        .public_key(public)
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=False,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(public), critical=False)
        .sign(key, hashes.SHA256())
    )


def _server_certificate(
    key: ec.EllipticCurvePrivateKey,
    ca_key: ec.EllipticCurvePrivateKey,
    ca: x509.Certificate,
    days: int,
) -> x509.Certificate:
    """The listener's certificate, signed by the CA, for 127.0.0.1 and localhost (SERVER_SAN),
    for both server and client use."""
    now = dt.datetime.now(dt.UTC)
    return (
        x509.CertificateBuilder()
        .subject_name(_name("localhost"))
        .issuer_name(ca.subject)
        .public_key(key.public_key())
        .serial_number(secrets.randbits(63) | 1)
        .not_valid_before(now - dt.timedelta(minutes=5))
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(
            x509.SubjectAlternativeName(
                [x509.IPAddress(ipaddress.ip_address("127.0.0.1")), x509.DNSName("localhost")]
            ),
            critical=False,
        )
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=False,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())
    )


def generate_certs(out_dir: Path, *, days: int = 365, force: bool = False) -> CertFiles:
    """Write ca.pem, ca-key.pem, server.pem and server-key.pem into `out_dir`.

    The CA is self-signed; server.pem is signed by it for 127.0.0.1 and localhost (subject
    alternative names), for both server and client use; keys are P-256 (PKCS#8 PEM, mode 0600),
    signatures SHA-256, validity `days` from now. Refuses to overwrite existing files unless
    `force`.
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
    ca_key = _new_key(files.ca_key_file)
    ca = _ca_certificate(ca_key, days)
    files.ca_file.write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    key = _new_key(files.key_file)
    cert = _server_certificate(key, ca_key, ca, days)
    files.cert_file.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
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
