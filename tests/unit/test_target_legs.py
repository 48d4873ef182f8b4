"""A target flying legs (`motion: legs`; config/targets.py, model/targets.py): straight, turn and
accelerate legs one after another, then straight on, without noise.

- `legs_states` against an independent fine RK4 integration of the legs' accelerations;
- a turn leg on its circle of radius v / omega at constant speed; an accelerate leg's speed
  v0 + a t and distance v0 t + a t^2 / 2 along a constant heading; straight on after the last;
- a leg boundary inside a slot split exactly, the path continuous at every boundary, and
  `legs_state_at` equal to `legs_states` at the slot instants; `target_paths` flies the legs;
- the refusals name the leg and its field (a speed that would reach 0, a missing parameter, legs
  with another motion);
- the shipped config/manoeuvring.yaml stays 300 m inside the area within its manoeuvre bound.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest

from isac_mission.config import load_scenario, parse_scenario
from isac_mission.config.targets import Leg, TargetSpec
from isac_mission.errors import ConfigError
from isac_mission.model.targets import legs_state_at, legs_states, target_paths

X0 = (700.0, 1500.0, 20.0, 0.0)
EVERY_KIND = (
    Leg("straight", 10.0),
    Leg("turn", 8.0, turn_rate_radps=0.2),
    Leg("accelerate", 5.0, accel_mps2=2.0),
    Leg("straight", 8.3),
    Leg("turn", 10.0, turn_rate_radps=-0.133),
    Leg("accelerate", 10.0, accel_mps2=-2.0),
    Leg("turn", 6.0, turn_rate_radps=0.4),
    Leg("accelerate", 10.0, accel_mps2=1.5),
)
"""Every kind of leg, both turn directions, speeding up and slowing down: 67.3 s, boundaries off
the slot instants of dt = 0.7 s."""


def _acceleration(leg: Leg, v: np.ndarray) -> np.ndarray:
    """The acceleration a leg applies at velocity v [2]: none, omega times v turned left by 90
    degrees, or a along v / |v|."""
    if leg.kind == "turn":
        return leg.turn_rate_radps * np.array([-v[1], v[0]])
    if leg.kind == "accelerate":
        return leg.accel_mps2 * v / np.linalg.norm(v)
    return np.zeros(2)


def _rk4(x0: Sequence[float], legs: Sequence[Leg], times: np.ndarray, h: float) -> np.ndarray:
    """[len(times), 4] states at the sorted times by RK4 on dx/dt = (v, a(leg, v)), stepping
    at most h and landing on every leg boundary and every requested time."""
    ends = np.cumsum([leg.duration_s for leg in legs])
    marks = np.unique(np.concatenate([[0.0], ends, times]))
    x, out, t_done = np.asarray(x0, float), {}, 0.0

    def f(leg: Leg, y: np.ndarray) -> np.ndarray:
        return np.concatenate([y[2:], _acceleration(leg, y[2:])])

    for t_next in marks:
        span = t_next - t_done
        if span > 0:
            i = int(np.searchsorted(ends, t_done + 1e-12, side="right"))
            leg = legs[i] if i < len(legs) else Leg("straight", math.inf)
            n = max(1, math.ceil(span / h))
            step = span / n
            for _ in range(n):
                k1 = f(leg, x)
                k2 = f(leg, x + 0.5 * step * k1)
                k3 = f(leg, x + 0.5 * step * k2)
                k4 = f(leg, x + step * k3)
                x = x + step / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        out[float(t_next)] = x.copy()
        t_done = t_next
    return np.array([out[float(t)] for t in times])


def test_legs_states_match_a_fine_integration_of_the_accelerations() -> None:
    # 3 minutes at dt = 0.7 s: the legs, then straight on. RK4 at h = 5 ms has a global error
    # of order (omega h)^4 v T, about 1e-9 m here: 1e-3 m is the bar of the closed forms.
    dt, n = 0.7, 258
    got = legs_states(X0, EVERY_KIND, dt, n)
    want = _rk4(X0, EVERY_KIND, dt * np.arange(n + 1), 5e-3)
    assert got.shape == (n + 1, 4)
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=1e-3, rtol=0)
    np.testing.assert_allclose(got[:, 2:], want[:, 2:], atol=1e-6, rtol=0)


def test_a_turn_leg_flies_a_circle_of_radius_v_over_omega_at_constant_speed() -> None:
    omega, v = 0.2, 20.0
    x = legs_states((0.0, 0.0, v, 0.0), (Leg("turn", 12.0, turn_rate_radps=omega),), 0.25, 48)
    centre = np.array([0.0, v / omega])  # left of the eastward start: counter-clockwise
    np.testing.assert_allclose(np.linalg.norm(x[:, :2] - centre, axis=1), v / omega, rtol=1e-12)
    np.testing.assert_allclose(np.hypot(x[:, 2], x[:, 3]), v, rtol=1e-12)
    heading = np.unwrap(np.arctan2(x[:, 3], x[:, 2]))
    np.testing.assert_allclose(heading, omega * 0.25 * np.arange(49), atol=1e-12)
    # clockwise: the centre on the right
    cw = legs_state_at((0.0, 0.0, v, 0.0), (Leg("turn", 12.0, turn_rate_radps=-omega),), 7.0)
    assert np.linalg.norm(cw[:2] - np.array([0.0, -v / omega])) == pytest.approx(v / omega)


@pytest.mark.parametrize("accel", [1.5, -0.9])
def test_an_accelerate_leg_covers_v0_t_plus_half_a_t_squared(accel: float) -> None:
    x0, v0, heading = (100.0, 200.0, 6.0, 8.0), 10.0, np.array([0.6, 0.8])
    duration, dt = 10.0, 0.5
    x = legs_states(x0, (Leg("accelerate", duration, accel_mps2=accel),), dt, 30)
    t = dt * np.arange(31)
    during = t <= duration
    along = v0 * t[during] + 0.5 * accel * t[during] ** 2
    np.testing.assert_allclose(x[during, :2], np.array(x0[:2]) + along[:, None] * heading)
    speed = v0 + accel * t[during]
    np.testing.assert_allclose(x[during, 2:], speed[:, None] * heading)
    # after the last leg: straight on at the speed it reached
    v_end = v0 + accel * duration
    end = np.array(x0[:2]) + (v0 * duration + 0.5 * accel * duration**2) * heading
    after = t[~during] - duration
    np.testing.assert_allclose(x[~during, :2], end + (v_end * after)[:, None] * heading)
    np.testing.assert_allclose(x[~during, 2:], np.tile(v_end * heading, (len(after), 1)))


def test_a_leg_boundary_inside_a_slot_is_split_exactly() -> None:
    # straight 2.5 s, then a counter-clockwise turn: slot 3 (t = 3 s) is 0.5 s into the turn
    v, omega = 20.0, 0.4
    legs = (Leg("straight", 2.5), Leg("turn", 10.0, turn_rate_radps=omega))
    x = legs_states((0.0, 0.0, v, 0.0), legs, 1.0, 3)
    start = np.array([2.5 * v, 0.0])
    centre = start + np.array([0.0, v / omega])
    angle = omega * 0.5
    want_xy = centre + v / omega * np.array([math.sin(angle), -math.cos(angle)])
    np.testing.assert_allclose(x[3, :2], want_xy, atol=1e-9)
    np.testing.assert_allclose(x[3, 2:], v * np.array([math.cos(angle), math.sin(angle)]))
    np.testing.assert_allclose(x[2], [2.0 * v, 0.0, v, 0.0])  # still straight at slot 2
    # the whole slot straight, or the whole slot turning, is off by metres
    assert np.linalg.norm(x[3, :2] - [3.0 * v, 0.0]) > 0.5
    assert np.linalg.norm(x[3, :2] - legs_state_at((0.0, 0.0, v, 0.0), legs[1:], 3.0)[:2]) > 0.5


def test_the_path_is_continuous_at_every_leg_boundary() -> None:
    eps, v_max, a_max = 1e-6, 30.0, 4.0  # |dp| <= v 2 eps, |dv| <= a 2 eps across a boundary
    for boundary in np.cumsum([leg.duration_s for leg in EVERY_KIND]):
        before = legs_state_at(X0, EVERY_KIND, float(boundary) - eps)
        after = legs_state_at(X0, EVERY_KIND, float(boundary) + eps)
        assert np.linalg.norm(after[:2] - before[:2]) <= 2 * eps * v_max + 1e-9
        assert np.linalg.norm(after[2:] - before[2:]) <= 2 * eps * a_max + 1e-9


def test_legs_state_at_equals_legs_states_at_the_slot_instants() -> None:
    dt, n = 0.7, 120
    path = legs_states(X0, EVERY_KIND, dt, n)
    at = np.array([legs_state_at(X0, EVERY_KIND, k * dt) for k in range(n + 1)])
    np.testing.assert_array_equal(at, path)
    np.testing.assert_array_equal(legs_state_at(X0, EVERY_KIND, 0.0), X0)
    with pytest.raises(ValueError, match="t_s must be >= 0"):
        legs_state_at(X0, EVERY_KIND, -1.0)


def test_target_paths_fly_the_legs_from_the_first_slot_without_noise() -> None:
    spec = TargetSpec(
        "legs", X0, 0.1, "legs", 0.0, (), first_slot=3, last_slot=40, prior_known=True,
        legs=EVERY_KIND,
    )  # fmt: skip
    normals = np.random.default_rng(7).standard_normal((1, 50, 4))
    paths = target_paths((spec,), 1.0, 0.5, 50, normals)
    assert np.isnan(paths.states[:3, 0]).all() and np.isnan(paths.states[41:, 0]).all()
    np.testing.assert_array_equal(paths.states[3:41, 0], legs_states(X0, EVERY_KIND, 1.0, 37))


# --------------------------------------------------------------------------------------------
# The scenario file


def _scenario(target: dict[str, Any]) -> dict[str, Any]:
    return {"targets": [{"initial_state": [700, 1500, 10, 0], **target}]}


def _refusal(target: dict[str, Any]) -> str:
    with pytest.raises(ConfigError) as err:
        parse_scenario(_scenario(target), "x.yaml")
    return str(err.value)


def test_a_scenario_with_legs_resolves_them_in_si_units() -> None:
    s = parse_scenario(
        _scenario(
            {
                "motion": "legs",
                "legs": [
                    {"kind": "straight", "duration_s": 5},
                    {"kind": "turn", "duration_s": 4, "turn_rate_radps": -0.1},
                    {"kind": "accelerate", "duration_s": 2, "accel_mps2": 1.5},
                ],
            }
        ),
        "x.yaml",
    )
    (t,) = s.targets
    assert t.motion == "legs" and s.multi_target
    assert t.legs == (
        Leg("straight", 5.0),
        Leg("turn", 4.0, turn_rate_radps=-0.1),
        Leg("accelerate", 2.0, accel_mps2=1.5),
    )
    legs = s.trace_config()["targets"][0]["legs"]
    assert [leg["kind"] for leg in legs] == ["straight", "turn", "accelerate"]


def test_a_speed_that_would_reach_zero_names_the_leg_and_its_field() -> None:
    # 10 m/s, +1 m/s^2 for 5 s (15 m/s), then -2 m/s^2 for 8 s: 0 at 7.5 s into leg 2
    message = _refusal(
        {
            "motion": "legs",
            "legs": [
                {"kind": "accelerate", "duration_s": 5, "accel_mps2": 1},
                {"kind": "straight", "duration_s": 3},
                {"kind": "accelerate", "duration_s": 8, "accel_mps2": -2},
            ],
        }
    )
    assert message.startswith("x.yaml: targets.0: legs[2].accel_mps2: -2 m/s^2: ")
    assert "to 0 at 7.5 s into the leg" in message and "must stay > 0" in message
    # 7 s of it leaves 1 m/s: flyable
    ok = _scenario(
        {
            "motion": "legs",
            "legs": [
                {"kind": "accelerate", "duration_s": 5, "accel_mps2": 1},
                {"kind": "accelerate", "duration_s": 7, "accel_mps2": -2},
            ],
        }
    )
    assert parse_scenario(ok, "x.yaml").targets[0].legs[1].accel_mps2 == -2


@pytest.mark.parametrize(
    ("legs", "line"),
    [
        (
            [{"kind": "straight", "duration_s": 2}, {"kind": "turn", "duration_s": 4}],
            "x.yaml: targets.0.legs.1: kind turn needs turn_rate_radps",
        ),
        (
            [{"kind": "accelerate", "duration_s": 4}],
            "x.yaml: targets.0.legs.0: kind accelerate needs accel_mps2",
        ),
        ([{"kind": "straight"}], "x.yaml: targets.0.legs.0.duration_s: Field required"),
        (
            [{"kind": "straight", "duration_s": 0}],
            "x.yaml: targets.0.legs.0.duration_s: Input should be greater than 0",
        ),
        (
            [{"kind": "turn", "duration_s": 4, "turn_rate_radps": 0.1, "accel_mps2": 1}],
            "x.yaml: targets.0.legs.0: accel_mps2 is for kind accelerate, not turn",
        ),
        (
            [{"kind": "straight", "duration_s": 4, "turn_rate_radps": 0.1}],
            "x.yaml: targets.0.legs.0: turn_rate_radps is for kind turn, not straight",
        ),
        (
            [{"kind": "climb", "duration_s": 4}],
            "x.yaml: targets.0.legs.0.kind: Input should be 'straight', 'turn' or 'accelerate'",
        ),
    ],
)
def test_a_bad_leg_is_refused_naming_its_index_and_field(
    legs: list[dict[str, Any]], line: str
) -> None:
    assert _refusal({"motion": "legs", "legs": legs}).startswith(line)


def test_legs_go_with_motion_legs_only_and_it_needs_them() -> None:
    legs = [{"kind": "straight", "duration_s": 5}]
    assert _refusal({"legs": legs}).startswith(
        "x.yaml: targets.0: legs is for motion legs, not constant_velocity"
    )
    assert _refusal({"motion": "coordinated_turn", "turn_rate_radps": 0.1, "legs": legs})
    assert _refusal({"motion": "legs"}).startswith("x.yaml: targets.0: motion legs needs legs")
    assert _refusal({"motion": "legs", "legs": []}).startswith("x.yaml: targets.0.legs: ")
    still = {"motion": "legs", "legs": legs, "initial_state": [700, 1500, 0, 0]}
    assert _refusal(still).startswith(
        "x.yaml: targets.0: motion legs flies from the initial velocity: the initial speed "
        "must be > 0"
    )


def test_the_manoeuvring_scenario_stays_300_m_inside_the_area_within_its_bound() -> None:
    s = load_scenario("manoeuvring")
    (t,) = s.targets
    assert t.motion == "legs" and sum(leg.duration_s for leg in t.legs) == s.N * s.dt == 90
    x = np.array([legs_state_at(t.x0, t.legs, tau) for tau in np.arange(0.0, 90.05, 0.1)])
    assert x[:, :2].min() >= 300.0 and (s.area - x[:, :2].max(axis=0)).min() >= 300.0
    speeds = np.hypot(x[:, 2], x[:, 3])
    assert speeds.min() > 0
    starts = np.cumsum([0.0, *(leg.duration_s for leg in t.legs[:-1])])
    for leg, start in zip(t.legs, starts, strict=True):
        v = float(np.hypot(*legs_state_at(t.x0, t.legs, float(start))[2:]))
        push = abs(leg.accel_mps2) if leg.kind == "accelerate" else 0.0
        turn = v * abs(leg.turn_rate_radps) if leg.kind == "turn" else 0.0
        assert max(push, turn) <= s.a_target
