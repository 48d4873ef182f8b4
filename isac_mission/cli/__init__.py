"""The `isac-mission` command line, one module per command group.

- `offline`: `check-config`, `simulate`, `replay` (a trace's planner inputs replayed)
- `sweep`: `sweep`
- `embedded`: `sim` (the world alone), and the world of `run` (`run_embedded`): the only module
  importing `sim`, and so the only one importing both `sim` and the service
- `live`: `run`, `serve` (their mission on the command line, its progress line and Ctrl-C, is in
  `mission`; the service side is assembled by isac_mission/service/assembly.py), `compile` (the
  planner's IPOPT problems compiled into the cache, isac_mission/nlp_cache.py)
- `view`: `view` (the console over traces) and the console of `run` / `serve`
- `security`: `gen-certs`, `gen-users`
- `schema`: `schema` (the JSON Schema of every bus message)

Importing a command module registers its commands on `app`; the heavy imports stay inside the
commands, so `isac-mission --version` and `--help` are fast.
"""

from __future__ import annotations

import importlib
import os
import sys

# IPOPT's MUMPS (through the OpenBLAS bundled with CasADi) spreads each factorisation over every
# core and gains nothing at the planner's sizes: at M = 12 the horizon's plans took the same wall
# time on one thread as on two, with twice the CPU (docs/performance.md, "Compiled problems").
# On the service's two cores that second core belongs to the world and the bridges. Set before
# any BLAS loads (the command modules import numpy and CasADi lazily); a user's value stands.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from isac_mission.cli.app import app

__all__ = ["app", "main"]

COMMAND_GROUPS = ("offline", "sweep", "embedded", "live", "security", "schema", "view")
"""Command modules in `--help` order; importing one registers its commands on `app`."""

for _group in COMMAND_GROUPS:
    importlib.import_module(f"isac_mission.cli.{_group}")


def main() -> None:
    """Console-script entry point (`isac-mission`, `python -m isac_mission.cli`)."""
    sys.exit(app())
