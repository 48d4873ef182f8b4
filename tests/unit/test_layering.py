"""Layering: the tree is the block diagram (docs/architecture.md, "What may import what").

Pure math never imports I/O; each I/O library has exactly one adapter package; no module
imports itself round a circle (imports under TYPE_CHECKING included: a circle of types is still a
circle of design); `sim/` and the service are peers on the neutral layer and import neither each other nor the command line
(the embedded entry alone imports `sim`; the command line calls the service's assembly, never
the other way round); no module holds two jobs' worth of lines.

Imports are parsed from the source (ast), so a lazy import inside a function counts too, and
relative imports are resolved against the module's package. Each rule is a function of the
repository root that lists its violations, so the tests below can also show that it finds one
in a small tree made for the purpose.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("isac_mission", "sim")
"""The code under the rules (tests, bench and scripts are not)."""

IO_MODULES = ("zenoh", "pymavlink", "asyncio", "socket", "mavsdk", "subprocess", "threading")
"""What a pure module may not import."""

PURE = (
    "isac_mission/model",
    "isac_mission/tracking",
    "isac_mission/planning",
    "isac_mission/config",
    "isac_mission/types.py",
    "sim/vehicle.py",
    "sim/target.py",
    "sim/sensing.py",
    "sim/scenes.py",
    "sim/multi_target_scene.py",
    "sim/impairment.py",
)
"""Pure modules and packages: numbers in, numbers out (numpy, scipy, cvxpy, filterpy ...)."""

ADAPTERS = {
    "zenoh": "isac_mission/bus/session.py",
    "pymavlink": "isac_mission/mavwire/dialect.py",
    "starlette": "isac_mission/console",
    "uvicorn": "isac_mission/console",
}
"""Library -> the one module or package (in isac_mission and sim alike) that may import it:
ZenohBus's session, the dialect module that sets MAVLINK20 and the dialect before pymavlink
loads, and the operator console for the web server."""

NEUTRAL = (
    "isac_mission/timebase.py",
    "isac_mission/frames.py",
    "isac_mission/wire",
    "isac_mission/bus",
    "isac_mission/mavwire",
    "isac_mission/records",
    "isac_mission/config",
    "isac_mission/tracking",
)
"""The layer both peers stand on: it imports neither peer, nor the offline experiments."""

CONSOLE = "isac_mission/console"
"""The operator console: an I/O adapter, a peer of the service on the neutral layer."""
CONSOLE_MAY_IMPORT = (
    "isac_mission.wire",
    "isac_mission.bus",
    "isac_mission.records",
    "isac_mission.config",
    "isac_mission.errors",
    "isac_mission.types",
    "isac_mission.console",
)
"""What the console may import of the project: the neutral layer (and the error and array
types), never the service, the planner, `sim`, the experiments or the command line."""

SERVICE = "isac_mission.service"
CLI = "isac_mission.cli"
EMBEDDED = "isac_mission/cli/embedded.py"
"""The one module that imports both `sim` and the service (`isac-mission run`)."""


# --------------------------------------------------------------------------------------------
# The checker


def module_name(path: Path, root: Path) -> str:
    """Dotted module name of a file under root: `sim/world.py` -> `sim.world`."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(node: ast.ImportFrom, path: Path, root: Path) -> str:
    """The absolute module of a `from ... import` (relative ones against the file's package)."""
    if node.level == 0:
        return node.module or ""
    package = module_name(path, root).split(".")
    if path.name != "__init__.py":
        package.pop()
    base = package[: len(package) - (node.level - 1)]
    return ".".join([*base, *([node.module] if node.module else [])])


def imported_modules(path: Path, root: Path = ROOT) -> set[str]:
    """Every module a file imports anywhere in its body, as dotted names.

    `from a.b import c` counts as both `a.b` and `a.b.c` (c may be a module); relative imports
    are resolved against the file's package under root.
    """
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            module = _resolve(node, path, root)
            if module:
                found.add(module)
            found.update(f"{module}.{a.name}" if module else a.name for a in node.names)
    return found


def imported_roots(path: Path, root: Path = ROOT) -> set[str]:
    """Top-level package names a module imports anywhere in its body."""
    return {name.split(".")[0] for name in imported_modules(path, root)}


