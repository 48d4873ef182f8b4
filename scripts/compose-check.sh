#!/usr/bin/env bash
# The two-container deployment, checked end to end on this machine (docs/deployment.md,
# "Docker Compose"):
# engine and Compose installed when missing, a Docker engine started when none answers, the base
# image pulled or (no Docker Hub) built from Debian's packages, the image built, `up`, then from
# the host: planned slots, the console on 127.0.0.1:8080, the fleet's heartbeats on 127.0.0.1:14550;
# `stop`, exit codes 0 and 3 vehicles landed; `down -v`; the engine it started stopped and the
# host's network as it was before.
#   scripts/compose-check.sh            keep the images for the next run (cached)
#   scripts/compose-check.sh --rmi      remove them as well
# CI runs it after the test suite (.ci/run). Needs root (apt-get, dockerd) unless an engine runs.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
remove_images=0
[ "${1:-}" = "--rmi" ] && remove_images=1

project=isaccheck
base_official=python:3.11-slim
base_standin=isac-mission-base:bookworm
min_ok_slots=5
speed=2 # simulation seconds per wall second: the 60 s mission outlasts the checks below
say() { echo "compose-check: $*" >&2; }
fail() {
    say "FAILED: $*"
    exit 1
}
t_start=$SECONDS
step_t=$SECONDS
step() {
    say "$1 done in $((SECONDS - step_t)) s"
    step_t=$SECONDS
}

# -- engine and Compose ---------------------------------------------------------------------
if ! command -v dockerd > /dev/null || ! command -v docker > /dev/null; then
    say "installing Debian's docker.io"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq docker.io > /dev/null ||
        fail "apt-get install docker.io"
fi
if docker compose version > /dev/null 2>&1; then
    compose=(docker compose)
else
    if ! command -v docker-compose > /dev/null; then
        say "installing Debian's docker-compose (Compose v1)"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq docker-compose \
            > /dev/null || fail "apt-get install docker-compose"
    fi
    compose=(docker-compose)
fi
command -v debootstrap > /dev/null || {
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap > /dev/null
} || fail "apt-get install debootstrap"
step "engine and Compose (${compose[*]})"

# -- the host's network before, to compare after ---------------------------------------------
net_state() {
    sysctl -n net.ipv4.ip_forward 2> /dev/null || true
    if command -v iptables > /dev/null; then iptables -S 2> /dev/null || true; fi
    ip -o link show 2> /dev/null | awk '{print $2}' || true
}
net_before="$(net_state)"

# -- a Docker engine: the running one, or one of our own that changes no network setting ------
started_dockerd=0
dockerd_pid=""
data_root=/var/lib/isac-compose-check
if ! docker info > /dev/null 2>&1; then
    export DOCKER_HOST=unix:///run/isac-compose-check/docker.sock
    mkdir -p /run/isac-compose-check
    # Host networking only: no bridge, no iptables rules, no forwarding, so nothing to undo.
    dockerd --host "$DOCKER_HOST" --data-root "$data_root" \
        --exec-root /run/isac-compose-check/exec --pidfile /run/isac-compose-check/docker.pid \
        --bridge=none --iptables=false --ip-forward=false --ip-masq=false \
        > /run/isac-compose-check/dockerd.log 2>&1 &
    dockerd_pid=$!
    started_dockerd=1
    for _ in $(seq 1 60); do
        docker info > /dev/null 2>&1 && break
        kill -0 "$dockerd_pid" 2> /dev/null || break
        sleep 0.5
    done
    docker info > /dev/null 2>&1 || {
        tail -20 /run/isac-compose-check/dockerd.log >&2
        fail "the Docker engine did not start (log above)"
    }
fi

listener_pid=""
cleanup() {
    local status=$?
    set +e
    [ -n "$listener_pid" ] && kill "$listener_pid" 2> /dev/null
    ISAC_BASE_IMAGE="${base:-$base_official}" "${compose[@]}" -p "$project" down -v \
        --remove-orphans > /dev/null 2>&1
    if [ "$remove_images" = 1 ]; then
        docker rmi -f isac-mission:latest "$base_standin" > /dev/null 2>&1
    fi
    if [ "$started_dockerd" = 1 ]; then
        kill "$dockerd_pid" 2> /dev/null
        wait "$dockerd_pid" 2> /dev/null
        # dockerd leaves its default network namespace's bind mount behind.
        awk '$2 ~ "^/run/isac-compose-check/" {print $2}' /proc/mounts | xargs -r umount
        rm -rf /run/isac-compose-check
    fi
    if grep -q " /run/isac-compose-check/" /proc/mounts; then
        say "FAILED: mounts left under /run/isac-compose-check"
        status=1
    fi
    if [ "$(net_state)" != "$net_before" ]; then
        say "FAILED: the host's network settings changed:"
        diff <(echo "$net_before") <(net_state) >&2
        status=1
    fi
    exit "$status"
}
trap cleanup EXIT
step "Docker engine ($([ "$started_dockerd" = 1 ] && echo "started" || echo "running"))"

# -- the base image: the official one, or a stand-in from Debian's packages -------------------
if docker image inspect "$base_official" > /dev/null 2>&1 ||
    timeout 60 docker pull -q "$base_official" > /dev/null 2>&1; then
    base=$base_official
elif docker image inspect "$base_standin" > /dev/null 2>&1; then
    base=$base_standin
else
    say "$base_official cannot be pulled; building the stand-in $base_standin"
    bash scripts/build-base-image.sh "$base_standin"
    base=$base_standin
