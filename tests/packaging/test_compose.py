"""The deployment files as scripts/compose-check.sh relies on them (that check runs them in a real
Docker engine, in CI after the suite); here what can be read without an engine."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[2]


def _compose(name: str = "docker-compose.yml") -> dict[str, Any]:
    data = yaml.safe_load((ROOT / name).read_text())
    assert isinstance(data, dict)
    return data


def _grace_s(text: str) -> float:
    m = re.fullmatch(r"(\d+)(s|m)", text)
    assert m, text
    return float(m.group(1)) * (60.0 if m.group(2) == "m" else 1.0)


def test_every_service_is_on_the_host_network_so_that_its_sockets_stay_on_loopback() -> None:
    services = _compose()["services"]
    assert set(services) == {"world", "ground", "ground-vehicles"}
    for name, service in services.items():
        assert service["network_mode"] == "host", name
        assert "ports" not in service, name  # nothing published wider than the code binds


def test_the_ground_stops_first_and_has_time_to_land_the_fleet() -> None:
    services = _compose()["services"]
    ground, world = services["ground"], services["world"]
    assert ground["depends_on"] == ["world"]  # compose stops dependants first
    assert "depends_on" not in world
    for name in ("ground", "ground-vehicles"):
        assert services[name]["stop_signal"] == "SIGINT"  # Ctrl-C: land, then the summary
        # Descent from H = 100 m at about 1 m/s of simulation time, at real time, and the summary.
        assert _grace_s(services[name]["stop_grace_period"]) >= 200.0
    assert world["healthcheck"] == {"disable": True}
    assert "profiles" not in ground and "profiles" not in world
    assert services["ground-vehicles"]["profiles"] == ["vehicles"]


def test_the_image_runs_unprivileged_from_a_base_that_can_be_swapped() -> None:
    lines = [ln.strip() for ln in (ROOT / "Dockerfile").read_text().splitlines()]
    code = [ln for ln in lines if ln and not ln.startswith("#")]
    assert code[0] == "ARG BASE=python:3.11-slim"
    assert code[1] == "FROM ${BASE}"
    users = [ln.split()[1] for ln in code if ln.startswith("USER ")]
    assert users and users[-1] not in ("root", "0")
    health = next(ln for ln in code if ln.startswith("HEALTHCHECK"))
    assert "127.0.0.1:8080" in " ".join(code[code.index(health) :])
    ignored = (ROOT / ".dockerignore").read_text().split()
    assert "secrets" in ignored and ".venv" in ignored


def test_secrets_come_as_docker_secrets_not_in_the_image() -> None:
    secure = _compose("docker-compose.secure.yml")
    assert set(secure["secrets"]) == {"zenoh_users", "mavlink_key"}
    for name in ("world", "ground"):
        assert set(secure["services"][name]["secrets"]) == {"zenoh_users", "mavlink_key"}


def test_the_stand_in_base_takes_the_mirror_apt_is_configured_with(tmp_path: Path) -> None:
    def mirror(files: dict[str, str]) -> subprocess.CompletedProcess[str]:
        etc = tmp_path / f"etc{len(list(tmp_path.iterdir()))}"
        (etc / "sources.list.d").mkdir(parents=True)
        for rel, text in files.items():
            (etc / rel).write_text(text)
        return subprocess.run(
            ["bash", str(ROOT / "scripts/build-base-image.sh"), "--print-mirror"],
            env={"PATH": "/usr/bin:/bin", "ISAC_APT_ETC": str(etc)},
            capture_output=True,
            text=True,
            timeout=30,
        )

    deb822 = (
        "Types: deb\nURIs: http://security.example.invalid/debian-security\n"
        "Suites: bookworm-security\n\nTypes: deb\nURIs: http://mirror.example.invalid/debian\n"
    )
    got = mirror({"sources.list.d/debian.sources": deb822})
    assert got.stdout.strip() == "http://mirror.example.invalid/debian"
    one_line = "# a comment\ndeb [arch=amd64] http://old.example.invalid/debian bookworm main\n"
    got = mirror({"sources.list": one_line})
    assert got.stdout.strip() == "http://old.example.invalid/debian"
    got = mirror({})
    assert got.returncode != 0
