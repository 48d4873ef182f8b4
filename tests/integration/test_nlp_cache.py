"""Compiled IPOPT problems cached on disk (isac_mission/nlp_cache.py): a compiled solver gives the
interpreted one's numbers, the cache is read back without compiling, a background compile takes
over at the next solve, and every way it can fail leaves the planner interpreted. Live tier: the
compiles run a C compiler in a child process."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.config.live_settings import LIVE_SETTINGS
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs
from isac_mission.nlp_cache import COMPILE_ENV, COMPILER_ENV, CompiledNlpCache, UpgradingSolver
from isac_mission.planning.horizon import horizon_nlp
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.per_slot import polish_nlp
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.types import SlotPlan
from tests.support.live_cli import cli

COMPILE_TIMEOUT_S = 600.0
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def compiling_on(monkeypatch: pytest.MonkeyPatch) -> None:
    """The suite turns compiling off (tests/conftest.py); these tests are about it."""
    monkeypatch.delenv(COMPILE_ENV, raising=False)


def small_horizon() -> Scenario:
    """paper.yaml with the live settings (vehicle model) and a short horizon with two leg samples:
    every row kind of the horizon NLP, compiled in seconds."""
    s = LIVE_SETTINGS.apply(load_scenario("paper"))
    horizon = s.planner.horizon.model_copy(update={"length": 2, "leg_samples": 2})
    return s.with_changes(planner=s.planner.model_copy(update={"horizon": horizon}), N=8)


@pytest.fixture(scope="module")
def inputs() -> list[SlotInput]:
    s = small_horizon()
    return record_slot_inputs(s, "horizon", draw_run_noise(s, 3), SolverKit(s))[1]  # type: ignore[arg-type]


def plans(kit: SolverKit, inputs: list[SlotInput]) -> list[SlotPlan]:
    return [plan_slot(inp, kit, "horizon") for inp in inputs]


def assert_same_plans(got: list[SlotPlan], want: list[SlotPlan]) -> None:
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a.uav_xy_m, b.uav_xy_m)
        np.testing.assert_array_equal(a.bandwidth_share, b.bandwidth_share)
        np.testing.assert_array_equal(a.uav_velocity_mps, b.uav_velocity_mps)
        assert a.report.polish == b.report.polish  # IPOPT's status, iterations and objective


def test_a_compiled_solver_evaluates_and_plans_as_the_interpreted_one(
    tmp_path: Path, inputs: list[SlotInput]
) -> None:
    s = small_horizon()
    cache = CompiledNlpCache(tmp_path, compile="now")
    compiled_kit, plain_kit = SolverKit(s, ipopt=cache), SolverKit(s)
    compiled, plain = horizon_nlp(compiled_kit).solver, horizon_nlp(plain_kit).solver
    assert any(line.startswith("horizon: compiled in") for line in cache.events), cache.events
    assert isinstance(compiled, ca.Function) and isinstance(plain, ca.Function)
    rng = np.random.default_rng(7)
    for name in ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l"):
        fc, fp = compiled.get_function(name), plain.get_function(name)
        for _ in range(3):
            args = [rng.normal(0.3, 0.5, size=fp.sparsity_in(i).shape) for i in range(fp.n_in())]
            for out_c, out_p in zip(fc.call(args), fp.call(args), strict=True):
                a, b = np.asarray(ca.DM(out_c)), np.asarray(ca.DM(out_p))
                np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * max(1.0, np.abs(b).max()))
    assert_same_plans(plans(compiled_kit, inputs), plans(plain_kit, inputs))


def test_the_warm_start_solver_shares_the_compiled_derivatives_of_the_cold_one(
    tmp_path: Path, inputs: list[SlotInput]
) -> None:
    s = small_horizon()
    cache = CompiledNlpCache(tmp_path, compile="now")
    nlp = horizon_nlp(SolverKit(s, ipopt=cache))
    assert [line.split(" in ")[0] for line in cache.events if "compiled in" in line] == [
        "horizon: compiled"
    ], cache.events
    assert any(line.startswith("horizon_warm: shares the compiled") for line in cache.events)
    assert len(list(tmp_path.glob("*.casadi"))) == 1
    cold, warm = nlp.solver, nlp.warm_solver
    assert isinstance(cold, ca.Function) and isinstance(warm, ca.Function)
    for name in ("nlp_grad_f", "nlp_jac_g", "nlp_hess_l"):
        # The very functions: compiled once, evaluated by both.
        assert warm.get_function(name).serialize() == cold.get_function(name).serialize()
    # A background compile: the warm solver upgrades with the cold one.
    background = CompiledNlpCache(tmp_path / "again", compile="background")
    again = horizon_nlp(SolverKit(s, ipopt=background))
    assert isinstance(again.warm_solver, UpgradingSolver)
    assert isinstance(again.solver, UpgradingSolver)
    assert again.warm_solver.wait(COMPILE_TIMEOUT_S), background.events
    assert again.solver.compiled
    assert len(list((tmp_path / "again").glob("*.casadi"))) == 1


def test_a_second_build_loads_from_the_cache_without_compiling(
    tmp_path: Path, inputs: list[SlotInput]
) -> None:
    s = small_horizon()
    first = CompiledNlpCache(tmp_path, compile="now")
    polish_nlp(SolverKit(s, ipopt=first))
    again = CompiledNlpCache(tmp_path, compile="now")
    polish_nlp(SolverKit(s, ipopt=again))
    assert [line for line in again.events if "compiled in" in line] == []
    assert any("loaded from the cache" in line for line in again.events), again.events
    # Another problem (another fleet size) is another file.
    other = s.with_changes(M=2, uav_start_xy=s.uav_start_xy[:2])
    polish_nlp(SolverKit(other, ipopt=again))
    assert any(line.startswith("polish: compiled in") for line in again.events), again.events


def test_a_background_compile_takes_over_at_the_next_solve(
    tmp_path: Path, inputs: list[SlotInput]
) -> None:
    s = small_horizon()
    cache = CompiledNlpCache(tmp_path, compile="background")
    kit = SolverKit(s, ipopt=cache)
    solver = horizon_nlp(kit).solver
    assert isinstance(solver, UpgradingSolver) and not solver.compiled
    want = plans(SolverKit(s), inputs)
    before = plans(kit, inputs[:2])  # interpreted, while the child compiles
    assert solver.wait(COMPILE_TIMEOUT_S), cache.events
    after = plans(kit, inputs[2:])
    assert solver.compiled
    assert_same_plans(before + after, want)


def test_without_a_compiler_the_planner_stays_interpreted(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, inputs: list[SlotInput]
) -> None:
    monkeypatch.setenv(COMPILER_ENV, "no-such-compiler")
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    cache = CompiledNlpCache(tmp_path, compile="background")
    assert cache.compiler is None
    kit = SolverKit(small_horizon(), ipopt=cache)
    assert_same_plans(plans(kit, inputs[:2]), plans(SolverKit(small_horizon()), inputs[:2]))
    assert any("interpreted (no C compiler" in line for line in cache.events), cache.events
    assert list(tmp_path.glob("*.casadi")) == []


def test_compiling_off_still_loads_what_is_cached(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = small_horizon()
    polish_nlp(SolverKit(s, ipopt=CompiledNlpCache(tmp_path, compile="now")))
    monkeypatch.setenv(COMPILE_ENV, "off")
    cache = CompiledNlpCache(tmp_path)
    assert cache.compiler is None
    polish_nlp(SolverKit(s, ipopt=cache))
    assert any("loaded from the cache" in line for line in cache.events), cache.events


def test_a_cache_file_that_does_not_load_is_removed_and_rebuilt(
    tmp_path: Path, inputs: list[SlotInput]
) -> None:
    s = small_horizon()
    polish_nlp(SolverKit(s, ipopt=CompiledNlpCache(tmp_path, compile="now")))
    [cached] = tmp_path.glob("polish-*.casadi")
    cached.write_text("not a CasADi file")
    cache = CompiledNlpCache(tmp_path, compile="now")
    polish_nlp(SolverKit(s, ipopt=cache))
    assert any("could not be loaded" in line for line in cache.events), cache.events
    assert any(line.startswith("polish: compiled in") for line in cache.events), cache.events
    assert CompiledNlpCache(tmp_path).load(cached) is not None


def test_a_failing_compiler_leaves_the_planner_interpreted(
    tmp_path: Path, inputs: list[SlotInput]
) -> None:
    fake = tmp_path / "bin" / "cc"
    fake.parent.mkdir()
    fake.write_text("#!/bin/sh\necho 'cc: internal error' >&2\nexit 3\n")
    fake.chmod(0o755)
    cache = CompiledNlpCache(tmp_path / "cache", compile="background", compiler=str(fake))
    kit = SolverKit(small_horizon(), ipopt=cache)
    solver = horizon_nlp(kit).solver
    assert isinstance(solver, UpgradingSolver)
    assert not solver.wait(COMPILE_TIMEOUT_S)
    assert any("not compiled" in line for line in cache.events), cache.events
    assert_same_plans(plans(kit, inputs[:2]), plans(SolverKit(small_horizon()), inputs[:2]))


def test_the_compile_command_fills_the_cache_for_run(tmp_path: Path) -> None:
    import yaml

    paper = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    paper["uavs"]["start_xy_m"] = paper["uavs"]["start_xy_m"][:2]
    paper.setdefault("planner", {})["horizon"] = {"length": 2, "leg_samples": 1}
    config = tmp_path / "small.yaml"
    config.write_text(yaml.safe_dump(paper))
    env = {**os.environ, "ISAC_MISSION_NLP_CACHE": str(tmp_path / "cache")}
    env.pop(COMPILE_ENV, None)

    def compile_command(env: dict[str, str]) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            cli("compile", str(config)),
            env=env,
            capture_output=True,
            text=True,
            timeout=COMPILE_TIMEOUT_S,
        )

    done = compile_command(env)
    assert done.returncode == 0, done.stderr
    # The fleet and the fleet with one vehicle out: the polish and the horizon each; the
    # horizon's warm-start solver (docs/model.md, "Last slot's multipliers") shares its cold
    # solver's compiled derivatives.
    assert done.stdout.count("compiled in") == 4, done.stdout
    for name in ("polish", "horizon"):
        assert done.stdout.count(f"{name}: compiled in") == 2, done.stdout
    assert done.stdout.count("horizon_warm: shares the compiled derivatives") == 2, done.stdout
    assert len(list((tmp_path / "cache").glob("*.casadi"))) == 4
    refused = compile_command({**env, COMPILE_ENV: "off"})
    assert refused.returncode == 2 and "no C compiler" in refused.stderr
