"""The receding-horizon problem of slots n..n+L-1 as CasADi expressions: a pure description.

    min  sum_i a_i sum_l w_l tr(C_il),  C_il = (J_pred,il + J_M(Q_l, eta_l; x_il))^-1,
         J_pred,i1 = target i's prior information, J_pred,il+1 = (F C_il F^T + W)^-1,
         x_il = F^(l-1) x_pred,i + o_il (the motion model's prediction, and the belief's
         departure o_il from it: a manoeuvring track's curve; 0 otherwise), over the T targets i
         (a_i their weights; one target: no weight, the single-target problem as it was)
    s.t. for every horizon slot l and UAV m (slot n's association kept over the horizon):
         eta_lm R~(|q_lm - w_k(m)| + e) >= R_th                       (14a, with the link margin)
         |q_lm - w_c(m)| + e <= d_th                                   (14b)
         sum_m eta_lm = 1, eta_lm >= 0                                 (14c, 14d)
         |q_lm - q_l-1,m| <= V_max dt                                  (14h)
         vehicle model: also the Hermite leg (q, v)_l-1 -> (q, v)_l within a_max and V_max
         at leg_samples points s of each leg: |q_m(s) - p_i(s)| >= c_il (14j from every
                                              target i along its own path, c_il its clearance)
                                              |q_i(s) - q_j(s)| >= D_s + 2e, |q_m(s) - k| >= D_s + 2e
         0 <= q_lm <= area                                             (operating area, bounds)

with w_l = discount^(l-1) (times terminal_weight on the last slot). The derivatives are exact:
CasADi's automatic differentiation, but the Lagrangian's Hessian is assembled through each
slot's information (planning/horizon_hessian.py: the same matrix at 0.4 of the operations at
M = 24). Everything that changes per slot is a parameter: the UAVs' positions and velocities, the
serving and control BSs, the keep-out points, each target's predicted state, path offsets o_il
(linear between slot ends at the leg samples), prior information and clearances c_il, the
targets' weights (T > 1) and the objective's scale.

Lifted: what IPOPT solves has the scaled predicted covariance Pt_l = E_l P_l+1 E_l of every horizon
slot but the last as 16 variables (per target: target-major, target i's L - 1 blocks after
target i - 1's), with the explicit equality Pt_l = E_l (F C_l F^T + W) E_l, and
slot l + 1 builds its prior on E_l Pt_l^-1 E_l: the same problem (eliminating Pt gives it back),
whose Hessian has one block per slot instead of one dense block over the horizon (docs/model.md,
"Receding horizon"). `HorizonProblem.objective` is the eliminated form.

Scaling: q_lm = q_m,n-1 + S z_lm with S = V_max dt; v_lm = V_max u_lm; D_l = diag(1 / sqrt(diag
J_l)) and E_l = diag(1 / sqrt(diag P_l+1)) taken at the start point (parameters); the objective
is divided by its value at the start point. Distances are constrained squared in units of S^2,
tightened by SOLVER_MARGIN_M.

`build_horizon_problem` depends on the scenario, the number of keep-out points, the pair band
and the number of targets T only (no slot's numbers, no solver): the same arguments build the same expressions, which is
what a compiled problem's key hashes (isac_mission/nlp_cache.py). The numeric solver around it
(a slot's numbers packed, bounds, start points, IPOPT, the answer unpacked) is
planning/horizon_nlp.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Any

import casadi as ca
import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.motion import MotionModel
from isac_mission.model.vehicle import end_accelerations, hermite_position, velocity_control_points
from isac_mission.planning.horizon_hessian import LiftedSlot, horizon_hess_lag, vech
from isac_mission.planning.legs import chord_point_clearance_m
from isac_mission.planning.margins import SafetyMargins, sag_m
from isac_mission.planning.nlp_model import (
    NlpRows,
    add_clearance_row,
    add_uav_rows,
    information_terms,
    scaled_inverse_sx,
    straight_leg_point,
)
from isac_mission.tracking.pcrb import SensingParams
from isac_mission.types import FloatArray, IntArray

Member = tuple[IntArray, ca.SX, ca.SX]
"""One UAV of a horizon slot for the Hessian (planning/horizon_hessian.CoupledStage): the indices
[3] of its variables (z_x, z_y, eta) in x, those variables [3], vech of its J_M terms [10]."""


def lifted_slot(
    J_prior: ca.SX,
    scale_j: ca.SX,
    scale_p: ca.SX,
    Pt: ca.SX | None,
    weight: float | ca.SX,
    F: FloatArray,
    W: FloatArray,
    J_info: ca.SX,
) -> tuple[ca.SX, ca.SX | None]:
    """One slot of the lifted recursion: (weight tr(C), vec(E (F C F^T + W) E - Pt) [16], None on
    the last slot: Pt None) with C = (J_prior + J_info)^-1 [4, 4] (Jacobi-scaled by scale_j [4])
    and E = diag(scale_p [4])."""
    J = J_prior + J_info
    C = scaled_inverse_sx(0.5 * (J + J.T), scale_j)
    term = weight * ca.trace(C)
    if Pt is None:
        return term, None
    E = ca.diag(scale_p)
    P = ca.mtimes(ca.mtimes(ca.DM(F), C), ca.DM(F.T)) + ca.DM(W)
    return term, ca.vec(ca.mtimes(ca.mtimes(E, P), E) - Pt)


def horizon_weights(length: int, discount: float, terminal_weight: float) -> FloatArray:
    """w [L]: discount^l (l = 0..L-1), the last one times terminal_weight."""
    w = discount ** np.arange(length, dtype=float)
    w[-1] *= terminal_weight
    return np.asarray(w)


@dataclass(frozen=True)
class HorizonSymbols:
    """The NLP's symbols, and the UAVs' positions, velocities and legs as expressions of them.

    Variables: z [L M 2] (positions in units of step_m S = V_max dt from prev: q = prev + S z),
    u [L M 2] (velocities in units of V_max; [0] without the vehicle model), eta [L M] (shares),
    lift [16 (L - 1) T] (the lifted covariances, each 4 x 4 column-major, target-major); index
    2 (h M + m) + axis for UAV m at the end of horizon slot h (eta: h M + m). Parameters: prev
    [M 2] (m), v0 [M 2] (m/s), serving, control [M 2] (m), keep_out [n_keep_out 2] (m), x_pred
    [4 T] (m, m/s; target i's at 4 i), j_pred [4, 4 T] (target i's the columns 4 i..4 i + 3),
    clearance [L T] (m; target i's at L i), target_weight [T] (T > 1 only; one target has no
    weight), path_offset [4 L T] (m, m/s: target i's predicted state at the end of horizon slot h
    minus the straight F^h x_pred,i, at 4 (L i + h); zeros for a target that flies straight,
    `TargetBelief.path_offsets`), scale_j, scale_p [4 L T] (the Jacobi scalings, numbers taken at the start point so
    that no derivative runs through them; target i's at 4 L i), f_scale [1]."""

    z: ca.SX
    u: ca.SX
    eta: ca.SX
    lift: ca.SX
    prev: ca.SX
    v0: ca.SX
    serving: ca.SX
    control: ca.SX
    keep_out: ca.SX
    x_pred: ca.SX
    j_pred: ca.SX
    clearance: ca.SX
    target_weight: ca.SX
    path_offset: ca.SX
    scale_j: ca.SX
    scale_p: ca.SX
    f_scale: ca.SX
    M: int
    step_m: float
    v_max_mps: float
    dt_s: float
    vehicle_model: bool
    n_targets: int
    length: int

    @classmethod
    def create(cls, s: Scenario, n_keep_out: int, n_targets: int = 1) -> HorizonSymbols:
        """The symbols of s's horizon (M UAVs, planner.horizon.length slots) with n_keep_out
        keep-out points and n_targets targets (1: the single-target problem's symbols)."""
        M, L, T = s.M, s.planner.horizon.length, n_targets
        if T < 1:
            raise ValueError(f"a horizon problem needs at least one target, not {T}")
        vehicle_model = s.planner.vehicle_model
        return cls(
            z=ca.SX.sym("z", L * M * 2),
            u=ca.SX.sym("u", L * M * 2) if vehicle_model else ca.SX.sym("u", 0),
            eta=ca.SX.sym("eta", L * M),
            lift=ca.SX.sym("lift", 16 * (L - 1) * T),
            prev=ca.SX.sym("prev", M * 2),
            v0=ca.SX.sym("v0", M * 2),
            serving=ca.SX.sym("serving", M * 2),
            control=ca.SX.sym("control", M * 2),
            keep_out=ca.SX.sym("keep_out", n_keep_out * 2),
            x_pred=ca.SX.sym("x_pred", 4 * T),
            j_pred=ca.SX.sym("j_pred", 4, 4 * T),
            clearance=ca.SX.sym("clearance", L * T),
            target_weight=ca.SX.sym("target_weight", T if T > 1 else 0),
            path_offset=ca.SX.sym("path_offset", 4 * L * T),
            scale_j=ca.SX.sym("scale_j", 4 * L * T),
            scale_p=ca.SX.sym("scale_p", 4 * L * T),
            f_scale=ca.SX.sym("f_scale"),
            M=M,
            step_m=s.v_max * s.dt,
            v_max_mps=s.v_max,
            dt_s=s.dt,
            vehicle_model=vehicle_model,
            n_targets=T,
            length=L,
        )

    def parameters(self) -> list[ca.SX]:
        """The parameters in p's order (j_pred column-major; target_weight only for T > 1, so
        that one target's parameters are the single-target problem's)."""
        weight = [self.target_weight] if self.n_targets > 1 else []
        return [
            self.prev,
            self.v0,
            self.serving,
            self.control,
            self.keep_out,
            self.x_pred,
            ca.reshape(self.j_pred, 16 * self.n_targets, 1),
            self.clearance,
            *weight,
            self.path_offset,
            self.scale_j,
            self.scale_p,
            self.f_scale,
        ]

    def state(self, i: int) -> ca.SX:
        """Target i's predicted state [4] (m, m/s) at the end of slot n (one target: x_pred)."""
        return self.x_pred if self.n_targets == 1 else self.x_pred[4 * i : 4 * i + 4]

    def offset(self, i: int, h: int) -> ca.SX:
        """Target i's path offset [4] (m, m/s) at the end of horizon slot h (h = -1, the slot's
        start: zeros)."""
        if h < 0:
            return ca.SX.zeros(4)
        k = 4 * (i * self.length + h)
        return self.path_offset[k : k + 4]

    def predicted(self, i: int, t_s: float, motion: MotionModel) -> ca.SX:
        """Target i's predicted position [2] (m) t_s after the end of slot n (-dt <= t_s <=
        (L - 1) dt): `motion`'s from its state, plus its path offset, linear between the
        slot ends around t_s."""
        h, frac = _slot_of(t_s, self.dt_s)
        off = (1.0 - frac) * self.offset(i, h - 1)[:2] + frac * self.offset(i, h)[:2]
        straight: ca.SX = motion.position_after(self.state(i), t_s)
        return straight + off

    def prior(self, i: int) -> ca.SX:
        """Target i's prior information [4, 4] (one target: j_pred)."""
        return self.j_pred if self.n_targets == 1 else self.j_pred[:, 4 * i : 4 * i + 4]

    def target_clearance(self, i: int, h: int) -> ca.SX:
        """Target i's 14j distance (m) at the leg samples of horizon slot h."""
        return self.clearance[i * self.length + h]

    def weight(self, i: int) -> ca.SX | None:
        """Target i's weight in the objective; None for one target (no weight)."""
        return None if self.n_targets == 1 else self.target_weight[i]

    def scales(self, i: int, h: int) -> tuple[ca.SX, ca.SX]:
        """(scale_j, scale_p) [4] each of target i's horizon slot h."""
        k = 4 * (i * self.length + h)
        return self.scale_j[k : k + 4], self.scale_p[k : k + 4]

    def lifted(self, i: int, h: int) -> ca.SX:
        """Target i's lifted covariance [4, 4] after horizon slot h (h < L - 1)."""
        k = 16 * (i * (self.length - 1) + h)
        return ca.reshape(self.lift[k : k + 16], 4, 4)

    def q(self, h: int, m: int) -> ca.SX:
        """UAV m's position [2] (m) at the end of horizon slot h (0-based; -1: now)."""
        if h < 0:
            return self.prev[2 * m : 2 * m + 2]
        i = 2 * (h * self.M + m)
        return self.prev[2 * m : 2 * m + 2] + self.step_m * self.z[i : i + 2]

    def v(self, h: int, m: int) -> ca.SX:
        """UAV m's velocity [2] (m/s) there (vehicle model only)."""
        if h < 0:
            return self.v0[2 * m : 2 * m + 2]
        i = 2 * (h * self.M + m)
        return self.v_max_mps * self.u[i : i + 2]

    def along(self, h: int, m: int, frac: float) -> ca.SX:
        """UAV m's position [2] (m) at fraction frac of its leg into horizon slot h: the Hermite
        leg with the vehicle model, else the straight one."""
        if self.vehicle_model:
            leg = hermite_position(
                self.q(h - 1, m), self.v(h - 1, m), self.q(h, m), self.v(h, m), self.dt_s, frac
            )
            return ca.SX(leg)
        return straight_leg_point(self.q(h - 1, m), self.q(h, m), frac)

    def sq(self, d: ca.SX) -> ca.SX:
        """|d|^2 in units of step_m^2."""
        return ca.sumsqr(d) / self.step_m**2


@dataclass(frozen=True)
class LegSamples:
    """Where along each leg the clearance rows are (fractions (k + 1) / K, K = leg_samples) and
    the squared distances (units of S^2) they keep from keep-out points (keep2) and between two
    UAVs (pair2, pair_clearance_m in m): between two samples a leg may come closer than at either
    (docs/model.md, "Safety"), so the samples keep the chord's distance, plus the curve's sag off
    its chord."""

    fracs: list[float]
    keep2: float
    pair2: float
    pair_clearance_m: float

    @classmethod
    def of(cls, s: Scenario, margins: SafetyMargins) -> LegSamples:
        S, K = s.v_max * s.dt, s.planner.horizon.leg_samples
        gap_s = s.dt / K
        sag = sag_m(s.a_max, gap_s) if s.planner.vehicle_model else 0.0
        sep = margins.separation_m if s.d_safe > 0 else 0.0
        keep2 = ((float(chord_point_clearance_m(sep, s.v_max * gap_s)) + sag) / S) ** 2
        pair_clearance_m = float(chord_point_clearance_m(sep, 2 * s.v_max * gap_s)) + 2 * sag
        return cls(
            fracs=[(k + 1) / K for k in range(K)],
            keep2=keep2,
            pair2=(pair_clearance_m / S) ** 2,
            pair_clearance_m=pair_clearance_m,
        )


def uav_information(
    sym: HorizonSymbols, h: int, m: int, qm: ca.SX, em: ca.SX, x_l: ca.SX, sensing: SensingParams
) -> tuple[ca.SX, Member]:
    """UAV m's J_M terms [4, 4] in horizon slot h (at qm [2], share em, the target at x_l [4])
    and its member for the Hessian."""
    terms = information_terms(qm, em, x_l, sensing)
    n_zu = int(sym.z.numel()) + int(sym.u.numel())
    i = 2 * (h * sym.M + m)
    index = np.array([i, i + 1, n_zu + h * sym.M + m])
    return terms, (index, ca.vertcat(sym.z[i], sym.z[i + 1], em), vech(terms))


def leg_limits(sym: HorizonSymbols, s: Scenario, h: int, m: int) -> list[ca.SX]:
    """The vehicle model's rows (<= 1) of UAV m's leg into horizon slot h: its end
    accelerations over a_max and its velocity control points over V_max, squared; [] on the
    paper's kinematics."""
    if not sym.vehicle_model:
        return []
    legs = (sym.q(h - 1, m), sym.v(h - 1, m), sym.q(h, m), sym.v(h, m), s.dt)
    limits = [ca.sumsqr(acc) / s.a_max**2 for acc in end_accelerations(*legs)]
    limits += [ca.sumsqr(vc) / s.v_max**2 for vc in velocity_control_points(*legs)[1:]]
    return limits


def add_uav_slot_rows(
    rows: NlpRows,
    sym: HorizonSymbols,
    s: Scenario,
    h: int,
    m: int,
    qm: ca.SX,
    em: ca.SX,
    link_m: float,
    samples: LegSamples,
) -> None:
    """UAV m's rows of horizon slot h (at qm [2] with share em): 14a, 14b, the leg limits and
    14h (nlp_model.add_uav_rows), then at each leg sample 14j from each target along its own
    predicted path (in the targets' order) and the keep-out distance from each keep-out point."""
    # 14h also on the vehicle model: a vehicle faster than V_max now (the live planner's V_max
    # is 0.9 of the vehicles') would otherwise cover more than V_max dt in its first slot.
    limits = leg_limits(sym, s, h, m)
    step2 = sym.sq(qm - sym.q(h - 1, m))
    bs = slice(2 * m, 2 * m + 2)
    S = sym.step_m
    add_uav_rows(rows, s, qm, em, sym.serving[bs], sym.control[bs], step2, link_m, S, limits)
    for frac in samples.fracs:
        for i in range(sym.n_targets):
            p = sym.predicted(i, (h - 1 + frac) * s.dt, s.motion)
            c2 = (sym.target_clearance(i, h) / S) ** 2
            add_clearance_row(rows, sym.along(h, m, frac) - p, c2, S)
        for k in range(int(sym.keep_out.numel()) // 2):
            gap = sym.along(h, m, frac) - sym.keep_out[2 * k : 2 * k + 2]
            add_clearance_row(rows, gap, samples.keep2, S)


def _slot_of(t_s: float, dt_s: float) -> tuple[int, float]:
    """(h, frac): t_s after the end of slot n lies at fraction frac of horizon slot h's leg,
    from the end of slot h - 1 to the end of slot h (h = 0: from -dt_s to 0)."""
    h = math.floor(t_s / dt_s + 1e-9) + 1
    frac = t_s / dt_s - (h - 1)
    if frac < 1e-9 and h > 0:
        h, frac = h - 1, 1.0
    return h, frac


def add_pair_rows(
    rows: NlpRows, sym: HorizonSymbols, h: int, band: int, samples: LegSamples
) -> None:
    """The UAV-UAV rows of horizon slot h at every leg sample: UAV slots a < b with
    b - a <= band."""
    M = sym.M
    for i in range(M):
        for j in range(i + 1, min(M, i + band + 1)):
            for frac in samples.fracs:
                gap = sym.along(h, i, frac) - sym.along(h, j, frac)
                add_clearance_row(rows, gap, samples.pair2, sym.step_m)


@dataclass(frozen=True)
class SlotInformation:
    """One horizon slot's J_M [4, 4] per target (the sum of its UAVs' terms at that target's
    predicted state) and, per target, its UAVs' members."""

    information: list[ca.SX]
    members: list[list[Member]]


def add_slot(
    rows: NlpRows,
    sym: HorizonSymbols,
    s: Scenario,
    h: int,
    band: int,
    margins: SafetyMargins,
    samples: LegSamples,
    sensing: SensingParams,
) -> SlotInformation:
    """Horizon slot h's rows (per UAV `add_uav_slot_rows`, the pairs within band, 14c) and its
    information per target, every target i's J_M at its predicted state x_il = F^h x_pred,i."""
    F = s.motion.transition(s.dt)
    T = sym.n_targets
    Fh = ca.DM(np.linalg.matrix_power(F, h))
    x_l = [ca.mtimes(Fh, sym.state(i)) + sym.offset(i, h) for i in range(T)]
    J_info = [ca.SX.zeros(4, 4) for _ in range(T)]
    members: list[list[Member]] = [[] for _ in range(T)]
    for m in range(sym.M):
        qm = sym.q(h, m)
        em = sym.eta[h * sym.M + m]
        for i in range(T):
            terms, member = uav_information(sym, h, m, qm, em, x_l[i], sensing)
            J_info[i] = J_info[i] + terms
            members[i].append(member)
        add_uav_slot_rows(rows, sym, s, h, m, qm, em, margins.link_m, samples)
    add_pair_rows(rows, sym, h, band, samples)
    rows.add(ca.sum1(sym.eta[h * sym.M : (h + 1) * sym.M]), 1.0, 1.0)
    return SlotInformation(J_info, members)


def add_terminal_rows(rows: NlpRows, sym: HorizonSymbols, s: Scenario) -> int:
    """The terminal rows (docs/model.md, "The terminal row"), one per UAV and target (UAV-major);
    returns their count.

    At the end of the horizon, |r| - |w|^2 / (2 a_max) >= c_L for the offset r from each
    predicted target and the velocity w relative to it (units of S). Braking w at a_max keeps it, so the
    plan shifted by one slot can be continued; without it the horizon ended where no next slot
    could keep the clearance, and the shifted starts of the soak's tracking phase missed their
    rows."""
    L, S, dt = s.planner.horizon.length, sym.step_m, s.dt
    T = sym.n_targets
    target_end = [sym.predicted(i, (L - 1) * dt, s.motion) for i in range(T)]
    brake = s.a_max * dt**2 / S  # in units of S per slot squared
    for m in range(sym.M):
        for i in range(T):
            offset = (sym.q(L - 1, m) - target_end[i]) / S
            target_v = sym.state(i)[2:4] + sym.offset(i, L - 1)[2:4]
            relative = (sym.v(L - 1, m) - target_v) * dt / S
            stopping = ca.sumsqr(relative) / (2 * brake)
            clearance = sym.target_clearance(i, L - 1) / S
            rows.add(ca.norm_2(offset) - stopping - clearance, 0.0, float("inf"))
    return sym.M * T


@dataclass(frozen=True)
class BoundRecursion:
    """The objective along the horizon: `objective` the eliminated sum_i a_i sum_l w_l tr(C_il),
    and `lifted_objective` with `lifted_rows` ((L - 1) T equalities [16] each, = 0, target-major)
    its lifted form; `stages`: per target and slot (target-major) its members and its LiftedSlot
    (the Hessian's, horizon_hess_lag)."""

    objective: ca.SX
    lifted_objective: ca.SX
    lifted_rows: list[ca.SX]
    stages: list[tuple[list[Member], LiftedSlot]]


def bound_recursion(
    sym: HorizonSymbols, slots: list[SlotInformation], s: Scenario, weights: FloatArray
) -> BoundRecursion:
    """The bound's recursion of every target (`target_recursion`), their terms summed in the
    targets' order; one target's is the single-target problem's recursion itself."""
    if sym.n_targets == 1:
        return target_recursion(sym, 0, slots, s, weights)
    stages: list[tuple[list[Member], LiftedSlot]] = []
    lifted_rows: list[ca.SX] = []
    lifted_objective = ca.SX(0.0)
    objective = ca.SX(0.0)
    for i in range(sym.n_targets):
        one = target_recursion(sym, i, slots, s, weights)
        stages += one.stages
        lifted_rows += one.lifted_rows
        lifted_objective = lifted_objective + one.lifted_objective
        objective = objective + one.objective
    return BoundRecursion(objective, lifted_objective, lifted_rows, stages)


def target_recursion(
    sym: HorizonSymbols, i: int, slots: list[SlotInformation], s: Scenario, weights: FloatArray
) -> BoundRecursion:
    """Target i's bound recursion over the slots' information (its J_M at its own predicted
    states), eliminated and lifted, each slot's term weighted by weights[h] [L] (times the
    target's weight where there are several targets).

    Lifted (docs/model.md, "Receding horizon"): the scaled predicted covariance
    Pt_h = E_h (F C_h F^T + W) E_h of every slot but the last is a variable, tied by that
    equality (the covariance's own dynamics, explicit), and slot h + 1 builds on its inverse.
    Eliminated, every tr(C_l) depends on all earlier slots through nested inverses: a dense
    Hessian that took 53 % of a solve at M = 3 and most of the build; lifted, each slot's terms
    couple its own UAVs with 16 numbers."""
    L = len(slots)
    F, W = s.motion.transition(s.dt), s.motion.process_noise(s.dt)
    ones4 = ca.SX.ones(4)
    target_weight = sym.weight(i)
    stages: list[tuple[list[Member], LiftedSlot]] = []
    lifted_rows: list[ca.SX] = []
    lifted_objective = ca.SX(0.0)
    objective = ca.SX(0.0)
    J_prior = sym.prior(i)
    J_prior_lifted = sym.prior(i)
    for h, slot_info in enumerate(slots):
        information = slot_info.information[i]
        J = J_prior + information
        dj, dp = sym.scales(i, h)
        C = scaled_inverse_sx(0.5 * (J + J.T), dj)
        weight = weights[h] if target_weight is None else weights[h] * target_weight
        objective = objective + weight * ca.trace(C)
        Pt = sym.lifted(i, h) if h + 1 < L else None
        slot = partial(lifted_slot, J_prior_lifted, dj, dp, Pt, weight, F, W)
        term, row = slot(information)
        stages.append((slot_info.members[i], slot))
        lifted_objective = lifted_objective + term
        if h + 1 < L:
            assert row is not None and Pt is not None
            lifted_rows.append(row)
            P = ca.mtimes(ca.mtimes(ca.DM(F), C), ca.DM(F.T)) + ca.DM(W)
            J_prior = scaled_inverse_sx(0.5 * (P + P.T), dp)
            E = ca.diag(dp)
            Pt_inv = scaled_inverse_sx(0.5 * (Pt + Pt.T), ones4)
            J_prior_lifted = ca.mtimes(ca.mtimes(E, Pt_inv), E)
    return BoundRecursion(objective, lifted_objective, lifted_rows, stages)


@dataclass(frozen=True)
class HorizonProblem:
    """The horizon NLP of a scenario, n_keep_out keep-out points, a pair band and n_targets
    targets T, symbolic.

    x [n_x] = (z, u, eta) (HorizonSymbols' variables), lift [n_lift = 16 (L - 1) T], p [sum
    param_sizes] (HorizonSymbols' parameters in order); g [n_rows] the rows, lbg <= g <= ubg
    (per horizon slot its UAVs' rows, its pairs', 14c; then n_terminal terminal rows, M T or
    none), rate_rows
    the indices of the 14a rows (their bound moves with R_th: nlp_model.lower_at_rate);
    g_lifted [n_lift] the lifted equalities (= 0). `objective` is the eliminated objective,
    `lifted_objective` the lifted one (both before the division by the parameter f_scale);
    `nlp` what IPOPT solves ({"x": (x, lift), "p", "f": lifted_objective / f_scale,
    "g": (g, g_lifted)}) and `hess_lag` its Lagrangian's Hessian (nlpsol's option).
    pair_band: the UAV-UAV rows' band (M - 1: every pair); pair_clearance_m: the distance those
    rows keep at each leg sample, m; step_m: S = V_max dt, m."""

    x: ca.SX
    lift: ca.SX
    p: ca.SX
    g: ca.SX
    g_lifted: ca.SX
    objective: ca.SX
    lifted_objective: ca.SX
    nlp: dict[str, ca.SX]
    hess_lag: ca.Function
    lbg: FloatArray
    ubg: FloatArray
    rate_rows: IntArray
    param_sizes: list[int]
    n_terminal: int
    length: int
    pair_band: int
    pair_clearance_m: float
    step_m: float
    vehicle_model: bool
    margins: SafetyMargins
    n_targets: int = 1

    @property
    def n_x(self) -> int:
        return int(self.x.numel())

    @property
    def n_lift(self) -> int:
        return int(self.lift.numel())


def build_horizon_problem(
    scenario: Scenario, n_keep_out: int = 0, pair_band: int | None = None, n_targets: int = 1
) -> HorizonProblem:
    """The horizon NLP of the scenario's M UAVs with n_keep_out keep-out points; pair_band: the
    UAV-UAV rows only of the UAV slots a < b with b - a <= pair_band (planning/pairs.py), None:
    every pair; n_targets: the targets T it plans for (the weighted sum of their horizon
    objectives, 14j from each; 1: the single-target problem, its expressions unchanged)."""
    s = scenario
    cfg = s.planner.horizon
    M, L = s.M, cfg.length
    band = M - 1 if pair_band is None else min(pair_band, M - 1)
    margins = SafetyMargins.of(s)
    samples = LegSamples.of(s, margins)
    sensing = SensingParams.from_scenario(s)
    sym = HorizonSymbols.create(s, n_keep_out, n_targets)
    params = sym.parameters()
    rows = NlpRows()
    slots = [add_slot(rows, sym, s, h, band, margins, samples, sensing) for h in range(L)]
    weights = horizon_weights(L, cfg.discount, cfg.terminal_weight)
    bound = bound_recursion(sym, slots, s, weights)
    n_terminal = 0
    if sym.vehicle_model and cfg.terminal_braking:
        n_terminal = add_terminal_rows(rows, sym, s)
    x = ca.vertcat(sym.z, sym.u, sym.eta)
    p = ca.vertcat(*params)
    lbg, ubg = rows.bounds()
    g = ca.vertcat(*rows.rows)
    g_lifted = ca.vertcat(*bound.lifted_rows)
    hess_lag = horizon_hess_lag(
        ca.vertcat(x, sym.lift), p, g, sym.lift, bound.stages, sym.f_scale, n_targets
    )
    nlp: dict[str, Any] = {
        "x": ca.vertcat(x, sym.lift),
        "p": p,
        "f": bound.lifted_objective / sym.f_scale,
        "g": ca.vertcat(g, g_lifted),
    }
    return HorizonProblem(
        x=x,
        lift=sym.lift,
        p=p,
        g=g,
        g_lifted=g_lifted,
        objective=bound.objective,
        lifted_objective=bound.lifted_objective,
        nlp=nlp,
        hess_lag=hess_lag,
        lbg=lbg,
        ubg=ubg,
        rate_rows=np.array(rows.rate_rows, dtype=int),
        param_sizes=[int(q.numel()) for q in params],
        n_terminal=n_terminal,
        length=L,
        pair_band=band,
        pair_clearance_m=samples.pair_clearance_m,
        step_m=sym.step_m,
        vehicle_model=sym.vehicle_model,
        margins=margins,
        n_targets=n_targets,
    )
