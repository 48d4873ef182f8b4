"""The operator's requests on `isac/<mission>/control`: check, execute, reply (docs/bus.md).

Each request gets one reply on `isac/<mission>/control/reply` with its id, accepted or refused,
why, and what the ground loop did. A malformed request (wire.read_request) is refused with the
field at fault and nothing is executed; so is a well-formed one that cannot be carried out (a
vehicle already out of the mission, nothing to resume, ...). What each command does:

- `set`: planning parameters (R_th) from the next planned slot on;
- `priority` (one track): the track's weight in the planner's objective, 0 to 10 (0: not
  planned for, still kept clear of), from the next planned slot on; refused with the mission
  state's reason when it cannot be set (no such track);
- `hold` (one vehicle or all): the vehicles are planned around (share 0, no BS; the others keep
  D_s from them) and their bridges switch them to PX4 HOLD, streaming setpoints at the vehicle's
  own position (`fleet` command);
- `resume` (one or all): undoes `hold`: the bridges take the vehicles back into OFFBOARD and
  the ground plans them again once they report OFFBOARD;
- `land` (one or all): planned around for good, the bridges land them;
- `release` (one): a vehicle its bridge reports overridden (an operator's mode change, its own
  failsafe) or held is given back to the service: the bridge takes it into OFFBOARD again.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from isac_mission.bus import ZenohBus
from isac_mission.config import Scenario
from isac_mission.errors import MessageError
from isac_mission.service.ground.exclusion import VehicleWatch
from isac_mission.service.ground.report import GroundReport
from isac_mission.wire import (
    ControlMsg,
    ControlReplyMsg,
    FleetMsg,
    Keys,
    encode,
    read_request,
    rejection_reason,
)

log = logging.getLogger(__name__)


class ControlledMission(Protocol):
    """What a request needs of the loop's mission state (service/ground/mission.py's
    MissionState): the last processed slot, the scenario
    planned with, a way to plan with another from the next slot on, and a track's priority."""

    @property
    def slot(self) -> int: ...

    @property
    def scenario(self) -> Scenario: ...

    def set_scenario(self, s: Scenario) -> None: ...

    @property
    def next_planned_slot(self) -> int:
        """The first slot whose plan a change made now goes into."""
        ...

    def set_priority(self, track_id: int, weight: float) -> None:
        """Plan with track `track_id` weighted `weight` (0 to 10) from the next planned slot
        on; ValueError saying what is wrong (no such track, a weight out of range)."""
        ...


HOLD_REASON = "control: hold"
LAND_REASON = "control: land"


@dataclass(frozen=True)
class Outcome:
    """What a request came to: accepted or not, why, what was done, to which vehicles."""

    accepted: bool
    reason: str
    effect: str
    vehicles: tuple[int, ...] = ()
    fleet_command: str | None = None
    """The `fleet` command to send the bridges of `vehicles` (None: none)."""


def _refused(reason: str) -> Outcome:
    return Outcome(False, reason, "nothing was executed")


def _names(vehicles: tuple[int, ...]) -> str:
    return ("vehicle " if len(vehicles) == 1 else "vehicles ") + ", ".join(map(str, vehicles))


