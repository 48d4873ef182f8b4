#!/usr/bin/env bash
# Create .venv and install the project with its dev extra at the versions of constraints.txt
# (the ones CI tested), once; later calls only re-install when pyproject.toml or constraints.txt
# changed. Sourced by the other scripts.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
stamp="$venv/.installed-from"
want="$(cat "$root/pyproject.toml" "$root/constraints.txt" | sha256sum | cut -d' ' -f1)"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setting up $venv (first run: about a minute; log in $venv/install.log)" >&2
  if ! { "$venv/bin/python" -m pip install --quiet --upgrade pip &&
         "$venv/bin/python" -m pip install --quiet -c "$root/constraints.txt" -e "$root[dev]"; } > "$venv/install.log" 2>&1; then
    cat "$venv/install.log" >&2
    echo "installation failed (log above)" >&2
    exit 1
  fi
  echo "$want" > "$stamp"
fi
export PATH="$venv/bin:$PATH"
export MAVLINK20=1
export MAVLINK_DIALECT=common
