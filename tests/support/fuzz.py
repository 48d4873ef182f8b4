"""Shared bounds of the wire fuzz tests (tests/reliability/test_wire_fuzz_*.py)."""

from __future__ import annotations

import os

from hypothesis import HealthCheck, settings

WAIT_S = 30.0
"""Generous wall-clock bound for any single awaited event."""
FUZZ = settings(
    max_examples=int(os.environ.get("ISAC_FUZZ_EXAMPLES", "150")),
    derandomize=True,
    database=None,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
"""Bounded, reproducible hypothesis runs (the same examples every time)."""
