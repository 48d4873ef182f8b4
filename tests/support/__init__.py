"""Test helpers shared by the unit, numerics and e2e tests (not part of the package)."""
