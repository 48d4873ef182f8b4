"""Decode time of every bus message type: medians per message, and against a previous tree.

The payloads are fixed JSON texts (the same bytes for every tree): one of each message type,
plans for M = 3, 24 and 256 UAVs, and two refusals (a string where a number belongs, and not
JSON) since a flood of garbage is decoded too. Each payload is decoded `--number` times per
repeat, `--repeat` repeats per round; the time per call is the median over repeats (and rounds).

`--compare-tree DIR` runs the same measurement on the package in DIR (e.g. the pre-refactor tree,
`git archive <commit> | tar -x -C DIR`) and on this tree, interleaved in subprocesses (old, new,
old, new, ...) so that both see the same machine load, and prints before, after and their ratio
after / before (docs/performance.md, "Bus message decoding"). A tree's decoders are found by
looking for the module that defines `decode_detection` (older trees) or else `decode_any`
(`decode(kind, ...)` for every type), wherever that tree keeps it.

Run: python bench/decode.py [--number 2000] [--repeat 7]
     python bench/decode.py --compare-tree DIR [--rounds 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def _envelope(kind: str, slot: int = 7, t: float = 7.0) -> dict[str, Any]:
    return {"schema": "isac/1", "type": kind, "slot": slot, "t": t}


def _plan(m: int) -> dict[str, Any]:
    k = max(1, (m + 1) // 2)
    return _envelope("plan") | {
        "assoc": [i % k for i in range(m)],
        "bandwidth_share": [1.0 / m] * m,
        "waypoints_xy_m": [[1500.0 + 3.25 * i, 1400.0 - 1.5 * i] for i in range(m)],
        "objective": 12.5,
        "status": "ok",
        "reason": "",
        "solve_s": 0.0123,
    }


def payloads() -> list[tuple[str, str, str, dict[str, int]]]:
    """(row name, message type, payload text, decoder keyword arguments), in table order."""
    det = _envelope("detection") | {
        "uav": 1,
        "range_m": 812.25,
        "radial_velocity_mps": -3.5,
        "uav_xy_m": [807.0, 1100.0],
        "bandwidth_share": 0.25,
    }
    rows: list[tuple[str, str, dict[str, Any] | str, dict[str, int]]] = [
        ("detection", "detection", det, {"n_uavs": 3}),
        (
            "detection (missed)",
            "detection",
            det | {"range_m": None, "radial_velocity_mps": None},
            {},
        ),
        (
            "clock",
            "clock",
            _envelope("clock") | {"slot_s": 1.0, "speed": 1.0, "mission_t0": 30.0},
            {},
        ),
        ("truth", "truth", _envelope("truth") | {"target_x": [600.0, 1600.0, 30.0, -0.25]}, {}),
        (
            "telemetry",
            "telemetry",
            _envelope("telemetry")
            | {
                "uav": 2,
                "position_xy_m": [10.0, 20.0],
                "altitude_m": 30.0,
                "velocity_xy_mps": [1.0, -0.5],
                "mode": "offboard",
                "armed": True,
                "landed": False,
                "link": "ok",
            },
            {"n_uavs": 3},
        ),
        (
            "track",
            "track",
            _envelope("track")
            | {
                "x": [600.0, 1600.0, 30.0, -0.25],
                "P": [[1.5 if i == j else 0.125 for j in range(4)] for i in range(4)],
                "J": [[2.7e9 if i == j else 1.0e3 for j in range(4)] for i in range(4)],
                "pcrb_trace": 2.5,
            },
            {},
        ),
        ("plan M=3", "plan", _plan(3), {"n_uavs": 3, "n_bs": 5}),
        ("plan M=24", "plan", _plan(24), {"n_uavs": 24, "n_bs": 20}),
        ("plan M=256", "plan", _plan(256), {}),
        (
            "health",
            "health",
            _envelope("health")
            | {
                "status": "ok",
                "counters": {f"counter {i}": i for i in range(12)},
                "last_error": "",
                "vehicles": {"0": "active", "1": "active", "2": "excluded: link lost"},
            },
            {},
        ),
        ("refused: range as string", "detection", det | {"range_m": "812"}, {"n_uavs": 3}),
        ("refused: not JSON", "detection", "{this is not json", {}),
    ]
    return [
        (name, kind, body if isinstance(body, str) else json.dumps(body), kw)
        for name, kind, body, kw in rows
    ]


TIMING_CODE = """
import functools, importlib, json, sys, timeit
from pathlib import Path
tree, spec_file, number, repeat = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
texts = {p: p.read_text() for p in sorted((tree / "isac_mission").rglob("*.py"))}
path = next((p for p, t in texts.items() if "def decode_detection(" in t), None) or next(
    p for p, t in texts.items() if "def decode_any(" in t
)
module = ".".join(path.relative_to(tree).with_suffix("").parts)
codec = importlib.import_module(module)
errors = importlib.import_module("isac_mission.errors")
out = {}
for name, kind, text, kw in json.loads(Path(spec_file).read_text()):
    decode = getattr(codec, "decode_" + kind, None) or functools.partial(codec.decode, kind)
    data = text.encode()
    def call(decode=decode, data=data, kw=kw):
        try:
            decode(data, **kw)
        except errors.MessageError:
            pass
    call()
    times = timeit.repeat(call, number=number, repeat=repeat)
    out[name] = [t / number for t in times]
