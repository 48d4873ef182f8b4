#!/usr/bin/env bash
# The main job on the embedded default: set up the venv if needed, then fly the paper's mission
# live (simulated PX4-like vehicles over MAVLink, sensing over Zenoh, the planner) at 4x speed,
# in lockstep: the world waits at each slot boundary for the slot's plan, so a busy machine
# slows the mission down instead of flying it on late plans (README, "Two commands").
# Arguments are passed on, e.g. ./scripts/demo.sh --speed 1 (real time), --method sd, or
# --no-lockstep (free-running: the world keeps its pace whether or not the plans do).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$root/scripts/setup-venv.sh"
cd "$root"
exec isac-mission run config/paper.yaml --speed 4 --lockstep "$@"
