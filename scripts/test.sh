#!/usr/bin/env bash
# The whole test suite: set up the venv if needed, lint, type-check, then pytest.
# Extra arguments go to pytest (e.g. --full for the full-size Monte Carlo and soak tests).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$root/scripts/setup-venv.sh"
cd "$root"
ruff check .
ruff format --check .
mypy isac_mission sim
exec python -m pytest -q "$@"
