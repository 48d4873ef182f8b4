#!/usr/bin/env bash
# Build a stand-in for the Dockerfile's default base (python:3.11-slim, on Docker Hub) from
# Debian's own packages, for machines that reach Debian's mirror and PyPI but not Docker Hub:
#   scripts/build-base-image.sh [TAG]        (default tag: isac-mission-base:bookworm)
# then `docker build --build-arg BASE=TAG .` (scripts/compose-check.sh does this by itself).
# The mirror is the one apt uses on this machine (its sources), so no host is written here;
# override with ISAC_DEBIAN_MIRROR=URL (`--print-mirror` prints the one it would use). Needs root, debootstrap and a running Docker engine.
# The image: Debian bookworm minbase, python3 (3.11), a venv at /opt/venv first on PATH (Debian's
# python refuses system-wide pip installs) and this machine's CA bundle (pip inside the build
# verifies the package index with it).
set -euo pipefail
tag="${1:-isac-mission-base:bookworm}"
suite="${ISAC_DEBIAN_SUITE:-bookworm}"

# The first main-archive URI of apt's sources: deb822 files (URIs:) or one-line sources.list.
apt_etc="${ISAC_APT_ETC:-/etc/apt}"
apt_mirror() {
    local f uri
    for f in "$apt_etc"/sources.list.d/*.sources; do
        [ -f "$f" ] || continue
        uri="$(awk '/^URIs:/ {for (i = 2; i <= NF; i++) if ($i !~ /security/) {print $i; exit}}' "$f")"
        if [ -n "$uri" ]; then echo "$uri"; return 0; fi
    done
    for f in "$apt_etc"/sources.list "$apt_etc"/sources.list.d/*.list; do
        [ -f "$f" ] || continue
        uri="$(awk '$1 == "deb" {for (i = 2; i <= NF; i++) if ($i ~ /^[a-z]+:\/\//) {if ($i !~ /security/) {print $i; exit}; break}}' "$f")"
        if [ -n "$uri" ]; then echo "$uri"; return 0; fi
    done
    return 1
}

if [ "${1:-}" = "--print-mirror" ]; then apt_mirror; exit $?; fi
mirror="${ISAC_DEBIAN_MIRROR:-$(apt_mirror || true)}"
if [ -z "$mirror" ]; then
    echo "build-base-image: no Debian mirror in /etc/apt/sources.list{,.d/}; set ISAC_DEBIAN_MIRROR" >&2
    exit 1
fi
command -v debootstrap > /dev/null || {
    echo "build-base-image: debootstrap is missing (apt-get install debootstrap)" >&2
    exit 1
}
root="$(mktemp -d /tmp/isac-base.XXXXXX)"
trap 'rm -rf "$root"' EXIT
echo "build-base-image: debootstrap $suite from the apt mirror into $root" >&2
debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates \
    "$suite" "$root" "$mirror" > "$root.log" 2>&1 || {
    tail -20 "$root.log" >&2
    echo "build-base-image: debootstrap failed (log above)" >&2
    rm -f "$root.log"
    exit 1
}
rm -f "$root.log"
cp /etc/ssl/certs/ca-certificates.crt "$root/etc/ssl/certs/ca-certificates.crt"
chroot "$root" python3 -m venv /opt/venv
# What a base image need not carry: apt's lists and caches, documentation, locales.
rm -rf "$root"/var/lib/apt/lists/* "$root"/var/cache/apt/* "$root"/usr/share/doc/* \
    "$root"/usr/share/man/* "$root"/usr/share/locale/*
tar -C "$root" -c . | docker import \
    --change 'ENV PATH=/opt/venv/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt' \
    --change 'CMD ["python3"]' - "$tag" > /dev/null
echo "build-base-image: $tag ($(docker image inspect --format '{{.Size}}' "$tag" | awk '{printf "%.0f MB", $1 / 1e6}'))" >&2