def within(name: str, package: str) -> bool:
    """True if dotted `name` is `package` or inside it."""
    return name == package or name.startswith(package + ".")


def python_files(root: Path, where: Iterable[str] = PACKAGES) -> Iterator[Path]:
    """The .py files of the given packages or files (relative to root), sorted."""
    for rel in where:
        target = root / rel
        if target.is_file():
            yield target
        elif target.is_dir():
            yield from sorted(target.rglob("*.py"))


def _rel(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix()


def _inside(path: Path, root: Path, rel: str) -> bool:
    """True if path is the file `rel` or lies in the folder `rel` (both under root)."""
    p = _rel(path, root)
    return p == rel or p.startswith(rel.rstrip("/") + "/")


# --------------------------------------------------------------------------------------------
# The rules: each lists its violations as "<file>: <what>"


def pure_io_violations(root: Path) -> list[str]:
    """Pure modules that import an I/O library."""
    out = []
    for path in python_files(root, PURE):
        bad = sorted(imported_roots(path, root) & set(IO_MODULES))
        if bad:
            out.append(f"{_rel(path, root)}: imports {', '.join(bad)}")
    return out


def adapter_violations(root: Path, library: str, adapter: str) -> list[str]:
    """Modules other than `adapter` (a file or a folder; in isac_mission and sim) that import
    `library`."""
    return [
        f"{_rel(path, root)}: imports {library} (only {adapter} may)"
        for path in python_files(root)
        if library in imported_roots(path, root) and not _inside(path, root, adapter)
    ]


def sim_violations(root: Path) -> list[str]:
    """Modules of sim/ that import the service or the command line."""
    out = []
    for path in python_files(root, ["sim"]):
        bad = sorted(
            m for m in imported_modules(path, root) if within(m, SERVICE) or within(m, CLI)
        )
        if bad:
            out.append(f"{_rel(path, root)}: imports {', '.join(bad)}")
    return out


def service_violations(root: Path) -> list[str]:
    """Modules of the service that import the command line (the command line parses options,
    prints, and calls the service's assembly: the service takes what it needs as ports)."""
    out = []
    for path in python_files(root, ["isac_mission/service"]):
        bad = sorted(m for m in imported_modules(path, root) if within(m, CLI))
        if bad:
            out.append(f"{_rel(path, root)}: imports {', '.join(bad)}")
    return out


def sim_importer_violations(root: Path) -> list[str]:
    """Modules of isac_mission that import `sim`: only the embedded entry may (it runs the
    world, alone for `isac-mission sim` or beside the service for `run`)."""
    return [
        f"{_rel(path, root)}: imports sim (only {EMBEDDED} may)"
        for path in python_files(root, ["isac_mission"])
        if _rel(path, root) != EMBEDDED
        and any(within(m, "sim") for m in imported_modules(path, root))
    ]


def neutral_violations(root: Path) -> list[str]:
    """Modules of the neutral layer that import the service, sim, the experiments or the CLI."""
    banned = (SERVICE, "sim", "isac_mission.experiment", CLI)
    out = []
    for path in python_files(root, NEUTRAL):
        bad = sorted(m for m in imported_modules(path, root) if any(within(m, b) for b in banned))
        if bad:
            out.append(f"{_rel(path, root)}: imports {', '.join(bad)}")
    return out


def console_violations(root: Path) -> list[str]:
    """Console modules importing more of the project than the neutral layer, and service
    modules importing the console (the two are peers)."""
    out = []
    for path in python_files(root, [CONSOLE]):
        bad = sorted(
            m
            for m in imported_modules(path, root)
            if within(m, "isac_mission")
            and m != "isac_mission"
            and not any(within(m, ok) for ok in CONSOLE_MAY_IMPORT)
        )
        bad += sorted(m for m in imported_modules(path, root) if within(m, "sim"))
        if bad:
            out.append(f"{_rel(path, root)}: imports {', '.join(bad)}")
    for path in python_files(root, ["isac_mission/service"]):
        bad = sorted(m for m in imported_modules(path, root) if within(m, "isac_mission.console"))
        if bad:
            out.append(f"{_rel(path, root)}: imports {', '.join(bad)}")
    return out


def import_graph(root: Path) -> dict[str, set[str]]:
    """Module -> the modules of the packages it imports (every import statement, lazy and
    TYPE_CHECKING ones included). An imported name that is not a module counts as its module
    (`from a.b import f` -> `a.b`); a package's own ancestors are no edge (importing `a.b.c`
    runs `a/__init__` first whatever imports it)."""
    modules = {module_name(path, root): path for path in python_files(root)}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        edges: set[str] = set()
        for target in imported_modules(path, root):
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name and not within(name, target):
                edges.add(target)
        graph[name] = edges
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(circles)


def circle_violations(root: Path) -> list[str]:
    """One line per import circle among the modules of isac_mission and sim."""
    return ["circle: " + " <-> ".join(c) for c in import_circles(import_graph(root))]


# --------------------------------------------------------------------------------------------
# The repository keeps the rules


def test_no_module_imports_itself_round_a_circle() -> None:
    assert len(import_graph(ROOT)) > 100
    assert circle_violations(ROOT) == []


@pytest.mark.parametrize("path", list(python_files(ROOT, PURE)), ids=lambda p: _rel(p, ROOT))
def test_pure_modules_import_no_io(path: Path) -> None:
    assert imported_roots(path) & set(IO_MODULES) == set()


def test_the_pure_modules_are_there() -> None:
    missing = [rel for rel in PURE if not (ROOT / rel).exists()]
    assert missing == []
    assert pure_io_violations(ROOT) == []


@pytest.mark.parametrize(("library", "adapter"), sorted(ADAPTERS.items()))
def test_each_io_library_has_one_adapter(library: str, adapter: str) -> None:
    assert (ROOT / adapter).exists()
    assert adapter_violations(ROOT, library, adapter) == []


def test_sim_imports_neither_the_service_nor_the_cli() -> None:
    assert sim_violations(ROOT) == []


def test_the_service_imports_no_cli() -> None:
    assert (ROOT / "isac_mission/service").is_dir()
    assert service_violations(ROOT) == []


def test_only_the_embedded_entry_imports_sim() -> None:
    assert (ROOT / EMBEDDED).is_file()
    assert sim_importer_violations(ROOT) == []


def test_the_neutral_layer_imports_no_peer() -> None:
    missing = [rel for rel in NEUTRAL if not (ROOT / rel).exists()]
    assert missing == []
    assert neutral_violations(ROOT) == []


def test_the_console_imports_the_neutral_layer_only() -> None:
    assert (ROOT / CONSOLE).is_dir()
    assert console_violations(ROOT) == []


def test_the_console_rule_finds_a_violation(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "isac_mission/console/app.py": "from isac_mission.wire import keys\nimport starlette\n",
            "isac_mission/console/bad.py": "from isac_mission.service.ground import loop\n",
            "isac_mission/service/ground/x.py": "def f():\n    import isac_mission.console\n",
            "isac_mission/cli/live.py": "import uvicorn\n",
        },
    )
    assert [v.split(":")[0] for v in console_violations(root)] == [
        "isac_mission/console/bad.py",
        "isac_mission/service/ground/x.py",
    ]
    assert adapter_violations(root, "uvicorn", ADAPTERS["uvicorn"]) == [
        "isac_mission/cli/live.py: imports uvicorn (only isac_mission/console may)"
    ]
    assert adapter_violations(root, "starlette", ADAPTERS["starlette"]) == []


