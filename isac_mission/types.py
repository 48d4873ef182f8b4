"""Domain types shared by the library, the simulator and the service.

Arrays are numpy float64. Shapes are given in brackets: M UAVs, K base stations. Positions are in the
scenario plane (x east, y north) in metres; the target state is [x, y, vx, vy] in m and m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Gaussian:
    """A Gaussian belief over the target state: mean x [4] and covariance P [4, 4]."""

    x: FloatArray
    P: FloatArray


@dataclass(frozen=True)
class Detections:
    """One slot's measurements.

    range_m [M] and radial_velocity_mps [M] hold NaN where a UAV's detection did not arrive;
    uav_xy_m [M, 2] are the positions at which the measurements were taken.
    """

    slot: int
    range_m: FloatArray
    radial_velocity_mps: FloatArray
    uav_xy_m: FloatArray

    @property
    def received(self) -> BoolArray:
        """[M] True where both the range and the radial velocity of UAV m arrived."""
        return np.isfinite(self.range_m) & np.isfinite(self.radial_velocity_mps)


@dataclass(frozen=True)
class SolveReport:
    """How a slot plan was obtained: status is "ok" or "infeasible"; reason says why if not ok,
    or why an ok plan is the SCA's when the polish ran and was not kept; polish: what the polish
    did ("" when it did not run); polish_iterations: IPOPT's iterations; fallback: why the
    method's own answer was not flown, as a short kind that summaries count ("" when it was;
    docs/trace.md, "Fallbacks": "infeasible", "horizon: ...", "timeout", "late", ...)."""

    status: str
    reason: str = ""
    ao_iterations: int = 0
    position_iterations: int = 0
    bandwidth_iterations: int = 0
    solve_s: float = 0.0
    objective_history: tuple[float, ...] = field(default_factory=tuple)
    polish: str = ""
    polish_iterations: int = 0
    fallback: str = ""


@dataclass(frozen=True)
class SlotPlan:
    """The planner's decision for one slot.

    uav_xy_m [M, 2]: waypoints for this slot; bs_of_uav [M]: 0-based BS index per UAV;
    bandwidth_share [M]: eta, sums to 1; pcrb_trace: tr(C) at the predicted state for this plan.
    """

    uav_xy_m: FloatArray
    bs_of_uav: IntArray
    bandwidth_share: FloatArray
    pcrb_trace: float
    report: SolveReport
    uav_velocity_mps: FloatArray | None = None
    """[M, 2] the velocity planned at the slot's end (planner.vehicle_model); None: the paper's
    kinematics (each leg flown at its constant velocity)."""
    horizon: HorizonPlan | None = None
    """The whole planned horizon (method horizon), for the warm start of the next slot."""


@dataclass(frozen=True)
class HorizonDuals:
    """IPOPT's multipliers at a horizon solution, the next slot's dual warm start (docs/model.md,
    "Receding horizon", "Start points").

    lam_x [n_x]: of the variables' bounds; lam_g [n_g]: of the rows, both of the NLP solved (its
    scaled units); f_scale: the objective's divisor they go with; pair_band: that NLP's band;
    order [M]: the fleet's order in it.
    """

    lam_x: FloatArray
    lam_g: FloatArray
    f_scale: float
    pair_band: int
    order: IntArray


@dataclass(frozen=True)
class HorizonPlan:
    """A receding-horizon plan of slots n..n+L-1.

    uav_xy_m [L, M, 2]: waypoints at the ends of the horizon slots; uav_velocity_mps [L, M, 2] or
    None: velocities there (planner.vehicle_model); bandwidth_share [L, M]; pcrb_trace [L]:
    tr(PCRB) predicted along the horizon (the bound's recursion at the predicted states).
    """

    uav_xy_m: FloatArray
    uav_velocity_mps: FloatArray | None
    bandwidth_share: FloatArray
    pcrb_trace: FloatArray
    duals: HorizonDuals | None = None
    """The multipliers of the solve that gave this plan (None: not a kept IPOPT answer)."""
