"""An independent re-checker of a run trace: the paper's constraints (`constraints.py`) and the
PCRB recursion (`pcrb.py`); `common.py` reads the trace.

Written from the paper (eq. 1-14) and docs/model.md with numpy only. It deliberately does not import
isac_mission.model, isac_mission.tracking or isac_mission.planning: its point is to catch the
library's own mistakes, so every formula here is re-derived and coded independently (in a
different style: per-UAV loops, a square-root information update instead of the library's
scaled inverse). It reads the trace through `isac_mission.records.read_trace` only when
given a path; otherwise any object with `.config` (dict) and `.slots` (records with the trace's
field names, see docs/trace.md) will do.

Units: SI throughout (m, s, W, Hz, bit/s, linear ratios); positions [M, 2] in the scenario plane;
target state [x, y, vx, vy] in m and m/s.
"""
