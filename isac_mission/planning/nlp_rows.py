"""Constraint rows shared by the CasADi NLPs (planning/polish.py, planning/horizon_nlp.py)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from isac_mission.config import Scenario
from isac_mission.types import FloatArray


class NlpRows:
    """The constraint rows g of an NLP with their bounds lbg <= g <= ubg."""

    def __init__(self) -> None:
        self.rows: list[ca.SX] = []
        self.lower: list[float] = []
        self.upper: list[float] = []

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
    with share eta, as if e = link_margin_m (m) farther from the BS."""
    d2 = ca.sumsqr(q - serving)
    dist2 = d2 if link_margin_m == 0 else (ca.sqrt(d2 + 1e-12) + link_margin_m) ** 2
    rate: ca.SX = eta * s.B * ca.log1p(s.rho0 / (dist2 + s.dH**2)) / (np.log(2.0) * s.r_th)
    return rate - 1.0
