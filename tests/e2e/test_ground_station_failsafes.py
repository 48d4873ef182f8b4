"""RTL and force disarm from a real MAVProxy mid-mission, and the low-battery failsafe: the
service never takes the vehicle back, plans around it, and the mission goes on with the others.

Real parts: the embedded world's PX4-like vehicles (AUTO.RTL, force disarm with param2 = 21196,
the battery model and PX4's low-battery failsafe: sim/autopilot), the bridges and the ground loop
of `run`, a real MAVProxy on the fleet's ground-station port, a Zenoh client observer.
"""

from __future__ import annotations

import asyncio
import socket
from pathlib import Path

from isac_mission.bus import tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import Scenario
from isac_mission.mavwire.modes import FlightMode
from isac_mission.service.assembly import LiveOptions
from isac_mission.service.mission_result import LiveResult
from isac_mission.wire import Keys, PlanMsg
from tests.support.mavproxy import MavlinkListener, MavProxy
from tests.support.mission_watch import MissionWatch, open_client
from tests.support.ports import free_port_block, sitl_ports

WAIT_S = 300.0
"""Generous wall-clock bound of every wait (a loaded 2-core machine)."""


def _out(plan: PlanMsg, m: int) -> bool:
    return int(plan.plan.bs_of_uav[m]) == -1 and float(plan.plan.bandwidth_share[m]) == 0.0


def _in(plan: PlanMsg, m: int) -> bool:
    return int(plan.plan.bs_of_uav[m]) >= 0 and float(plan.plan.bandwidth_share[m]) > 0.0


def _options(s: Scenario, tmp_path: Path, endpoint: str, seed: int) -> tuple[LiveOptions, str]:
    ports = sitl_ports(s.M)
    opts = LiveOptions(
        speed=5.0,
        lockstep=True,
        seed=seed,
        out_dir=tmp_path,
        zenoh_endpoint=endpoint,
        **ports.world_kwargs(),
    )
    return opts, f"udpin:127.0.0.1:{ports.gcs}"


async def _mission(
    s: Scenario,
    tmp_path: Path,
    seed: int,
    operate: object,
) -> LiveResult:
    """Run `operate(watch, listener, mavproxy)` (a coroutine function) on a live mission."""
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    opts, master = _options(s, tmp_path, endpoint, seed)
    stop = asyncio.Event()
    with MavlinkListener() as seen, MavProxy(master, [seen.out]) as mp:
        mission = asyncio.create_task(run_embedded(s, opts, stop))
        try:
            with await open_client(endpoint, WAIT_S) as bus:
                async with MissionWatch(bus, Keys(s.mission_id)) as w:
                    await w.until(lambda: len(w.plans) >= 5, WAIT_S, "five plans")
                    await operate(w, seen, mp)  # type: ignore[operator]
        finally:
            stop.set()
            result = await asyncio.wait_for(mission, timeout=WAIT_S)
    return result


async def _override(w: MissionWatch, m: int, prefix: str) -> str:
    await w.until(
        lambda: (t := w.last_telemetry(m)) is not None and t.override.startswith(prefix),
        WAIT_S,
        f"vehicle {m} reported '{prefix}...'",
    )
    tel = w.last_telemetry(m)
    assert tel is not None
    return tel.override


async def _others_fly_on(w: MissionWatch, out: set[int], n_uavs: int, plans: int = 4) -> None:
    """Wait for the first plan that leaves `out` out; it and the next plans leave them out and
    plan every other vehicle."""

    def first_without() -> int | None:
        return next((i for i, (_, p) in enumerate(w.plans) if all(_out(p, m) for m in out)), None)

    await w.until(lambda: first_without() is not None, WAIT_S, f"a plan without {sorted(out)}")
    i = first_without()
    assert i is not None
    n = max(i, len(w.plans) - 1)
    await w.until(lambda: len(w.plans) >= n + plans, WAIT_S, f"{plans} more plans")
    for _, p in w.plans[n:]:
        for m in range(n_uavs):
            assert (_out if m in out else _in)(p, m), (p.slot, m)


