#!/usr/bin/env bash
# The main job on the embedded default: set up the venv if needed, then run the scenario.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$root/scripts/setup-venv.sh"
cd "$root"
exec isac-mission simulate config/paper.yaml "$@"
