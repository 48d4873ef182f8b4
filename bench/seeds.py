"""The benches' --seeds option: "1..10" (a range, both ends included) or "1,3,5"."""

from __future__ import annotations


def parse_seeds(text: str) -> list[int]:
    """The seeds a --seeds value names, in order."""
    if ".." in text:
        a, b = text.split("..")
        return list(range(int(a), int(b) + 1))
    return [int(x) for x in text.split(",") if x.strip()]
