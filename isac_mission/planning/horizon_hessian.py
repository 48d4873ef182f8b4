"""The Lagrangian's Hessian of an NLP whose dense coupling runs through a few numbers per stage,
and the horizon's (`horizon_hess_lag`).

In the horizon's NLP (planning/horizon_nlp.py) the M UAVs of a slot meet only in the slot's
information J_M = sum_m T_m(x_m), 10 numbers (a symmetric 4 x 4), with x_m = (z_m, eta_m) one
UAV's 3 variables: the slot's objective term and its lifted equalities are a function
Phi(y, w) of y = vech(J_M) and a few other variables w (the lifted covariance before it). By the
chain rule the slot's block of the Hessian is

    d2 L / dx_m dx_n = Y_m^T (d2 Phi / dy2) Y_n  +  [m = n] d2 (mu . T_m) / dx_m2,
    d2 L / dx_m dw   = Y_m^T (d2 Phi / dy dw),       d2 L / dw2 = d2 Phi / dw2,

with Y_m = dT_m / dx_m [10 x 3] and mu = dPhi / dy [10]: 3M x 3M dense entries, each a
10-term sum. CasADi's automatic Hessian of the same Lagrangian finds the same numbers without the
bottleneck: 1.94 million operations for the horizon's problem at M = 24 against 0.75 million
here (docs/decisions/0019-hessian-through-the-information.md). Everything else (the
per-UAV, pair and terminal rows) keeps CasADi's sparse automatic Hessian.

Pure CasADi; no I/O.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from isac_mission.types import IntArray

N_SYM = 10
"""Entries of a symmetric 4 x 4 matrix's upper triangle (vech)."""

_UPPER = [(i, j) for i in range(4) for j in range(i, 4)]


def vech(A: ca.SX) -> ca.SX:
    """The upper triangle [10] of a symmetric 4 x 4 SX matrix, row by row."""
    return ca.vertcat(*[A[i, j] for i, j in _UPPER])


def unvech(y: ca.SX) -> ca.SX:
    """The symmetric 4 x 4 matrix of its upper triangle y [10] (`vech`'s order)."""
    rows = [[ca.SX(0.0)] * 4 for _ in range(4)]
    for k, (i, j) in enumerate(_UPPER):
        rows[i][j] = rows[j][i] = y[k]
    return ca.vertcat(*[ca.horzcat(*row) for row in rows])


@dataclass(frozen=True)
class CoupledStage:
    """One stage's coupling: `members` the per-member terms, each (indices [k] of its variables
    in x, their symbols [k], vech of its terms [10] as an expression of them); `phi(y)` the
    stage's part of the Lagrangian (multipliers included) as an expression of y = vech of the
    members' sum [10] and of the variables `outer` (symbols [j], indices `outer_index` [j] in x),
    independent of the members' variables but through y."""

    members: Sequence[tuple[IntArray, ca.SX, ca.SX]]
    phi: Callable[[ca.SX], ca.SX]
    outer: ca.SX
    outer_index: IntArray


def _add(entries: dict[tuple[int, int], ca.SX], i: int, j: int, value: ca.SX) -> None:
    key = (i, j) if i <= j else (j, i)
    entries[key] = entries[key] + value if key in entries else value


def _add_block(
    entries: dict[tuple[int, int], ca.SX],
    rows: IntArray,
    cols: IntArray,
    block: ca.SX,
    diagonal: bool,
) -> None:
    """block [len(rows), len(cols)] at (rows, cols), its upper triangle only; diagonal: rows is
    cols and block symmetric (its lower half skipped)."""
    for a, i in enumerate(rows):
        for b, j in enumerate(cols):
            if diagonal and b < a:
                continue
            value = block[a, b]
            if not (value.is_constant() and float(value) == 0.0):
                _add(entries, int(i), int(j), value)


def stage_hessian(stage: CoupledStage, entries: dict[tuple[int, int], ca.SX]) -> None:
    """Add the stage's Hessian entries (module docstring) into `entries` (upper triangle,
    keyed (row, column) with row <= column)."""
    y_sym = ca.SX.sym("y", N_SYM)
    phi = stage.phi(y_sym)
    inner = ca.vertcat(y_sym, stage.outer)
    hess_phi, grad_phi = ca.hessian(phi, inner)
    y_of_x = sum((terms for _, _, terms in stage.members), ca.SX.zeros(N_SYM))
    hess_phi, grad_phi = ca.substitute([hess_phi, grad_phi], [y_sym], [y_of_x])
    mu = grad_phi[:N_SYM]
    h_yy = hess_phi[:N_SYM, :N_SYM]
    h_yw = hess_phi[:N_SYM, N_SYM:]
    h_ww = hess_phi[N_SYM:, N_SYM:]
    jacobians = [ca.jacobian(terms, symbols) for _, symbols, terms in stage.members]
    weighted = [ca.mtimes(h_yy, Y) for Y in jacobians]
    mu_sym = ca.SX.sym("mu", N_SYM)
    for a, (index_a, symbols_a, terms_a) in enumerate(stage.members):
        # mu held fixed: the terms' own curvature, weighted by dPhi/dy.
        curvature = ca.hessian(ca.dot(mu_sym, terms_a), symbols_a)[0]
        curvature = ca.substitute(curvature, mu_sym, mu)
        own = ca.mtimes(jacobians[a].T, weighted[a]) + curvature
        _add_block(entries, index_a, index_a, own, diagonal=True)
        for b in range(a + 1, len(stage.members)):
            index_b = stage.members[b][0]
            _add_block(entries, index_a, index_b, ca.mtimes(jacobians[a].T, weighted[b]), False)
        if stage.outer.numel():
            _add_block(entries, index_a, stage.outer_index, ca.mtimes(jacobians[a].T, h_yw), False)
    if stage.outer.numel():
        _add_block(entries, stage.outer_index, stage.outer_index, h_ww, diagonal=True)


