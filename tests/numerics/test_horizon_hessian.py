"""The Lagrangian's Hessian through the information (planning/horizon_hessian.py): equal to
CasADi's automatic Hessian of the same Lagrangian, and to central finite differences of its
gradient, on a toy and on the horizon's NLPs."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
import pytest

from isac_mission.config import Scenario, load_scenario
from isac_mission.config.live_settings import LIVE_SETTINGS
from isac_mission.planning.horizon_hessian import CoupledStage, bottleneck_hessian, unvech, vech
from isac_mission.planning.horizon_nlp import HorizonNLP, HorizonSlotData
from isac_mission.planning.nlp_model import NlpSolver, plain_ipopt


def _dense(f: ca.Function, args: list[np.ndarray]) -> np.ndarray:
    return np.asarray(ca.DM(f.call(args)[0]).full())


def test_vech_and_unvech_are_inverse_on_symmetric_matrices() -> None:
    a = np.random.default_rng(1).normal(size=(4, 4))
    sym = a + a.T
    y = np.asarray(ca.DM(vech(ca.SX(sym))).full()).ravel()
    assert len(y) == 10
    np.testing.assert_array_equal(np.asarray(ca.DM(unvech(ca.SX(y))).full()), sym)


def test_a_toy_stage_matches_the_automatic_hessian_and_finite_differences() -> None:
    """Three members of two variables each, their 4 x 4 terms coupled by tr((J0 + sum T)^-1)
    with an outer variable w scaling J0, plus a separable rest."""
    x = ca.SX.sym("x", 7)
    rng = np.random.default_rng(3)
    basis = [rng.normal(size=(4, 4)) for _ in range(3)]
    members = []
    for m in range(3):
        a, b = x[2 * m], x[2 * m + 1]
        g = ca.vertcat(ca.cos(a), ca.sin(a), b, a * b)
        terms = g @ g.T + (1 + b**2) * ca.DM(basis[m] @ basis[m].T)
        members.append((np.array([2 * m, 2 * m + 1]), ca.vertcat(a, b), vech(terms)))
    w = x[6]
    J0 = ca.DM(np.eye(4))

    def phi(y: ca.SX) -> ca.SX:
        return ca.trace(ca.inv((1 + w**2) * J0 + unvech(y)))

    rest = ca.sum1(x**3) + x[0] * x[5] ** 2
    stage = CoupledStage(members, phi, w, np.array([6]))
    mine = ca.Function("mine", [x], [bottleneck_hessian(x, rest, [stage])])
    total = rest + phi(sum((t for _, _, t in members), ca.SX.zeros(10)))
    automatic = ca.Function("auto", [x], [ca.triu(ca.hessian(total, x)[0])])
    gradient = ca.Function("grad", [x], [ca.gradient(total, x)])
    for _ in range(3):
        point = rng.normal(size=7)
        got = _dense(mine, [point])
        np.testing.assert_allclose(got, _dense(automatic, [point]), rtol=1e-11, atol=1e-11)
        step = 1e-6
        fd = np.column_stack(
            [
                (
                    np.asarray(gradient(point + step * e)).ravel()
                    - np.asarray(gradient(point - step * e)).ravel()
                )
                / (2 * step)
                for e in np.eye(7)
            ]
        )
        np.testing.assert_allclose(got, np.triu(fd), rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def _captured(s: Scenario, band: int | None = None) -> tuple[HorizonNLP, dict[str, Any]]:
    """The horizon NLP of s and what it handed its IPOPT factory (nlp, options)."""
    got: dict[str, Any] = {}

    def factory(
        name: str, nlp: dict[str, Any], options: dict[str, Any], like: NlpSolver | None = None
    ) -> NlpSolver:
        got.setdefault("nlp", nlp)
        got.setdefault("options", options)
        return plain_ipopt(name, nlp, options, like)

    return HorizonNLP(s, 0, None, factory, pair_band=band), got


def _slot_data(s: Scenario, L: int) -> HorizonSlotData:
    """The mission's first slot: the UAVs at their starts, the target at x0 with prior P0."""
    nearest = np.argmin(np.linalg.norm(s.uav_start_xy[:, None] - s.bs_xy[None], axis=-1), axis=1)
    return HorizonSlotData(
        rate_min_bps=s.r_th,
        prev_xy=s.uav_start_xy,
        prev_velocity=np.zeros((s.M, 2)),
        serving_xy=s.bs_xy[nearest],
        control_xy=s.bs_xy[nearest],
        keep_out_xy=np.zeros((0, 2)),
        x_pred=s.x0,
        J_pred=np.linalg.inv(s.P0),
        clearance_m=np.full(L, s.d_safe),
    )


@pytest.mark.parametrize(
    ("fleet", "vehicle_model", "band"), [(3, False, None), (3, True, None), (6, True, 2)]
)
def test_the_horizons_hessian_is_casadis_automatic_hessian_of_its_lagrangian(
    fleet: int, vehicle_model: bool, band: int | None
) -> None:
    """At random plans around the fleet's start (packed with their own scales and lifted
    variables) and random multipliers."""
    s = load_scenario("paper")
    if vehicle_model:
        s = LIVE_SETTINGS.apply(s)
    if fleet != s.M:
        rng = np.random.default_rng(fleet)
        s = s.with_changes(M=fleet, uav_start_xy=rng.uniform(300, 2700, size=(fleet, 2)))
    nlp_object, got = _captured(s, band)
    nlp, hess = got["nlp"], got["options"]["hess_lag"]
    x, p = nlp["x"], nlp["p"]
    lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", nlp["g"].numel())
    lagrangian = lam_f * nlp["f"] + ca.dot(lam_g, nlp["g"])
    automatic = ca.Function("auto", [x, p, lam_f, lam_g], [ca.triu(ca.hessian(lagrangian, x)[0])])
    assert hess.sparsity_out(0).is_triu()
    L = nlp_object.length
    data = _slot_data(s, L)
    rng = np.random.default_rng(11)
    for _ in range(3):
        xy = s.uav_start_xy[None] + np.cumsum(rng.uniform(-15, 15, size=(L, s.M, 2)), axis=0)
        velocity = rng.uniform(-20, 20, size=(L, s.M, 2)) if vehicle_model else None
        eta = rng.dirichlet(np.ones(s.M), size=L)
        x_plan, p_value = nlp_object.pack(xy, velocity, eta, data, f_scale=0.7)
        # The lifted covariances off their equality a little: a point IPOPT's iterates visit.
        lift = nlp_object.lifted(xy, eta, data, p_value) * rng.uniform(0.9, 1.1, L * 16 - 16)
        args = [
            np.concatenate([x_plan, lift]),
            p_value,
            np.array([rng.uniform(0.5, 2.0)]),
            rng.normal(0.0, 1.0, size=lam_g.numel()),
        ]
        want = _dense(automatic, args)
        scale = np.abs(want).max()
        np.testing.assert_allclose(_dense(hess, args), want, rtol=1e-9, atol=1e-12 * scale)
    assert nlp_object.solver.get_function("nlp_hess_l").n_instructions() == hess.n_instructions()