fi
export ISAC_BASE_IMAGE=$base ISAC_SPEED=$speed
step "base image ($base)"

"${compose[@]}" -p "$project" build -q world > /dev/null || fail "compose build"
step "image build ($(docker image inspect --format '{{.Size}}' isac-mission:latest |
    awk '{printf "%.0f MB", $1 / 1e6}'))"

# -- up, and the operator's view from the host ------------------------------------------------
source scripts/setup-venv.sh # pymavlink for the host's ground-station port
heartbeats="$(mktemp)"
python - "$heartbeats" << 'EOF' &
"""Bind the host's ground-station port as QGroundControl would; write each system id seen."""
import sys
import time

from pymavlink import mavutil

link = mavutil.mavlink_connection("udpin:127.0.0.1:14550", source_system=255)
seen: set[int] = set()
end = time.monotonic() + 600.0
while time.monotonic() < end and len(seen) < 3:
    msg = link.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
    if msg is not None and msg.get_srcSystem() not in seen:
        seen.add(msg.get_srcSystem())
        with open(sys.argv[1], "a") as out:
            out.write(f"{msg.get_srcSystem()}\n")
EOF
listener_pid=$!

"${compose[@]}" -p "$project" up -d > /dev/null || fail "compose up"
container() {
    docker ps -a -q --filter "label=com.docker.compose.project=$project" \
        --filter "label=com.docker.compose.service=$1"
}
ground="$(container ground)"
world="$(container world)"
[ -n "$ground" ] && [ -n "$world" ] || fail "compose up made no ground or world container"
step "up"

# Planned slots, as the console on the host's loopback sees them.
python - "$min_ok_slots" << 'EOF' || fail "fewer than $min_ok_slots planned slots within 240 s"
import json
import sys
import time
import urllib.request

want = int(sys.argv[1])
end = time.monotonic() + 240.0
page = ""
slot = -1
while time.monotonic() < end:
    try:
        page = urllib.request.urlopen("http://127.0.0.1:8080/", timeout=5).read().decode()
        snap = json.load(urllib.request.urlopen("http://127.0.0.1:8080/api/snapshot", timeout=5))
        plan = snap["latest"].get("plan")
        slot = -1 if plan is None else int(plan["slot"])
        if slot >= want and "<html" in page.lower():
            print(f"compose-check: console on 127.0.0.1:8080, plan for slot {slot}", file=sys.stderr)
            sys.exit(0)
    except OSError:
        pass
    time.sleep(1.0)
print(f"compose-check: last plan slot {slot}", file=sys.stderr)
sys.exit(1)
EOF
step "slots planned, console"

for _ in $(seq 1 120); do
    [ "$(sort -u "$heartbeats" | wc -l)" -ge 3 ] && break
    sleep 0.5
done
seen="$(sort -n "$heartbeats" | tr '\n' ' ')"
[ "$seen" = "1 2 3 " ] || fail "heartbeats on the host's 127.0.0.1:14550 from system ids '$seen', not 1 2 3"
say "heartbeats on 127.0.0.1:14550 from system ids $seen"
health=""
for _ in $(seq 1 60); do
    health="$(docker inspect --format '{{.State.Health.Status}}' "$ground")"
    [ "$health" = healthy ] && break
    sleep 1
done
[ "$health" = healthy ] || fail "the ground's healthcheck says '$health', not healthy"
say "ground healthy"

# -- stop: the ground lands the fleet and writes its summary, then the world goes -------------
"${compose[@]}" -p "$project" stop > /dev/null || fail "compose stop"
step "stop"
for c in ground world; do
    id="$(container "$c")"
    code="$(docker inspect --format '{{.State.ExitCode}}' "$id")"
    [ "$code" = 0 ] || {
        docker logs --tail 40 "$id" >&2
        fail "$c exited $code"
    }
done
# The ground's log read once into a file: `docker logs | grep -q` under pipefail fails when grep
# exits at its match while docker logs is still writing (SIGPIPE, exit 141).
ground_log="$(mktemp)"
docker logs "$ground" > "$ground_log" 2>&1
grep -Eq 'vehicles landed[^0-9]*3' "$ground_log" || {
    docker logs --tail 40 "$ground" >&2
    fail "the ground's summary does not say the 3 vehicles landed"
}
# The trace, copied out of the named volume as docs/deployment.md says.
out="$(mktemp -d)"
docker cp "$("${compose[@]}" -p "$project" ps -a -q ground)":/data/serve "$out/" > /dev/null
# One trace, of the default method (trace_horizon.jsonl; the name follows `serve`'s default).
traces=("$out"/serve/trace_*.jsonl)
[ "${#traces[@]}" = 1 ] && [ -f "${traces[0]}" ] || fail "expected one trace in /data/serve, found: ${traces[*]}"
ok_slots="$(grep -c '"status": *"ok"' "${traces[0]}" || true)"
[ "$ok_slots" -ge "$min_ok_slots" ] || fail "the trace has $ok_slots ok slots"
# `stop` came mid-mission (the landing is the shutdown's, not the mission's end).
grep -Eq 'slots completed[^0-9]*([0-9]|[1-5][0-9])/60' "$ground_log" || {
    docker logs --tail 40 "$ground" >&2
    fail "the mission was not stopped mid-way (see the summary above)"
}
rm -rf "$out" "$heartbeats" "$ground_log"
say "both exited 0; 3 vehicles landed; $ok_slots ok slots in the trace"
say "passed in $((SECONDS - t_start)) s"
