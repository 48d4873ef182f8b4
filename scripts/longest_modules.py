"""Print the longest modules of isac_mission/ and sim/ (information, not a rule).

A long module is a hint that it may hold two jobs; whether it does is a reading, not a count.
`./scripts/test.sh --fast` prints this after the fast tier. Usage: python scripts/longest_modules.py [N]
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("isac_mission", "sim")


def module_lengths(root: Path = ROOT) -> list[tuple[int, str]]:
    """(lines, path relative to root) of every .py file of PACKAGES, longest first."""
    rows = [
        (len(path.read_text(encoding="utf-8").splitlines()), path.relative_to(root).as_posix())
        for package in PACKAGES
        for path in (root / package).rglob("*.py")
    ]
    return sorted(rows, key=lambda row: (-row[0], row[1]))


def main(argv: list[str]) -> None:
    count = int(argv[0]) if argv else 8
    print(f"longest modules (information; a long module may hold two jobs): top {count}")
    for lines, rel in module_lengths()[:count]:
        print(f"  {lines:5d}  {rel}")


if __name__ == "__main__":
    main(sys.argv[1:])