class ControlDesk:
    """Answers the operator's requests for one ground loop.

    Args:
        keys: The mission's keys; bus: the ground's session (replies, fleet commands).
        vehicles: The loop's VehicleWatch (held vehicles, overrides from telemetry).
        report: Counters (`operator commands`, `operator commands refused`, `rejected ...`).
        state: The loop's mission state (`set` changes its scenario; slot for the envelope).
        t_s: The loop's simulation time, s.
    """

    def __init__(
        self,
        keys: Keys,
        bus: ZenohBus,
        vehicles: VehicleWatch,
        report: GroundReport,
        state: Callable[[], ControlledMission],
        t_s: Callable[[], float],
    ) -> None:
        self.keys = keys
        self.bus = bus
        self.vehicles = vehicles
        self.report = report
        self.n_uavs = vehicles.n_uavs
        self.plan_rate_factor = vehicles.settings.plan_rate_factor
        self.state = state
        self.t_s = t_s
        self.landed: set[int] = set()
        """Vehicles an operator's `land` took out of the mission."""

    def on_request(self, payload: bytes) -> ControlReplyMsg:
        """Read, execute and answer one request; the reply is published and returned."""
        read = read_request(payload, n_uavs=self.n_uavs)
        if read.msg is None:
            err = read.error or MessageError("control: unreadable")
            self.report.count_rejected(rejection_reason(err), err)
            outcome = _refused(str(err))
        else:
            try:
                outcome = self._execute(read.msg)
            except Exception as err:  # a bug: refuse and say so, the loop goes on
                self.report.count_internal_error(err)
                outcome = _refused(f"internal error: {type(err).__name__}: {err}")
        if outcome.accepted:
            self.report.counters["operator commands"] += 1
            log.warning("operator %s (%s): %s", read.command, read.request_id, outcome.effect)
        else:
            self.report.counters["operator commands refused"] += 1
            log.warning("operator request %r refused: %s", read.request_id, outcome.reason)
        slot, t_s = max(self.state().slot, -1), self.t_s()
        if outcome.fleet_command is not None and read.request_id is not None:
            fleet = FleetMsg(
                slot=slot,
                t_s=t_s,
                request_id=read.request_id,
                command=outcome.fleet_command,
                uavs=outcome.vehicles,
            )
            self.bus.publish(self.keys.fleet, encode(fleet))
        reply = ControlReplyMsg(
            slot=slot,
            t_s=t_s,
            request_id=read.request_id,
            command=read.command,
            accepted=outcome.accepted,
            reason=outcome.reason,
            effect=outcome.effect,
            vehicles=outcome.vehicles,
        )
        self.bus.publish(self.keys.control_reply, encode(reply))
        return reply

    # ------------------------------------------------------------------ commands

    def _execute(self, msg: ControlMsg) -> Outcome:
        if msg.command == "set":
            assert msg.params is not None  # set carries them (wire.control_models)
            return Outcome(True, "parameters valid", self._set(msg.params))
        if msg.command == "priority":
            assert msg.track is not None and msg.params is not None  # (wire.control_models)
            return self._priority(msg.track, msg.params["weight"])
        every = tuple(range(self.n_uavs)) if msg.uav is None else (msg.uav,)
        if msg.command in ("hold", "land"):
            return self._take(msg, every)
        if msg.command == "resume":
            return self._resume(msg, every)
        assert msg.uav is not None  # release names one vehicle (wire.control_models)
        return self._release(msg.uav)

    def _set(self, params: dict[str, float]) -> str:
        """`set`: R_th (Mbit/s, with the live margin plan_rate_factor) from the next planned
        slot on."""
        state = self.state()
        r_th_mbps = params["rate_min_mbps"]
        state.set_scenario(
            state.scenario.with_changes(r_th=r_th_mbps * 1e6 * self.plan_rate_factor)
        )
        return f"R_th = {r_th_mbps:g} Mbit/s from slot {state.slot + 2} on"

    def _priority(self, track_id: int, weight: float) -> Outcome:
        """`priority`: the track's weight in the planner's objective from the next planned slot
        on; refused with the mission state's reason (ValueError: no such track, ...)."""
        state = self.state()
        try:
            state.set_priority(track_id, weight)
        except ValueError as err:
            return _refused(str(err))
        effect = f"track {track_id}: priority {weight:g} from slot {state.next_planned_slot} on"
        if weight == 0.0:
            effect += " (not planned for, still kept clear of)"
        return Outcome(True, "priority accepted", effect)

    def _out_of_mission(self, m: int) -> str:
        """Why vehicle m is out of the mission for good ("" when it is not)."""
        if m in self.landed:
            return f"vehicle {m} was landed by an operator: out of the mission"
        if self.vehicles.airborne(m) is False and m in self.vehicles.excluded:
            return f"vehicle {m} is on the ground ({self.vehicles.excluded[m]}): out of the mission"
        return ""

    def _take(self, msg: ControlMsg, every: tuple[int, ...]) -> Outcome:
        """hold or land: plan around the vehicles, tell their bridges."""
        holding = msg.command == "hold"
        targets = []
        for m in every:
            out = self._out_of_mission(m)
            override = self.vehicles.override(m)
            if not out and override and not override.startswith("control:"):
                out = f"vehicle {m} is not the service's ({override}): use the ground station"
            if holding and self.vehicles.held.get(m) == HOLD_REASON:
                out = f"vehicle {m} is held already"
            if out and msg.uav is not None:
                return _refused(out)
            if not out:
                targets.append(m)
        if not targets:
            return _refused(f"no vehicle to {msg.command}: every vehicle is held or out")
        vehicles = tuple(targets)
        for m in vehicles:
            self.vehicles.held[m] = HOLD_REASON if holding else LAND_REASON
            if not holding:
                self.landed.add(m)
        what = "held (PX4 HOLD)" if holding else "landing; out of the mission"
        effect = (
            f"{_names(vehicles)} {what}: planned around from the next slot (share 0, no BS); "
            f"'{msg.command}' sent to their bridges on {self.keys.fleet}"
        )
        return Outcome(True, f"{msg.command} accepted", effect, vehicles, msg.command)

    def _resume(self, msg: ControlMsg, every: tuple[int, ...]) -> Outcome:
        """resume: undo an operator's hold."""
        out = "" if msg.uav is None else self._out_of_mission(msg.uav)
        if out:
            return _refused(out)
        targets = tuple(m for m in every if self.vehicles.held.get(m) == HOLD_REASON)
        if not targets:
            if msg.uav is not None and self.vehicles.override(msg.uav):
                why = self.vehicles.override(msg.uav)
                return _refused(f"vehicle {msg.uav} is not held but overridden ({why}): release it")
            who = "no vehicle is" if msg.uav is None else f"vehicle {msg.uav} is not"
            return _refused(f"{who} held by a control 'hold'")
        for m in targets:
            del self.vehicles.held[m]
        effect = (
            f"{_names(targets)} resumed: their bridges take them back into OFFBOARD; planned "
            "again once they report OFFBOARD"
        )
        return Outcome(True, "resume accepted", effect, targets, "resume")

    def _release(self, m: int) -> Outcome:
        """release: give a vehicle an operator or its own failsafe took back to the service."""
        out = self._out_of_mission(m)
        if out:
            return _refused(out)
        override = self.vehicles.override(m)
        held = self.vehicles.held.get(m)
        if not override and held is None:
            return _refused(f"vehicle {m} is flown by the service: nothing to release")
        self.vehicles.held.pop(m, None)
        was = override or held
        effect = (
            f"vehicle {m} released (was: {was}): its bridge takes it back into OFFBOARD; "
            "planned again once it reports OFFBOARD"
        )
        return Outcome(True, "release accepted", effect, (m,), "release")
