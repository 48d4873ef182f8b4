"""The motion model interface (model/motion.py): its closed-form path against the matrices it
gives, its symbolic prediction, and that nothing outside model/ writes the motion equations."""

from __future__ import annotations

import ast
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from isac_mission.model.motion import ConstantVelocity
from isac_mission.tracking.beliefs import TargetBelief

ROOT = Path(__file__).resolve().parents[2]


def test_the_path_is_the_transition_and_noise_of_each_step() -> None:
    rng = np.random.default_rng(3)
    motion = ConstantVelocity(0.7)
    A = rng.standard_normal((4, 4))
    P = A @ A.T + np.eye(4)
    x = rng.standard_normal(4) * 50
    times = np.array([0.0, 0.25, 1.0, 2.5, 7.0])
    path = motion.predicted_path(x, P, times)
    for i, t in enumerate(times):
        F, W = motion.transition(float(t)), motion.process_noise(float(t))
        np.testing.assert_allclose(path.means[i], F @ x, rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(path.covariances[i], F @ P @ F.T + W, rtol=1e-12, atol=1e-12)
    assert path.covariances.shape == (5, 4, 4) and np.all(path.times_s == times)


def test_two_steps_of_the_transition_make_one_and_the_noise_adds_up() -> None:
    motion = ConstantVelocity(0.5)
    F1, F2, F3 = (motion.transition(t) for t in (1.0, 2.0, 3.0))
    np.testing.assert_allclose(F1 @ F2, F3, atol=1e-15)
    W1, W2, W3 = (motion.process_noise(t) for t in (1.0, 2.0, 3.0))
    np.testing.assert_allclose(F2 @ W1 @ F2.T + W2, W3, rtol=1e-13)


def test_the_predicted_position_is_the_same_for_numbers_and_symbols() -> None:
    motion = ConstantVelocity(0.5)
    x = np.array([100.0, -20.0, 3.0, 4.5])
    numeric = motion.position_after(x, 1.75)
    sym = ca.SX.sym("x", 4)
    symbolic = ca.Function("p", [sym], [motion.position_after(sym, 1.75)])(x)
    np.testing.assert_array_equal(numeric, np.asarray(symbolic).ravel())
    np.testing.assert_allclose(numeric, (motion.transition(1.75) @ x)[:2], rtol=1e-15)


def test_a_belief_predicts_through_its_motion_model() -> None:
    motion = ConstantVelocity(0.5)
    x = np.array([10.0, 20.0, -1.0, 2.0])
    belief = TargetBelief(x, np.eye(4), motion)
    np.testing.assert_array_equal(belief.position_at(-1.0), x[:2] - x[2:])
    np.testing.assert_allclose(belief.covariance(), np.eye(4))
    np.testing.assert_allclose(
        belief.path(np.array([2.0])).covariances[0], motion.process_noise(2.0), rtol=1e-14
    )


@pytest.mark.parametrize("package", ["isac_mission", "sim"])
def test_only_the_model_writes_the_motion_equations(package: str) -> None:
    """Outside model/, nothing builds a transition or a process noise itself: every predictor
    of the target takes a motion model."""
    offenders = []
    for path in sorted((ROOT / package).rglob("*.py")):
        if "model" in path.relative_to(ROOT).parts[:2]:
            continue
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module == "isac_mission.model.kinematics":
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert offenders == []
