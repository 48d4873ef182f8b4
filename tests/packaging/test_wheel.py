"""The package a user installs: a wheel built without the network, installed `--no-deps` into a
fresh venv, carries the scenarios, the version and the public API, and runs the README's
notebook-style example there (load "paper", plan one slot, run one closed loop, plot into an ax).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

import isac_mission

ROOT = Path(__file__).resolve().parents[2]
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "isac_mission", "sim")
"""What a source distribution holds: the wheel is built from a copy of these alone."""
TIMEOUT_S = 600.0


def readme_example() -> str:
    """The first Python block of the README's "From Python" section."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## From Python") :]
    match = re.search(r"```python\n(.*?)```", section, flags=re.DOTALL)
    assert match is not None, "README: no python block under 'From Python'"
    return match.group(1)


def run(argv: list[str], cwd: Path, env: dict[str, str]) -> str:
    """Run argv and return its stdout; fail with its stderr."""
    proc = subprocess.run(
        argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT_S, check=False
    )
    assert proc.returncode == 0, f"{argv}: exit {proc.returncode}\n{proc.stderr[-4000:]}"
    return proc.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    """(the fresh venv's python, an environment without this checkout on the path)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=ignore)
        else:
            shutil.copy2(path, src / name)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env |= {"PIP_NO_INDEX": "1", "PIP_DISABLE_PIP_VERSION_CHECK": "1", "MPLBACKEND": "Agg"}
    wheels = tmp / "wheels"
    pip = [sys.executable, "-m", "pip"]
    run([*pip, "wheel", "--no-build-isolation", "--no-deps", "-w", str(wheels), str(src)], tmp, env)
    (wheel,) = wheels.glob("isac_mission-*.whl")
    venv = tmp / "venv"
    run(
        [sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", str(venv)],
        tmp,
        env,
    )
    python = venv / "bin" / "python"
    if sys.prefix != sys.base_prefix:
        # A venv made from a venv sees the base interpreter's site-packages, not this venv's:
        # list this venv's library folders (as plain paths: their .pth files, such as an
        # editable install of this checkout, stay inactive).
        site = Path(
            run(
                [str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                tmp,
                env,
            ).strip()
        )
        libs = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib")}
        (site / "_parent_venv.pth").write_text("".join(f"{p}\n" for p in sorted(libs)))
    run([*pip, "--python", str(python), "install", "--no-deps", "--no-index", str(wheel)], tmp, env)
    return python, env


def test_the_wheel_installs_with_its_version_and_scenarios(
    installed: tuple[Path, dict[str, str]], tmp_path: Path
) -> None:
    python, env = installed
    out = run(
        [
            str(python),
            "-c",
            "import isac_mission as im; print(im.__version__); print(im.__file__); "
            "print(im.scenario_names()); from isac_mission.config import SCENARIOS_DIR; "
            "print(SCENARIOS_DIR); print((SCENARIOS_DIR.parent / 'py.typed').is_file()); "
            "print(sorted(p.name for p in (SCENARIOS_DIR.parent / 'console' / 'static').iterdir()))",
        ],
        tmp_path,
        env,
    )
    version, where, names, scenarios, typed, static = out.splitlines()
    assert version == isac_mission.__version__
    venv = python.parent.parent
    assert Path(where).is_relative_to(venv), where
    assert Path(scenarios).is_relative_to(venv) and not Path(scenarios).is_symlink()
    assert {"paper", "paper-literal", "constrained"} <= set(eval(names))
    assert typed == "True"
    assert {"index.html", "console.js", "draw.js", "console.css"} <= set(eval(static))
    cli = run([str(python.parent / "isac-mission"), "--version"], tmp_path, env)
    assert cli.strip() == f"isac-mission {isac_mission.__version__}"


def test_the_readme_example_runs_from_the_wheel(
    installed: tuple[Path, dict[str, str]], tmp_path: Path
) -> None:
    python, env = installed
    code = readme_example()
    assert len(code.strip().splitlines()) <= 6
    check = (
        "\nfrom matplotlib.figure import Figure\n"
        "assert isinstance(fig, Figure), type(fig)\n"
        "assert fig.axes and fig.axes[0].lines, 'nothing drawn'\n"
        "print(im.__file__, plan.report.status, len(run.trace), scenario.N)\n"
    )
    out = run([str(python), "-c", code + check], tmp_path, env)
    where, status, slots, n = out.split()[-4:]
    assert Path(where).is_relative_to(python.parent.parent)
    assert status == "ok"
    assert int(slots) == int(n) == 60
