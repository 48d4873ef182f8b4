"""Layering: pure math never imports I/O, and each I/O library has exactly one adapter.

Parsed from the source (ast), so a lazy import inside a function counts too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PURE = [
    *sorted((ROOT / "isac_mission" / "model").glob("*.py")),
    *sorted((ROOT / "isac_mission" / "tracking").glob("*.py")),
    *sorted((ROOT / "isac_mission" / "planning").glob("*.py")),
    *sorted((ROOT / "isac_mission" / "config").glob("*.py")),
    ROOT / "isac_mission" / "types.py",
    ROOT / "sim" / "vehicle.py",
    ROOT / "sim" / "target.py",
    ROOT / "sim" / "sensing.py",
]
IO_MODULES = {"zenoh", "pymavlink", "asyncio", "socket", "mavsdk", "subprocess", "threading"}


def imported_roots(path: Path) -> set[str]:
    """Top-level package names a module imports anywhere in its body."""
    roots: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            roots.add(node.module.split(".")[0])
    return roots


@pytest.mark.parametrize("path", PURE, ids=lambda p: str(p.relative_to(ROOT)))
def test_pure_modules_import_no_io(path: Path) -> None:
    assert imported_roots(path) & IO_MODULES == set()


@pytest.mark.parametrize(
    ("library", "adapter"),
    [("zenoh", "bus/session.py"), ("pymavlink", "mavwire/dialect.py")],
)
def test_each_io_library_has_one_adapter_in_the_package(library: str, adapter: str) -> None:
    users = {
        p.relative_to(ROOT).as_posix()
        for p in [*(ROOT / "isac_mission").rglob("*.py"), *(ROOT / "sim").rglob("*.py")]
        if library in imported_roots(p)
    }
    assert users <= {f"isac_mission/{adapter}"}


def test_the_checker_sees_imports_inside_functions(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    import zenoh\n    from asyncio import sleep\n")
    assert imported_roots(f) == {"zenoh", "asyncio"}
