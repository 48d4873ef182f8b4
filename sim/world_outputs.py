"""What the world publishes on the bus besides the detections: the scene's truth once per slot
(`truth`, or `truth_set` on a multi-target mission: `sim.scenes`) and `clock`.

`clock` goes out at every slot boundary, every 1 / clock_rate_hz simulation seconds on the grid
k / clock_rate_hz (slot -1 before the mission starts), and repeated while the world holds in
lockstep. The unpaced world (speed = inf) announces `UNPACED_SPEED` as its speed. Message
fields: docs/bus.md.
"""

from __future__ import annotations

import math

from isac_mission.bus import ZenohBus
from isac_mission.timebase import UNPACED_SPEED, SlotTimeline, reached
from isac_mission.wire import ClockMsg, Keys, TruthMsg, TruthSetMsg, encode


class WorldOutputs:
    """The world's `truth` and `clock` publishers on one bus session; tracks when the next
    periodic clock message is due."""

    def __init__(
        self, bus: ZenohBus, keys: Keys, slot_s: float, speed: float, clock_rate_hz: float
    ) -> None:
        self._bus = bus
        self._keys = keys
        self._slot_s = slot_s
        self._speed = speed if math.isfinite(speed) else UNPACED_SPEED
        self._clock_grid = SlotTimeline(0.0, 1.0 / clock_rate_hz)
        self.next_clock_s = 0.0
        """Simulation time (s) at which the next periodic clock message is due."""

    def publish_truth(self, msg: TruthMsg | TruthSetMsg) -> None:
        """The scene's truth of a slot (`sim.scenes.SceneSlot.truth`) on the truth key."""
        self._bus.publish(self._keys.truth, encode(msg))

    def clock_due(self, now_s: float) -> bool:
        """True once the simulation time `now_s` (s) has reached the next periodic clock time."""
        return reached(now_s, self.next_clock_s)

    def publish_clock(self, slot: int, now_s: float, mission_t0_s: float | None) -> None:
        """The clock at `now_s` (s) in `slot` (-1 before the mission start `mission_t0_s`); the
        next periodic message is then due at the next grid point after now_s."""
        msg = ClockMsg(
            slot=slot,
            t_s=now_s,
            slot_s=self._slot_s,
            speed=self._speed,
            mission_t0_s=mission_t0_s,
        )
        self._bus.publish(self._keys.clock, encode(msg))
        grid = self._clock_grid
        self.next_clock_s = grid.slot_end_s(grid.slot_of(now_s) + 1)
