#!/usr/bin/env bash
# The test suite by tiers (docs/testing.md, "Tiers"; tiers in tests/conftest.py): set up the venv if
# needed, lint, type-check, the fast tier, and, unless --fast, the live tier.
#   ./scripts/test.sh           ruff, mypy, fast tier, then live tier (what CI runs: .ci/run)
#   ./scripts/test.sh --fast    ruff, mypy, fast tier only (a few minutes: after every change)
#   ./scripts/test.sh --full    also the slow tier (full-size variants) in each tier
# Other arguments go to pytest (e.g. -k NAME, -x). The live tier runs only if the fast one passed.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
fast_only=0
args=()
for arg in "$@"; do
    if [ "$arg" = "--fast" ]; then fast_only=1; else args+=("$arg"); fi
done
source "$root/scripts/setup-venv.sh"
cd "$root"
# The console's browser tests (live tier) drive Debian's Chromium (tests/e2e/test_console.py).
if [ "$fast_only" = 0 ] && [ ! -x /usr/bin/chromium ]; then
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

# pytest's exit 5 (nothing collected) is a failure, except when the caller's own selection
# (-k, a path) leaves one tier empty.
tier() {
    local status=0
    echo "== $1 tier ==" >&2
    python -m pytest -q -m "$1" "${@:2}" ${args[@]+"${args[@]}"} || status=$?
    if [ "$status" = 5 ] && [ "${#args[@]}" -gt 0 ]; then status=0; fi
    return "$status"
}
# Fast: two workers, a test file per worker (a module's fixtures, e.g. Monte Carlo runs, once).
tier fast -n 2 --dist loadfile
python scripts/longest_modules.py
if [ "$fast_only" = 1 ]; then exit 0; fi
# Live: a live test mostly waits on simulation time (two workers kept about one core busy),
# so three workers share the two cores; each test has its own ports (tests/support/ports.py).
tier live -n 3 --dist worksteal
