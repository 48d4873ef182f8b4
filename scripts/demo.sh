#!/usr/bin/env bash
# The main job on the embedded default: set up the venv if needed, then fly the paper's mission
# live (simulated PX4-like vehicles over MAVLink, sensing over Zenoh, the planner) at 4x speed.
# Arguments are passed on, e.g. ./scripts/demo.sh --speed 1 (real time) or --method sd.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$root/scripts/setup-venv.sh"
cd "$root"
exec isac-mission run config/paper.yaml --speed 4 "$@"
