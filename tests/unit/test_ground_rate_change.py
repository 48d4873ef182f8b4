"""An operator's new R_th (`set`, service/ground/control.py) on the ground loop's mission state:
the kits are renewed for the new scenario and keep their IPOPT problems, the solve lock and the
problem factory (a rebuild made the next plans of a live mission time out)."""

from __future__ import annotations

import threading
from typing import Any

from isac_mission.config import load_scenario
from isac_mission.planning.fleet import prepare_fleet
from isac_mission.planning.horizon import horizon_nlp
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.nlp_model import NlpSolver, plain_ipopt
from isac_mission.planning.per_slot import polish_nlp
from isac_mission.planning.tracks import multi_target_kit
from isac_mission.service.ground.mission import MissionState
from isac_mission.types import Gaussian


def test_a_new_r_th_keeps_the_ipopt_problems_of_every_fleet_size() -> None:
    s = load_scenario("paper")
    state = MissionState.from_prior(s, SolverKit(s), "horizon", Gaussian(s.x0.copy(), s.P0.copy()))
    prepare_fleet(state.kit, "horizon", 0)
    full, one_out = horizon_nlp(state.kit), horizon_nlp(state.kits.for_active((0, 2)))
    state.set_scenario(s.with_changes(r_th=2 * s.r_th))
    assert state.kit.scenario.r_th == 2 * s.r_th
    assert state.kits.for_active((0, 2)).scenario.r_th == 2 * s.r_th
    assert horizon_nlp(state.kit) is full
    assert horizon_nlp(state.kits.for_active((0, 2))) is one_out


def test_a_new_r_th_on_a_multi_target_mission_keeps_the_solve_lock_and_the_problems() -> None:
    s = load_scenario("multi-target")
    lock = threading.RLock()

    def factory(
        name: str, nlp: dict[str, Any], options: dict[str, Any], like: NlpSolver | None = None
    ) -> NlpSolver:
        return plain_ipopt(name, nlp, options, like)

    base = multi_target_kit(s)
    kit = SolverKit(s, n_keep_out=base.n_keep_out, solve_lock=lock, ipopt=factory)
    mission = MissionState(s, kit, "proposed")
    polish = polish_nlp(mission.kit)
    mission.set_scenario(s.with_changes(r_th=2 * s.r_th))
    assert mission.kit.scenario.r_th == 2 * s.r_th
    assert mission.kit.solve_lock is lock and mission.kit.ipopt is factory
    assert mission.kit.n_keep_out == base.n_keep_out
    assert polish_nlp(mission.kit) is polish
