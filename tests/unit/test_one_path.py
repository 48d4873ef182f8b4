"""One mission for any number of targets: outside the tracker implementations, the detection
models, the one factory that picks them from the scenario (and the scenario's own schema, which
resolves `tracker.kind`), no module names a several-target class or asks whether a scenario has
several targets (docs/architecture.md, "One definition each")."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

ALLOWED = {
    # the tracker implementations
    "isac_mission/tracking/tracker.py",
    "isac_mission/tracking/multi_target.py",
    "isac_mission/tracking/initiation.py",
    "isac_mission/tracking/association.py",
    "isac_mission/tracking/origin_uncertainty.py",
    # the detection models, offline and in the simulated world
    "isac_mission/model/scene.py",
    "isac_mission/model/run_noise.py",
    "isac_mission/model/detections.py",
    "isac_mission/model/targets.py",
    "sim/multi_target_scene.py",
    "sim/scenes.py",
    # the one factory that picks them from the scenario, and the world's
    "isac_mission/tracking/factory.py",
    "sim/world_assembly.py",
}
"""Files that may name them; plus the scenario schema (isac_mission/config/), where
`tracker.kind: auto` is resolved."""

ASKS = re.compile(
    r"MultiTarget\w*"  # a several-target class
    r"|\.multi_target\b(?!\s+import|\.)"  # Scenario.multi_target (not a module's path)
    r"|\blabelled\(\s*(s|scenario|self\.s|self\.scenario|planning|p\.scenario)\b"  # factory.labelled
    r"|len\([\w.]*\.targets\)\s*(>|==|!=|<)"  # counting the targets to choose a path
)


def _sources() -> list[Path]:
    files = [*sorted((ROOT / "isac_mission").rglob("*.py")), *sorted((ROOT / "sim").rglob("*.py"))]
    return [
        f
        for f in files
        if f.relative_to(ROOT).as_posix() not in ALLOWED
        and not f.relative_to(ROOT).as_posix().startswith("isac_mission/config/")
    ]


def test_no_module_outside_the_trackers_detection_models_and_factory_picks_a_path() -> None:
    found = []
    for path in _sources():
        for n, line in enumerate(path.read_text().splitlines(), start=1):
            if ASKS.search(line):
                found.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not found, "modules that choose by the number of targets:\n" + "\n".join(found)


def test_the_pattern_finds_what_it_forbids() -> None:
    """Not vacuous: each form it forbids is found."""
    for line in (
        "from isac_mission.tracking.multi_target import MultiTargetTracker",
        "    if s.multi_target:",
        "    if labelled(s):",
        "    many = len(s.targets) > 1",
    ):
        assert ASKS.search(line), line
    assert not ASKS.search("    tracker = tracker_for(s)")
