"""The model as CasADi expressions, shared by the NLPs (planning/polish.py, planning/horizon_nlp.py).

Eq. 8's information terms (`information_terms`, from model/radar.SensingParams, the same code the
numpy objective runs), the constraint rows and their bounds (`NlpRows`, the 14a row
`relative_rate`), 4 x 4 inverses of symbols, the solve lock's type, and how an NLP becomes an
IPOPT solver (`IpoptFactory`: `plain_ipopt`, or compiled and cached on disk by
isac_mission/nlp_cache.py)."""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import AbstractContextManager
from typing import Any, Protocol

import casadi as ca
import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.radar import SensingParams
from isac_mission.planning.margins import RATE_MARGIN, SOLVER_MARGIN_M
from isac_mission.types import FloatArray, IntArray

SolveLock = AbstractContextManager[Any]
"""What SolverKit.solve_lock is: held around every IPOPT construction and solve. The live service
passes one threading lock to all its kits (IPOPT's MUMPS keeps global state: two solves at once,
a timed-out plan's thread beside the next slot's, corrupt memory); offline it is a null context."""


class NlpSolver(Protocol):
    """An IPOPT solver as the NLPs use it: a call with x0, p, lbx, ubx, lbg, ubg, and the stats of
    the last call (a casadi nlpsol Function is one)."""

    def __call__(self, **arguments: Any) -> Any: ...

    def stats(self) -> Any: ...


class IpoptFactory(Protocol):
    """Builds the solver of an NLP {"x", "p", "f", "g"} (SX) with nlpsol's options. The solvers it
    returns evaluate the same functions: a compiled one (isac_mission/nlp_cache.py) gives the
    same numbers as the interpreted one (tests/integration/test_nlp_cache.py).

    like: a solver this factory built for the same nlp (with other options): an interpreted
    solver built now may take its derivatives (`shared_derivatives`) instead of generating them."""

    def __call__(
        self,
        name: str,
        nlp: dict[str, Any],
        options: dict[str, Any],
        like: NlpSolver | None = None,
    ) -> NlpSolver: ...


DERIVATIVES: dict[str, str] = {
    "grad_f": "nlp_grad_f",
    "jac_g": "nlp_jac_g",
    "hess_lag": "nlp_hess_l",
}
"""nlpsol's options for the derivative functions, and the names a built solver has them under."""


def shared_derivatives(like: NlpSolver | None) -> dict[str, ca.Function]:
    """The options that give a new nlpsol the derivative functions (the objective's gradient, the
    rows' Jacobian, the Lagrangian's Hessian) of `like`, a built solver of the same NLP; {} when
    like is None or not a CasADi Function. Generating them is most of an nlpsol's build (the
    horizon at M = 12: about 3.0 of 3.2 s): the horizon's warm-start instance builds in a fraction,
    and evaluates the same functions."""
    if not isinstance(like, ca.Function):
        return {}
    return {option: like.get_function(name) for option, name in DERIVATIVES.items()}


def plain_ipopt(
    name: str, nlp: dict[str, Any], options: dict[str, Any], like: NlpSolver | None = None
) -> NlpSolver:
    """IPOPT through CasADi's interpreted functions (no compiler, no files); like: a solver of
    the same nlp whose derivatives it takes (`shared_derivatives`)."""
    solver: NlpSolver = ca.nlpsol(name, "ipopt", nlp, {**options, **shared_derivatives(like)})
    return solver


class NlpRows:
    """The constraint rows g of an NLP with their bounds lbg <= g <= ubg; rate_rows: the indices
    of its 14a rows (`relative_rate`, whose bound `lower_at_rate` moves with R_th)."""

    def __init__(self) -> None:
        self.rows: list[ca.SX] = []
        self.lower: list[float] = []
        self.upper: list[float] = []
        self.rate_rows: list[int] = []

    def add(self, expr: ca.SX, lo: float, hi: float) -> None:
        """Append the row lo <= expr <= hi (scalar SX)."""
        self.rows.append(expr)
        self.lower.append(lo)
        self.upper.append(hi)

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """(lbg, ubg) as arrays."""
        return np.array(self.lower, dtype=float), np.array(self.upper, dtype=float)


def relative_rate(q: ca.SX, serving: ca.SX, eta: ca.SX, s: Scenario, link_margin_m: float) -> ca.SX:
    """eta R~(|q - w| + e) / R_th - 1 (14a, >= 0 when met): UAV at q [2] on the BS at serving [2]
    with share eta, as if e = link_margin_m (m) farther from the BS. R_th is s's, the NLP's
    build value; another R_th is a bound of the row (`lower_at_rate`)."""
    d2 = ca.sumsqr(q - serving)
    dist2 = d2 if link_margin_m == 0 else (ca.sqrt(d2 + 1e-12) + link_margin_m) ** 2
    rate: ca.SX = eta * s.B * ca.log1p(s.rho0 / (dist2 + s.dH**2)) / (np.log(2.0) * s.r_th)
    return rate - 1.0


