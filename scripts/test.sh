#!/usr/bin/env bash
# The whole test suite: set up the venv if needed, lint, type-check, then pytest.
# Extra arguments go to pytest (e.g. --full for the full-size Monte Carlo and soak tests).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$root/scripts/setup-venv.sh"
cd "$root"
# The console's browser tests drive Debian's Chromium (tests/e2e/test_console.py).
if [ ! -x /usr/bin/chromium ]; then
    echo "test.sh: /usr/bin/chromium is missing; installing Debian's chromium package" >&2
    if ! { apt-get update && apt-get install -y chromium; } >&2; then
        echo "test.sh: cannot install chromium (apt-get update && apt-get install -y chromium" \
            "failed; run it as root, or install Chromium at /usr/bin/chromium)" >&2
        exit 1
    fi
fi
ruff check .
ruff format --check .
mypy isac_mission sim
exec python -m pytest -q "$@"
