"""The receding horizon along a manoeuvring belief's curve (docs/model.md, "The interacting
multiple model", "Its bound, and what the planner predicts with"): the IMM's open-loop path
(`ImmPath`) against the circle flown at a known turn rate, and the NLP's path offsets against the
same NLP with the offsets folded into the target's state."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs
from isac_mission.planning.horizon import horizon_bound_traces, horizon_nlp
from isac_mission.planning.horizon_nlp import HorizonSlotData
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import SlotInput
from isac_mission.tracking.imm import ImmBelief, ImmMode, ImmModel, ImmPath
from isac_mission.tracking.pcrb import SensingParams

DT_S = 1.0


def _model(modes: tuple[ImmMode, ...], switching: list[list[float]]) -> ImmModel:
    r = len(modes)
    return ImmModel(modes, np.array(switching), DT_S, np.full(r, 1.0 / r), 0.1)


def _belief(means: np.ndarray, probabilities: list[float]) -> ImmBelief:
    r = len(means)
    covs = np.repeat(np.diag([4.0, 4.0, 1.0, 1.0, 0.01])[None], r, axis=0)
    return ImmBelief(np.asarray(means, dtype=float), covs, np.array(probabilities))


@pytest.mark.parametrize("omega", [0.2, -0.133, 0.4])
def test_a_turn_mode_alone_predicts_the_circle(omega: float) -> None:
    """One ct mode that never switches: the path is the exact arc at omega, written here from
    the circle's equations (heading phi + omega t, radius V / omega)."""
    x0, y0, speed, phi = 100.0, -50.0, 20.0, 0.7
    start = [x0, y0, speed * math.cos(phi), speed * math.sin(phi), omega]
    path = ImmPath(_model((ImmMode("ct", 0.5, 0.01),), [[1.0]]), _belief(np.array([start]), [1.0]))
    offsets = path.offsets(6)
    np.testing.assert_array_equal(offsets[0], np.zeros(4))
    for h in range(1, 6):
        t, heading = h * DT_S, phi + omega * h * DT_S
        arc = np.array(
            [
                x0 + speed / omega * (math.sin(heading) - math.sin(phi)),
                y0 - speed / omega * (math.cos(heading) - math.cos(phi)),
                speed * math.cos(heading),
                speed * math.sin(heading),
            ]
        )
        straight = np.array([x0 + start[2] * t, y0 + start[3] * t, start[2], start[3]])
        np.testing.assert_allclose(offsets[h], arc - straight, atol=1e-9)
    assert np.linalg.norm(offsets[5, :2]) > 10.0  # the curve matters over five slots


def test_straight_modes_have_no_offsets() -> None:
    """Every mode's turn rate 0: the mixture goes straight, offsets 0 (within rounding)."""
    modes = (ImmMode("cv", 0.05), ImmMode("ct", 0.5, 0.01), ImmMode("cv", 8.0))
    switching = [[0.9, 0.05, 0.05], [0.05, 0.9, 0.05], [0.1, 0.1, 0.8]]
    means = np.tile([10.0, 20.0, 15.0, -5.0, 0.0], (3, 1))
    offsets = ImmPath(_model(modes, switching), _belief(means, [0.2, 0.7, 0.1])).offsets(5)
    np.testing.assert_allclose(offsets, 0.0, atol=1e-9)


def test_the_curve_flattens_as_the_turn_mode_mixes_away() -> None:
    """A turn mode at 0.2 rad/s beside a straight mode: the mixture's curve lies between the
    straight line and the turn mode's own circle, and bends less than the circle."""
    modes = (ImmMode("cv", 0.05), ImmMode("ct", 0.5, 0.01))
    start = np.array([[0.0, 0.0, 20.0, 0.0, 0.0], [0.0, 0.0, 20.0, 0.0, 0.2]])
    mixing = ImmPath(_model(modes, [[0.9, 0.1], [0.1, 0.9]]), _belief(start, [0.1, 0.9]))
    turn_only = ImmPath(_model(modes[1:], [[1.0]]), _belief(start[1:], [1.0]))
    bend, circle = mixing.offsets(5)[:, 1], turn_only.offsets(5)[:, 1]
    assert np.all(bend[1:] > 0) and np.all(bend[1:] < circle[1:])


