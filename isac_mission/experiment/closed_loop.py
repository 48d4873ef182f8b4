"""The offline closed loop of Section II-C: predict, plan, fly, measure, update, for N slots.

Every method of one Monte Carlo run sees the same random numbers (`RunNoise`): the same target path,
the same initial estimate error and the same standard-normal measurement draws, scaled by each
method's own noise standard deviations. The planner is the same `plan_slot` the live service calls, and the slot recursion the same
`tracking/cycle.py` (predict -> plan -> update -> bound); the noisy detections are
`model/detections.py`'s, as in `sim/sensing.py`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from isac_mission.config import Scenario, single_target_problem
from isac_mission.errors import ConfigError
from isac_mission.model.detections import noisy_detections
from isac_mission.model.kinematics import transition_matrix
from isac_mission.model.run_noise import RunNoise
from isac_mission.model.run_noise import draw_run_noise as draw_run_noise
from isac_mission.planning.slot import Method, SlotInput, SolverKit, plan_slot
from isac_mission.tracking.cycle import CycleModel, TrackState, predict, update
from isac_mission.tracking.pcrb import Bound
from isac_mission.types import FloatArray, Gaussian, IntArray, SlotPlan


def true_trajectory(s: Scenario, noise: RunNoise) -> FloatArray:
    """[N + 1, 4] target states x_0..x_N of the constant-velocity model (eq. 3)."""
    F = transition_matrix(s.dt)
    xs = np.empty((s.N + 1, 4))
    xs[0] = s.x0
    for n in range(1, s.N + 1):
        xs[n] = F @ xs[n - 1] + noise.process[n - 1]
    return xs


@dataclass(frozen=True)
class SlotOutcome:
    """Everything one slot produced (the trace's contract fields, docs/trace.md).

    slot_input: what the planner was given; uav_xy [M, 2] where measurements were taken; r_diag
    [2M] variances used (NaN = missing);
    target_* [4]; P, J [4, 4].
    """

    slot: int
    method: str
    slot_input: SlotInput
    plan: SlotPlan
    uav_xy: FloatArray
    target_true: FloatArray
    target_pred: FloatArray
    target_est: FloatArray
    r_diag: FloatArray
    P: FloatArray
    bound: Bound


@dataclass(frozen=True)
class RunResult:
    """Per-slot arrays of one run of one method (slots 1..N).

    est, true [N, 4]; pcrb [N, 4, 4] (C = J^-1); solve_s [N]; status [N]; uav_xy [N, M, 2];
    eta [N, M]; assoc [N, M]; fallback [N]: why the method's answer was not flown ("" = it was).
    """

    method: str
    seed: int
    est: FloatArray
    true: FloatArray
    pcrb: FloatArray
    solve_s: FloatArray
    status: list[str]
    uav_xy: FloatArray
    eta: FloatArray
    assoc: IntArray
    fallback: list[str] = field(default_factory=list)


def run_closed_loop(
    s: Scenario,
    method: Method,
    noise: RunNoise,
    kit: SolverKit,
    on_slot: Callable[[SlotOutcome], None] | None = None,
    truth: FloatArray | None = None,
) -> RunResult:
    """Fly one mission of N slots with the given planning method; returns per-slot results.
    truth [N + 1, 4]: the target's true states x_0..x_N (a scripted target); None: the
    constant-velocity model driven by the run's process noise (`true_trajectory`). A scenario of
    the multi-target path raises ConfigError (config.single_target_problem)."""
    problem = single_target_problem(s)
    if problem is not None:
        raise ConfigError(f"{s.mission_id}: {problem}")
    model = CycleModel.from_scenario(s)
    truth = true_trajectory(s, noise) if truth is None else np.asarray(truth, dtype=float)
    state = TrackState(
        belief=Gaussian(x=s.x0 + noise.initial_error, P=s.P0.copy()),
        bound=Bound.from_covariance(s.P0.copy()),
    )
    uav_xy, eta, assoc = s.uav_start_xy.copy(), np.full(s.M, 1.0 / s.M), None
    velocity = np.zeros((s.M, 2))
    plan: SlotPlan | None = None
    rows: dict[str, list[object]] = {
        k: [] for k in ("est", "pcrb", "solve_s", "status", "fallback", "uav_xy", "eta", "assoc")
    }
    for n in range(1, s.N + 1):
        predicted = predict(model, state)
        pred = predicted.prediction
        slot_input = SlotInput(
            uav_xy, eta, assoc, pred.x, predicted.prior, velocity, None, pred.P, plan
        )
        plan = plan_slot(slot_input, kit, method)
        if plan.uav_velocity_mps is not None:
            velocity = plan.uav_velocity_mps  # the vehicle model's planned end velocity
        else:
            velocity = (plan.uav_xy_m - uav_xy) / s.dt  # each leg flown at constant velocity
        uav_xy, eta, assoc = plan.uav_xy_m, plan.bandwidth_share, plan.bs_of_uav
        # Measurements at the planned positions: noise from the true geometry; the filter and the
        # bound use the variances at the predicted state (the target's truth is not theirs).
        z = noisy_detections(
            truth[n],
            uav_xy,
            eta,
            kit.sensing,
            noise.measurement[n - 1],
            noise.miss_draw[n - 1],
            s.missed_detection_prob,
        )
        updated = update(model, state, predicted, kit.sensing, z, uav_xy, eta)
        state, r_used = updated.state, updated.r_used
        belief, bound = state.belief, state.bound
        for key, value in (
            ("est", belief.x),
            ("pcrb", bound.C),
            ("solve_s", plan.report.solve_s),
            ("status", plan.report.status),
            ("fallback", plan.report.fallback),
            ("uav_xy", uav_xy),
            ("eta", eta),
            ("assoc", assoc),
        ):
            rows[key].append(value)
        if on_slot is not None:
            on_slot(
                SlotOutcome(
                    slot=n,
                    method=method,
                    slot_input=slot_input,
                    plan=plan,
                    uav_xy=uav_xy,
                    target_true=truth[n],
                    target_pred=pred.x,
                    target_est=belief.x,
                    r_diag=r_used,
                    P=belief.P,
                    bound=bound,
                )
            )
    return RunResult(
        method=method,
        seed=noise.seed,
        est=np.array(rows["est"]),
        true=truth[1:],
        pcrb=np.array(rows["pcrb"]),
        solve_s=np.array(rows["solve_s"], dtype=float),
        status=[str(v) for v in rows["status"]],
        fallback=[str(v) for v in rows["fallback"]],
        uav_xy=np.array(rows["uav_xy"]),
        eta=np.array(rows["eta"]),
        assoc=np.array(rows["assoc"], dtype=np.int64),
    )


def record_slot_inputs(
    s: Scenario, method: Method, noise: RunNoise, kit: SolverKit
) -> tuple[RunResult, list[SlotInput]]:
    """One run, and the planner's input of every slot (to replay or time the planner alone)."""
    inputs: list[SlotInput] = []
    result = run_closed_loop(s, method, noise, kit, lambda o: inputs.append(o.slot_input))
    return result, inputs
