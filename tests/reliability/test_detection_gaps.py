"""Slots without detections over real Zenoh to a real GroundLoop (issue 7, item 2; split from
test_detection_faults.py): a gap of slots is predicted through with a growing covariance, and a
slot whose detections were all lost under a held (lockstep) clock goes on by the wall wait. The
test plays the world (tests/support/ground_rig.py); nothing sleeps to synchronise.
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from isac_mission.service.ground.report import GroundReport
from tests.support.ground_rig import (
    N_SLOTS,
    SEED,
    WAIT_S,
    GroundRig,
    Reference,
    assert_same_belief,
    detections,
)

pytestmark = pytest.mark.timeout(120)


async def test_a_gap_of_slots_is_predicted_through_with_growing_covariance(
    ground_rig: tuple[GroundRig, asyncio.Task[GroundReport]],
) -> None:
    """Slots 2-6 without a single detection: each is a prediction-only update (x = F x,
    P = F P F^T + W, J = (F J^-1 F^T + W)^-1), the covariance grows every slot, and the first
    detections after the gap are used normally."""
    rig, run = ground_rig
    s = rig.s
    rng = np.random.default_rng(SEED + 1)
    ref = Reference.start(s)
    F, W = ref.F, ref.W
    plan = await rig.start_mission()
    det = detections(s, 1, plan.plan.bandwidth_share, rng)
    for d in det:
        rig.publish_detection(d)
    assert_same_belief(await rig.track(1), ref.step(1, det), "slot 1")
    for n in range(2, 7):
        await rig.plan(n)
        rig.publish_clock(n * s.dt + rig.loop.settings.detection_wait_s + 0.1 * s.dt)
        track = await rig.track(n)
        prev = rig.tracks[n - 1]
        assert_same_belief(track, ref.step(n, []), f"slot {n}")
        np.testing.assert_allclose(track.P, F @ prev.P @ F.T + W, rtol=1e-9)
        assert np.trace(track.P[:2, :2]) > np.trace(prev.P[:2, :2])
        J_pred = np.linalg.inv(F @ np.linalg.inv(prev.J) @ F.T + W)
        np.testing.assert_allclose(track.J, J_pred, rtol=1e-6)
        assert track.pcrb_trace > prev.pcrb_trace
    for n in (7, 8):
        plan = await rig.plan(n)
        det = detections(s, n, plan.plan.bandwidth_share, rng)
        for d in det:
            rig.publish_detection(d)
        assert_same_belief(await rig.track(n), ref.step(n, det), f"slot {n}")
    assert np.trace(rig.tracks[7].P) < np.trace(rig.tracks[6].P)  # measurements shrink it again
    report = await asyncio.wait_for(run, WAIT_S)
    assert report.counters["slots"] == N_SLOTS
    assert report.counters["slots with missing detections"] == 5
    assert report.counters["detections missing"] == 5 * s.M


async def test_a_slot_without_detections_under_a_held_clock_goes_on_by_the_wall_wait(
    ground_rig: tuple[GroundRig, asyncio.Task[GroundReport]],
) -> None:
    """The world holds its clock exactly at slot 2's end (lockstep, waiting for plan 3) and every
    detection of slot 2 is lost: the ground processes slot 2 without them once
    detection_wall_wait_s of wall time has passed since the clock reached the boundary (it used
    to wait for a first detection that never came, i.e. for the world's lockstep timeout)."""
    rig, _run = ground_rig
    s = rig.s
    rng = np.random.default_rng(SEED + 2)
    plan = await rig.start_mission()
    for d in detections(s, 1, plan.plan.bandwidth_share, rng):
        rig.publish_detection(d)
    await rig.plan(2)
    rig.publish_clock(2 * s.dt)  # held here: never past the simulation-time deadline
    t0 = asyncio.get_running_loop().time()
    track = await rig.track(2)
    waited = asyncio.get_running_loop().time() - t0
    assert waited >= rig.loop.settings.detection_wall_wait_s * 0.9
    assert rig.loop.report.counters["detections missing"] == s.M
    assert np.trace(track.P) > np.trace(rig.tracks[1].P)  # a prediction-only update
    await rig.plan(3)
