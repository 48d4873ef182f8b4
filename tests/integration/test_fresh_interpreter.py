"""What a fresh interpreter loads: the command line, the package and the sweep modules, each
imported in its own Python process (a test process has already imported everything), and
`python -m isac_mission.cli`."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import isac_mission

ROOT = Path(__file__).resolve().parents[2]


def test_python_dash_m_runs_the_cli() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "isac_mission.cli", "--version"],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    assert out.stdout.strip() == f"isac-mission {isac_mission.__version__}"


def test_starting_the_cli_loads_neither_the_simulator_nor_the_service() -> None:
    code = (
        "import sys, isac_mission.cli; "
        "print(sorted({m.split('.')[0] if m.startswith('sim') else m for m in sys.modules "
        "if m == 'sim' or m.startswith(('sim.', 'isac_mission.service', 'zenoh', 'cvxpy'))}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert out.stdout.strip() == "[]"


def test_importing_the_package_loads_no_solver_nor_plotting() -> None:
    code = "import sys, isac_mission; print(sorted(m for m in ('cvxpy', 'matplotlib', 'zenoh') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_the_sweep_modules_do_not_import_dask() -> None:
    code = textwrap.dedent(
        """
        import sys
        import isac_mission.experiment.sweep.cluster
        import isac_mission.experiment.sweep.grid
        import isac_mission.experiment.sweep.plots
        import isac_mission.experiment.sweep.runs
        import isac_mission.experiment.sweep.summary
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in ("dask", "distributed"))
        print(loaded)
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert proc.stdout.strip() == "[]", proc.stderr