def _scenario() -> Scenario:
    s = load_scenario("paper")
    horizon = s.planner.horizon.model_copy(update={"length": 4})
    return s.with_changes(planner=s.planner.model_copy(update={"horizon": horizon}))


def _slot(s: Scenario) -> tuple[SlotInput, HorizonSlotData]:
    inp = record_slot_inputs(s, "proposed", draw_run_noise(s, 5), SolverKit(s))[1][12]
    nearest = np.argmin(np.linalg.norm(inp.prev_xy_m[:, None] - s.bs_xy[None], axis=-1), axis=1)
    data = HorizonSlotData(
        rate_min_bps=s.r_th,
        prev_xy=inp.prev_xy_m,
        prev_velocity=np.zeros((s.M, 2)),
        serving_xy=s.bs_xy[nearest],
        control_xy=s.bs_xy[nearest],
        keep_out_xy=np.zeros((0, 2)),
        x_pred=inp.lead.state_pred,
        J_pred=inp.lead.prior_information,
        clearance_m=np.full(4, s.d_safe),
    )
    return inp, data


def test_offsets_of_a_velocity_change_are_that_velocity_in_the_state() -> None:
    """Offsets o_h = [h dt dv, dv] move every horizon slot's predicted state to F^h (x + [0, dv]):
    the NLP's objective, and the numeric bound recursion, equal those of the straight belief
    whose velocity is x's + dv, with no offsets."""
    s = _scenario()
    L = 4
    nlp = horizon_nlp(SolverKit(s))
    inp, data = _slot(s)
    rng = np.random.default_rng(3)
    xy = inp.prev_xy_m[None] + np.cumsum(rng.uniform(-15, 15, size=(L, s.M, 2)), axis=0)
    eta = rng.dirichlet(np.ones(s.M), size=L)
    dv = np.array([3.0, -4.0])
    offsets = np.array([[*(h * s.dt * dv), *dv] for h in range(L)])
    moved = replace(data, x_pred=data.x_pred + np.r_[0.0, 0.0, dv])
    x, p = nlp.pack(xy, None, eta, replace(data, path_offset=offsets))
    x_moved, p_moved = nlp.pack(xy, None, eta, moved)
    with_offsets = float(nlp.objective(x, p))
    assert with_offsets == pytest.approx(float(nlp.objective(x_moved, p_moved)), rel=1e-12)
    assert with_offsets != pytest.approx(float(nlp.objective(*nlp.pack(xy, None, eta, data))))
    sensing = SensingParams.from_scenario(s)
    J = data.J_pred
    np.testing.assert_allclose(
        horizon_bound_traces(s, J, data.x_pred, xy, eta, sensing, offsets),
        horizon_bound_traces(s, J, moved.x_pred, xy, eta, sensing),
        rtol=1e-12,
    )


def test_the_clearance_rows_follow_the_offset_path() -> None:
    """UAVs hovering where they are, the target's curve brought onto UAV 0 in horizon slot 2:
    the plan misses its 14j rows there by about (clearance / S)^2; without the offset it does
    not come near them."""
    s = _scenario()
    L = 4
    nlp = horizon_nlp(SolverKit(s))
    inp, data = _slot(s)
    xy = np.repeat(inp.prev_xy_m[None], L, axis=0)
    eta = np.full((L, s.M), 1.0 / s.M)
    straight = data.x_pred[:2] + 2 * s.dt * data.x_pred[2:4]
    offsets = np.zeros((L, 4))
    offsets[2, :2] = inp.prev_xy_m[0] + np.array([2.0, 0.0]) - straight
    curved = replace(data, path_offset=offsets)
    step_m = s.v_max * s.dt
    assert nlp.violation(xy, None, eta, curved) >= 0.9 * (s.d_safe / step_m) ** 2
    assert nlp.violation(xy, None, eta, data) < 0.1 * (s.d_safe / step_m) ** 2