def bottleneck_hessian(x: ca.SX, rest: ca.SX, stages: Sequence[CoupledStage]) -> ca.SX:
    """The upper triangle [n, n] (n = x's length) of the Hessian of rest + sum of the stages'
    phi, w.r.t. x [n] (a symbol vector): `rest` by CasADi's automatic Hessian, the stages by
    `stage_hessian`."""
    n = int(x.numel())
    entries: dict[tuple[int, int], ca.SX] = {}
    hess_rest = ca.triu(ca.hessian(rest, x)[0])
    rows, cols = hess_rest.sparsity().get_triplet()
    for k, (i, j) in enumerate(zip(rows, cols, strict=True)):
        _add(entries, i, j, hess_rest.nz[k])
    for stage in stages:
        stage_hessian(stage, entries)
    keys = sorted(entries)
    values = ca.vertcat(*[entries[k] for k in keys]) if keys else ca.SX(0, 1)
    return ca.SX.triplet([k[0] for k in keys], [k[1] for k in keys], values, n, n)


LiftedSlot = Callable[[ca.SX], tuple[ca.SX, ca.SX | None]]
"""One horizon slot's lifted terms as a function of its J_M [4, 4]: (its objective term, its
lifted equalities [16], None on the last slot) (planning/horizon_problem.lifted_slot, the rest
bound)."""


def horizon_hess_lag(
    X: ca.SX,
    p: ca.SX,
    g: ca.SX,
    lift: ca.SX,
    stages: Sequence[tuple[Sequence[tuple[IntArray, ca.SX, ca.SX]], LiftedSlot]],
    f_scale: ca.SX,
    n_targets: int = 1,
) -> ca.Function:
    """nlpsol's hess_lag (x, p, lam_f, lam_g) -> upper triangle, for the horizon's lifted NLP:
    variables X [n] (the lifted ones `lift` [16 (L - 1) T] last, target-major), parameters p,
    rows g [n_rows] followed by the (L - 1) T lifted equalities [16] (target-major), objective
    sum of the slots' terms / f_scale. Per target and slot (`stages`, T L of them,
    target-major): its UAVs' members (CoupledStage) and its LiftedSlot, whose terms are a
    function of vech(that target's J_M) and its lifted covariance before it. The targets' stages
    share the UAVs' variables: their Hessian entries add up."""
    L = len(stages) // n_targets
    n_rows = int(g.numel())
    n_x = int(X.numel()) - int(lift.numel())
    lam_f = ca.SX.sym("lam_f")
    lam_g = ca.SX.sym("lam_g", n_rows + 16 * (L - 1) * n_targets)
    coupled = []
    for k, (members, slot) in enumerate(stages):
        h = k % L
        base = 16 * (k // L) * (L - 1)  # the target's first lifted block
        last = h == L - 1
        lam_row = (
            ca.SX(0, 1) if last else lam_g[n_rows + base + 16 * h : n_rows + base + 16 * h + 16]
        )

        def phi(y: ca.SX, slot: LiftedSlot = slot, lam_row: ca.SX = lam_row) -> ca.SX:
            term, row = slot(unvech(y))
            value: ca.SX = lam_f * term / f_scale
            return value if row is None else value + ca.dot(lam_row, row)

        outer = lift[base + 16 * (h - 1) : base + 16 * h] if h > 0 else ca.SX(0, 1)
        outer_index = n_x + base + 16 * (h - 1) + np.arange(16) if h > 0 else np.zeros(0, int)
        coupled.append(CoupledStage(members, phi, outer, outer_index))
    hess = bottleneck_hessian(X, ca.dot(lam_g[:n_rows], g), coupled)
    return ca.Function(
        "nlp_hess_l",
        [X, p, lam_f, lam_g],
        [hess],
        ["x", "p", "lam_f", "lam_g"],
        ["triu_hess_gamma_x_x"],
    )