def lower_at_rate(
    lbg: FloatArray, rate_rows: IntArray, built_bps: float, r_th_bps: float
) -> FloatArray:
    """The lower bounds lbg [n_rows] of an NLP built for R_th = built_bps, for R_th = r_th_bps:
    its 14a rows (indices rate_rows) are eta R / built_bps - 1 >= RATE_MARGIN, so for r_th_bps
    they take the bound (1 + RATE_MARGIN) r_th_bps / built_bps - 1. lbg itself (the same
    numbers, bit for bit) when the two are equal. An operator's new R_th (the service's `set`)
    thus keeps the NLP: rebuilt, its build made the next plans of a live mission time out."""
    if r_th_bps == built_bps:
        return lbg
    out = np.array(lbg, dtype=float)
    out[np.asarray(rate_rows, dtype=int)] = (1.0 + RATE_MARGIN) * (r_th_bps / built_bps) - 1.0
    return out


def scaled_inverse_sx(A: ca.SX, scale: ca.SX) -> ca.SX:
    """A^-1 [4, 4] of a symmetric positive-definite SX matrix, scaled by D = diag(scale [4])
    first (A^-1 = D (D A D)^-1 D), by 2 x 2 blocks (Schur complement: a far smaller expression,
    and Hessian, than a symbolic solve; a symbolic scaling 1 / sqrt(diag A) made the Hessian ten
    times dearer)."""
    D = ca.diag(scale)
    S = ca.mtimes(ca.mtimes(D, A), D)
    P, Q, R = S[:2, :2], S[:2, 2:], S[2:, 2:]
    P_inv = _inverse_2x2(P)
    schur_inv = _inverse_2x2(R - ca.mtimes(ca.mtimes(Q.T, P_inv), Q))
    X = ca.mtimes(P_inv, Q)  # P^-1 Q
    top_right = -ca.mtimes(X, schur_inv)
    top_left = P_inv + ca.mtimes(ca.mtimes(X, schur_inv), X.T)
    inv = ca.vertcat(ca.horzcat(top_left, top_right), ca.horzcat(top_right.T, schur_inv))
    return ca.mtimes(ca.mtimes(D, inv), D)


def _inverse_2x2(A: ca.SX) -> ca.SX:
    """A^-1 of a 2 x 2 SX matrix by its adjugate."""
    det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    adj = ca.vertcat(ca.horzcat(A[1, 1], -A[0, 1]), ca.horzcat(-A[1, 0], A[0, 0]))
    return adj / det


def information_terms(q: ca.SX, eta: ca.SX, x_pred: ca.SX, sensing: SensingParams) -> ca.SX:
    """J_M's terms [4, 4] of one UAV at q [2] with share eta (eq. 8 and 12, as
    tracking/pcrb.PlanningObjective): a g g^T + b k k^T with g, k the rows of H (eq. 10) and
    a, b eq. 8's information (SensingParams)."""
    r = x_pred[:2] - q
    d2 = ca.sumsqr(r)
    d = ca.sqrt(d2)
    u = r / d
    w = x_pred[2:]
    v_r = ca.dot(u, w)
    g = ca.vertcat(u, 0.0, 0.0)
    k = ca.vertcat((w - v_r * u) / d, u)
    a = sensing.range_information(d, eta)
    b = sensing.velocity_information(d)
    terms: ca.SX = a * (g @ g.T) + b * (k @ k.T)
    return terms


def straight_leg_point(q0: ca.SX, q1: ca.SX, tau: float) -> ca.SX:
    """The point at fraction tau of the straight leg q0 -> q1, in the polish's form (the
    horizon's former q0 + tau (q1 - q0) differs by round-off; which path moved is measured in
    docs/model.md, "The polish")."""
    point: ca.SX = tau * q1 + (1.0 - tau) * q0
    return point


def add_uav_rows(
    rows: NlpRows,
    s: Scenario,
    q: ca.SX,
    eta: ca.SX,
    serving: ca.SX,
    control: ca.SX,
    step2: ca.SX,
    link_m: float,
    scale_m: float,
    leg_limits: Sequence[ca.SX] = (),
    reach: Sequence[ca.SX] = (),
) -> None:
    """One UAV's rows of one slot, distances in units of scale_m: 14a on the serving BS and 14b
    to the control BS, both link_m farther away (the safety rule's e); `leg_limits` (rows <= 1:
    the vehicle model's accelerations and velocities); 14h on step2, the slot's squared step in
    units of scale_m^2; `reach` (rows <= 0: the dynamics disk). Every distance is tightened by
    SOLVER_MARGIN_M, the rate by RATE_MARGIN (planning/margins.py)."""
    inf = float("inf")
    rows.rate_rows.append(len(rows.rows))
    rows.add(relative_rate(q, serving, eta, s, link_m), RATE_MARGIN, inf)
    control2 = (max(s.d_th - link_m - SOLVER_MARGIN_M, 0.0) / scale_m) ** 2
    rows.add(ca.sumsqr(q - control) / scale_m**2, -inf, control2)
    for limit in leg_limits:
        rows.add(limit, -inf, 1.0)
    rows.add(step2, -inf, ((scale_m - SOLVER_MARGIN_M) / scale_m) ** 2)
    for limit in reach:
        rows.add(limit, -inf, 0.0)


def add_clearance_row(rows: NlpRows, gap: ca.SX, clearance2: ca.SX | float, scale_m: float) -> None:
    """14i/14j at one leg sample: |gap|^2 / scale_m^2 >= clearance2, gap [2] the offset between
    the two parties there; clearance2 a number (the row's bound), or a parameter (the row is
    then the difference >= 0)."""
    d2 = ca.sumsqr(gap) / scale_m**2
    if isinstance(clearance2, float):
        rows.add(d2, clearance2, float("inf"))
    else:
        rows.add(d2 - clearance2, 0.0, float("inf"))