print(json.dumps({"module": module, "times": out}))
"""


def measure(tree: Path, spec_file: Path, number: int, repeat: int) -> dict[str, Any]:
    """Run the timing code on the package in `tree`: {"module", "times": {row: [s per call]}}."""
    out = subprocess.run(
        [sys.executable, "-c", TIMING_CODE, str(tree), str(spec_file), str(number), str(repeat)],
        cwd=tree,
        env={**os.environ, "PYTHONPATH": str(tree)},
        capture_output=True,
        text=True,
        check=True,
    )
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def _spec(tmp: Path) -> Path:
    spec = tmp / "decode-bench-payloads.json"
    spec.write_text(json.dumps(payloads()))
    return spec


def table(old_tree: Path | None, rounds: int, number: int, repeat: int) -> None:
    """Print the table (this tree alone, or before/after against old_tree)."""
    tmp = Path(os.environ.get("TMPDIR", "/tmp"))
    spec = _spec(tmp)
    trees = [ROOT] if old_tree is None else [old_tree, ROOT]
    times: dict[Path, dict[str, list[float]]] = {t: {} for t in trees}
    modules: dict[Path, str] = {}
    for _ in range(rounds):
        for tree in trees:
            got = measure(tree, spec, number, repeat)
            modules[tree] = got["module"]
            for name, ts in got["times"].items():
                times[tree].setdefault(name, []).extend(ts)
    rows = payloads()
    width = max(len(r[0]) for r in rows)
    if old_tree is None:
        print(f"decoders: {modules[ROOT]}; {rounds} x {repeat} repeats of {number} calls")
        print(f"{'message':<{width}} {'bytes':>6} {'median us':>10}")
        for name, _, text, _ in rows:
            print(
                f"{name:<{width}} {len(text):>6} {statistics.median(times[ROOT][name]) * 1e6:>10.2f}"
            )
        return
    print(
        f"before = {old_tree} ({modules[old_tree]}), after = {ROOT} ({modules[ROOT]}); "
        f"{rounds} interleaved rounds x {repeat} repeats of {number} calls"
    )
    print(f"{'message':<{width}} {'bytes':>6} {'before us':>10} {'after us':>9} {'ratio':>6}")
    for name, _, text, _ in rows:
        before = statistics.median(times[old_tree][name]) * 1e6
        after = statistics.median(times[ROOT][name]) * 1e6
        print(
            f"{name:<{width}} {len(text):>6} {before:>10.2f} {after:>9.2f} {after / before:>6.2f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--number", type=int, default=2000, help="decodes per repeat")
    ap.add_argument("--repeat", type=int, default=7, help="repeats per round")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (subprocesses)")
    ap.add_argument(
        "--compare-tree",
        metavar="DIR",
        help="before/after against the isac_mission package in DIR, with the ratio after/before",
    )
    args = ap.parse_args()
    old = Path(args.compare_tree).resolve() if args.compare_tree else None
    table(old, args.rounds, args.number, args.repeat)


if __name__ == "__main__":
    main()