# --------------------------------------------------------------------------------------------
# The checker finds what it must


def test_the_checker_sees_imports_inside_functions(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    import zenoh\n    from asyncio import sleep\n")
    assert imported_roots(f, tmp_path) == {"zenoh", "asyncio"}


def test_the_checker_resolves_relative_and_from_package_imports(tmp_path: Path) -> None:
    f = tmp_path / "isac_mission" / "wire" / "m.py"
    f.parent.mkdir(parents=True)
    f.write_text("from ..service import ground\nfrom . import keys\nfrom isac_mission import cli\n")
    mods = imported_modules(f, tmp_path)
    assert {"isac_mission.service.ground", "isac_mission.wire.keys", "isac_mission.cli"} <= mods
    assert module_name(f, tmp_path) == "isac_mission.wire.m"


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return tmp_path


def test_each_rule_reports_a_violation(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "isac_mission/planning/slot.py": "import socket\n",
            "isac_mission/service/ground/loop.py": "import zenoh\nfrom sim import world\n",
            "isac_mission/bus/session.py": "import zenoh\n",
            "isac_mission/mavwire/dialect.py": "import pymavlink\n",
            "isac_mission/mavwire/link.py": "from isac_mission.mavwire.dialect import mavlink2\n",
            "sim/autopilot/link.py": "from pymavlink.dialects.v20 import common\n",
            "sim/world.py": "from isac_mission.service.bridge import fleet\n",
            "sim/emulator.py": "from isac_mission.cli import app\n",
            "isac_mission/cli/embedded.py": "import sim.world\nimport isac_mission.service\n",
            "isac_mission/cli/world.py": "import sim.world\n",
            "isac_mission/cli/live.py": "import sim.world\nfrom isac_mission.service import x\n",
            "isac_mission/records/writer.py": "from isac_mission.experiment import plots\n",
            "isac_mission/tracking/cycle.py": "def f():\n    from isac_mission.service import g\n",
            "isac_mission/service/bridge/fleet.py": "def f():\n    from ...cli import stopping\n",
        },
    )
    assert pure_io_violations(root) == ["isac_mission/planning/slot.py: imports socket"]
    assert adapter_violations(root, "zenoh", ADAPTERS["zenoh"]) == [
        "isac_mission/service/ground/loop.py: imports zenoh (only isac_mission/bus/session.py may)"
    ]
    assert adapter_violations(root, "pymavlink", ADAPTERS["pymavlink"]) == [
        "sim/autopilot/link.py: imports pymavlink (only isac_mission/mavwire/dialect.py may)"
    ]
    assert [v.split(":")[0] for v in sim_violations(root)] == ["sim/emulator.py", "sim/world.py"]
    assert [v.split(":")[0] for v in sim_importer_violations(root)] == [
        "isac_mission/cli/live.py",
        "isac_mission/cli/world.py",
        "isac_mission/service/ground/loop.py",
    ]
    assert [v.split(":")[0] for v in neutral_violations(root)] == [
        "isac_mission/records/writer.py",
        "isac_mission/tracking/cycle.py",
    ]
    assert service_violations(root) == [
        "isac_mission/service/bridge/fleet.py: imports isac_mission.cli, isac_mission.cli.stopping"
    ]


