"""Design rules the layering does not see, checked on the source (ast):

- no caller asks a time's class: the time port (`isac_mission.timebase.SimTime`) says what a
  caller needs, so `isinstance(x, SomeTime)` appears only in the module that defines SomeTime;
- a record is changed with `dataclasses.replace`, never rebuilt through its dict
  (`Record.from_dict(record.to_dict() | {...})`).

Each rule is a function of the repository root that lists its violations, so the tests below
also show it finding one in a small tree made for the purpose.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("isac_mission", "sim")


def _sources(root: Path) -> Iterator[tuple[str, ast.Module]]:
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            yield rel, ast.parse(path.read_text(encoding="utf-8"), rel)


def time_classes(root: Path) -> dict[str, str]:
    """Class name -> the file that defines it, for every class named `...Time`."""
    return {
        node.name: rel
        for rel, tree in _sources(root)
        for node in ast.walk(tree)
        if isinstance(node, ast.ClassDef) and node.name.endswith("Time")
    }


def _names(node: ast.expr) -> set[str]:
    """The class names an isinstance's second argument mentions (a name, an attribute, a
    tuple of them)."""
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name)} | {
        n.attr for n in ast.walk(node) if isinstance(n, ast.Attribute)
    }


def time_type_checks(root: Path) -> list[str]:
    """`isinstance(x, T)` with T a time class, outside the file that defines T."""
    defined = time_classes(root)
    out: list[str] = []
    for rel, tree in _sources(root):
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name)
                and node.func.id == "isinstance"
                and len(node.args) == 2
            ):
                asked = sorted(n for n in _names(node.args[1]) if defined.get(n, rel) != rel)
                out += [f"{rel}:{node.lineno}: isinstance(..., {name})" for name in asked]
    return out


def _calls(node: ast.AST, attribute: str) -> Iterator[ast.Call]:
    for n in ast.walk(node):
        if (
            isinstance(n, ast.Call)
            and isinstance(n.func, ast.Attribute)
            and n.func.attr == attribute
        ):
            yield n


def dict_round_trips(root: Path) -> list[str]:
    """`X.from_dict(...)` calls whose arguments hold a `.to_dict()` call."""
    return [
        f"{rel}:{call.lineno}: from_dict of a to_dict"
        for rel, tree in _sources(root)
        for call in _calls(tree, "from_dict")
        if any(True for arg in call.args for _ in _calls(arg, "to_dict"))
    ]


# --------------------------------------------------------------------------------------------
# The repository keeps the rules


def test_no_caller_asks_the_class_of_a_time() -> None:
    assert {"WallTime", "ClockSimTime"} <= set(time_classes(ROOT))
    assert time_type_checks(ROOT) == []


def test_no_record_is_rebuilt_through_its_dict() -> None:
    assert dict_round_trips(ROOT) == []


# --------------------------------------------------------------------------------------------
# The rules find what they must


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return tmp_path


def test_the_rules_find_a_time_type_check_and_a_round_trip(tmp_path: Path) -> None:
    root = _tree(
        tmp_path,
        {
            "isac_mission/timebase.py": (
                "class WallTime: ...\n"
                "def f(t):\n    return isinstance(t, WallTime)\n"  # its own module: allowed
            ),
            "sim/clock.py": "class ClockTime: ...\n",
            "isac_mission/bridge.py": (
                "from isac_mission import timebase\n"
                "def g(t):\n    return isinstance(t, (timebase.WallTime, int))\n"
                "def h(t):\n    return isinstance(t, ClockTime)\n"
            ),
            "isac_mission/records.py": (
                "def k(rec):\n"
                "    a = Rec.from_dict(rec.to_dict() | {'slot': 2})\n"
                "    b = Rec.from_dict(obj)\n"
            ),
        },
    )
    assert time_classes(root) == {
        "WallTime": "isac_mission/timebase.py",
        "ClockTime": "sim/clock.py",
    }
    assert time_type_checks(root) == [
        "isac_mission/bridge.py:3: isinstance(..., WallTime)",
        "isac_mission/bridge.py:5: isinstance(..., ClockTime)",
    ]
    assert dict_round_trips(root) == ["isac_mission/records.py:2: from_dict of a to_dict"]
