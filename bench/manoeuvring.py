"""The interacting multiple model against the constant-velocity tracker on a manoeuvring intruder
(docs/model.md, "The interacting multiple model"): tracking error per phase, its consistency,
and the bound against the error.

For each seed and method, two closed-loop missions of --config (`fly_outcomes`, the same scene):
the tracker as the file says (`tracker.motion: imm`) and the constant-velocity tracker
(`tracker.motion: cv`, its `tracker.multi.process_noise_intensity` --cv-kappa, tuned on other
seeds). Per slot, the confirmed track nearest the target gives the errors; the phases are the
approach (slots 1..10), the tracking phase (11..N), and the slots flown in each kind of leg
(straight, turn, accelerate; a slot belongs to the leg flown at its middle).

Prints per method and motion: position and velocity RMSE per phase (m, m/s), the mean
tr(PCRB_pos) and MSE / tr(PCRB_pos) per phase, the average NEES over runs (4 degrees of freedom)
and the share of slots inside its 95 % band for the run count (chi^2_{4R} / R), and the IMM's
reduction of each RMSE against CV (%, positive: lower) with its paired 95 % interval over seeds.
One mission at a time.

Run: python bench/manoeuvring.py [--seeds 1..20] [--methods sd,proposed,horizon] [--cv-kappa 2.0]
     [--config config/manoeuvring.yaml]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from seeds import parse_seeds  # noqa: E402

from isac_mission.config import Scenario, load_scenario  # noqa: E402
from isac_mission.experiment.bootstrap import paired_bootstrap, reduction_of_rms  # noqa: E402
from isac_mission.experiment.runs import fly_outcomes  # noqa: E402
from isac_mission.planning.tracks import multi_target_kit  # noqa: E402
from isac_mission.quiet import quiet_highs_banner  # noqa: E402
from isac_mission.types import FloatArray  # noqa: E402

APPROACH_SLOTS = 10


def constant_velocity(s: Scenario, kappa: float) -> Scenario:
    """s with the constant-velocity tracker of intensity kappa on every track."""
    multi = s.multi_tracker.model_copy(update={"process_noise_intensity": kappa})
    return s.with_changes(tracker_motion="cv", imm=None, multi_tracker=multi)


def leg_kinds(s: Scenario) -> np.ndarray:
    """[N] the kind of leg the first target flies at the middle of each slot."""
    legs = s.targets[0].legs
    ends = np.cumsum([leg.duration_s for leg in legs])
    kinds = []
    for n in range(1, s.N + 1):
        i = int(np.searchsorted(ends, (n - 0.5) * s.dt, side="right"))
        kinds.append(legs[i].kind if i < len(legs) else "straight")
    return np.array(kinds)


def run_errors(s: Scenario, method: str, seed: int) -> FloatArray:
    """[N, 4]: per slot the squared position and velocity errors (m^2, m^2/s^2), the NEES and
    tr(PCRB_pos) (m^2) of the confirmed track nearest the target (NaN: none)."""
    out = np.full((s.N, 4), np.nan)
    for n, o in enumerate(fly_outcomes(s, method, seed, multi_target_kit(s))):  # type: ignore[arg-type]
        truth = o.truth[0]
        confirmed = [t for t in o.tracking.tracks if t.confirmed]
        if not np.all(np.isfinite(truth)) or not confirmed:
            continue
        t = min(confirmed, key=lambda t: float(np.hypot(*(t.belief.x[:2] - truth[:2]))))
        e = t.belief.x - truth
        nees = float(e @ np.linalg.solve(t.belief.P, e))
        out[n] = (e[:2] @ e[:2], e[2:] @ e[2:], nees, t.bound.position_trace)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--config", default="config/manoeuvring.yaml")
    ap.add_argument("--seeds", default="1..20")
    ap.add_argument("--methods", default="sd,proposed,horizon")
    ap.add_argument("--cv-kappa", type=float, default=2.0)
    args = ap.parse_args()
    quiet_highs_banner()
    imm = load_scenario(ROOT / args.config)
    cv = constant_velocity(imm, args.cv_kappa)
    seeds = parse_seeds(args.seeds)
    kinds = leg_kinds(imm)
    slots = np.arange(1, imm.N + 1)
    phases = {
        "approach": slots <= APPROACH_SLOTS,
        "tracking": slots > APPROACH_SLOTS,
        "straight": kinds == "straight",
        "turn": kinds == "turn",
        "accelerate": kinds == "accelerate",
    }
    R = len(seeds)
    low, high = chi2.ppf([0.025, 0.975], 4 * R) / R
    start = time.monotonic()
    print(
        f"{args.config}, seeds {seeds[0]}..{seeds[-1]}; CV kappa {args.cv_kappa:g}; NEES band "
        f"[{low:.2f}, {high:.2f}] ({R} runs, 4 dof)\n"
    )
    print(
        "| method | motion | phase | pos RMSE (m) | vel RMSE (m/s) | tr(PCRB_pos) (m^2) | "
        "MSE / tr(PCRB_pos) | IMM's pos RMSE reduction | IMM's vel RMSE reduction |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    nees_rows = []
    for method in [m.strip() for m in args.methods.split(",") if m.strip()]:
        errors = {
            label: np.stack([run_errors(s, method, seed) for seed in seeds])
            for label, s in (("cv", cv), ("imm", imm))
        }  # [R, N, 4] each
        for phase, mask in phases.items():
            per_run = {k: np.nanmean(v[:, mask], axis=1) for k, v in errors.items()}  # [R, 4]
            for label in ("cv", "imm"):
                pr = per_run[label]
                ratio = np.nanmean(pr[:, 0]) / np.nanmean(pr[:, 3])
                cells = ["", ""]
                if label == "imm":
                    cells = [_interval(per_run["cv"][:, q], per_run["imm"][:, q]) for q in (0, 1)]
                print(
                    f"| {method} | {label} | {phase} | {np.sqrt(np.nanmean(pr[:, 0])):.3f} | "
                    f"{np.sqrt(np.nanmean(pr[:, 1])):.3f} | {np.nanmean(pr[:, 3]):.3f} | "
                    f"{ratio:.2f} | {cells[0]} | "
                    f"{cells[1]} |"
                )
        for label, v in errors.items():
            mean_nees = np.nanmean(v[:, :, 2], axis=0)  # [N] over runs
            inside = (mean_nees >= low) & (mean_nees <= high)
            nees_rows.append(
                f"| {method} | {label} | {np.nanmean(mean_nees):.2f} | "
                f"{100 * np.mean(inside):.0f} % | {100 * np.mean(inside[phases['turn']]):.0f} % |"
            )
    print("\n| method | motion | average NEES | slots in the 95 % band | turn slots in it |")
    print("|---|---|---|---|---|")
    print("\n".join(nees_rows))
    print(f"\nwall {time.monotonic() - start:.0f} s")


def _interval(cv_ms: FloatArray, imm_ms: FloatArray) -> str:
    """The IMM's RMSE reduction against CV (%, positive: lower), with its paired 95 % interval
    over seeds."""
    iv = paired_bootstrap(cv_ms, imm_ms, reduction_of_rms)
    return f"{iv.estimate:.1f} % [{iv.low:.1f}, {iv.high:.1f}]"


if __name__ == "__main__":
    main()