async def test_rtl_and_force_disarm_from_mavproxy_take_vehicles_out_for_good(
    paper: Scenario, tmp_path: Path
) -> None:
    s = paper.with_changes(N=150, H=20.0)  # a short climb and landing

    async def operate(w: MissionWatch, seen: MavlinkListener, mp: MavProxy) -> None:
        await asyncio.to_thread(mp.wait_for, r"Detected vehicle 3:1", WAIT_S)
        # RTL on vehicle 1 (system id 2): flies home and lands; the service leaves it alone.
        mark = mp.set_px4_mode(2, FlightMode.RTL)
        await asyncio.to_thread(mp.wait_for, r"DO_SET_MODE: ACCEPTED", 60.0, mark)
        assert await _override(w, 1, "operator: RTL") == "operator: RTL"
        await _others_fly_on(w, {1}, s.M)
        # Force disarm in the air on vehicle 2 (system id 3): it falls, out of the mission.
        mark = mp.mark()
        mp.send("vehicle 3")
        mp.send("long COMPONENT_ARM_DISARM 0 21196")
        await asyncio.to_thread(mp.wait_for, r"COMPONENT_ARM_DISARM: ACCEPTED", 60.0, mark)
        assert await _override(w, 2, "killed") == "killed: disarmed in the air"
        await _others_fly_on(w, {1, 2}, s.M)
        # Vehicle 1 finishes its RTL on its own (never switched back), then it is out too.
        await _override(w, 1, "landed")
        rtl = [t for t in w.telemetry[1] if t.override == "operator: RTL"]
        assert rtl and {t.mode for t in rtl} <= {"rtl", "land"}, {t.mode for t in rtl}
        assert seen.mode(2) in ("rtl", "land")
        assert any(h.vehicles.get(2) == "excluded: killed: disarmed in the air" for h in w.health)
        await _others_fly_on(w, {1, 2}, s.M)
        # Neither can be released back: out of the mission.
        for m in (1, 2):
            reply = await w.request(f"release-{m}", "release", m)
            assert not reply.accepted and "out of the mission" in reply.reason, reply

    result = await _mission(s, tmp_path, 6, operate)
    assert result.report.counters["vehicle exclusions"] >= 2


async def test_the_low_battery_failsafe_returns_a_vehicle_and_the_mission_goes_on(
    paper: Scenario, tmp_path: Path
) -> None:
    # Vehicle 1's small pack (8 Wh, allowed to run out) reaches the critical level (20 % here)
    # some 40 s into the mission: "Critical battery level, executing RTL in 5 seconds", then
    # COM_LOW_BAT_ACT's RTL; at the emergency level (2 %, some 17 s later) it lands.
    battery = paper.battery.model_copy(
        update={
            "capacity_wh_by_uav": {1: 8.0},
            "min_remaining": 0.0,
            "low_thr": 0.3,
            "critical_thr": 0.2,
            "emergency_thr": 0.02,
        }
    )
    s = paper.with_changes(N=150, H=20.0, battery=battery)

    async def operate(w: MissionWatch, seen: MavlinkListener, mp: MavProxy) -> None:
        await w.until(
            lambda: any(t.override == "RTL: low battery" for t in w.telemetry.get(1, [])),
            WAIT_S,
            "vehicle 1 reported 'RTL: low battery'",
        )
        taken = [t for t in w.telemetry[1] if t.override]
        assert taken[0].override == "RTL: low battery" and taken[0].mode == "rtl", taken[0]
        await w.until(
            lambda: any(h.vehicles.get(1, "").endswith("low battery") for h in w.health),
            WAIT_S,
            "health saying why",
        )
        await _others_fly_on(w, {1}, s.M)
        await _override(w, 1, "landed")  # landed and disarmed on its own
        # Never taken back: from the failsafe on, only its own modes (RTL, then LAND). "From"
        # in arrival order (one bridge's messages arrive in order): two messages can carry the
        # same position stamp t_s when no new position came between them, the one before the
        # failsafe in OFFBOARD (CI saw that).
        first = next(i for i, t in enumerate(w.telemetry[1]) if t is taken[0])
        modes = {t.mode for t in w.telemetry[1][first:]}
        assert modes <= {"rtl", "land"}, modes
        assert seen.mode(2) in ("rtl", "land")
        await _others_fly_on(w, {1}, s.M)

    result = await _mission(s, tmp_path, 7, operate)
    assert result.report.counters["vehicle exclusions"] >= 1