def test_the_circle_rule_finds_circles_of_types_and_lazy_imports(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "isac_mission/__init__.py": "from isac_mission.planning import slot\n",
            "isac_mission/planning/__init__.py": "from isac_mission.planning.slot import Kit\n",
            "isac_mission/planning/slot.py": "from isac_mission.planning.registry import get\n",
            "isac_mission/planning/registry.py": (
                "from typing import TYPE_CHECKING\n"
                "if TYPE_CHECKING:\n    from isac_mission.planning.slot import Kit\n"
            ),
            "sim/a.py": "def f():\n    from sim import b\n",
            "sim/b.py": "from sim.a import f\n",
            "sim/c.py": "from sim.a import f\n",
        },
    )
    assert circle_violations(root) == [
        "circle: isac_mission.planning.registry <-> isac_mission.planning.slot",
        "circle: sim.a <-> sim.b",
    ]


def test_a_clean_tree_has_no_violations(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "isac_mission/bus/session.py": "import zenoh\nfrom isac_mission.wire import keys\n",
            "isac_mission/mavwire/dialect.py": "import os\nimport pymavlink\n",
            "isac_mission/mavwire/link.py": "import asyncio\nfrom . import dialect\n",
            "isac_mission/cli/embedded.py": "import sim.world\nimport isac_mission.service\n",
            "sim/world.py": "from isac_mission.bus import session\n",
        },
    )
    assert pure_io_violations(root) == []
    assert adapter_violations(root, "zenoh", ADAPTERS["zenoh"]) == []
    assert adapter_violations(root, "pymavlink", ADAPTERS["pymavlink"]) == []
    assert sim_violations(root) == []
    assert sim_importer_violations(root) == []
    assert neutral_violations(root) == []
    assert service_violations(root) == []
    assert circle_violations(root) == []
