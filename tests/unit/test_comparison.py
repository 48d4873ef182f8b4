"""experiment/comparison.py and its report tables: per-run figures on hand-made runs, reductions
against `proposed` with paired intervals, and the tables printed whole."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from isac_mission.config import parse_scenario
from isac_mission.experiment.bootstrap import paired_bootstrap, reduction_of_rms
from isac_mission.experiment.closed_loop import RunResult
from isac_mission.experiment.comparison import (
    FIGURES,
    pooled,
    reductions_against_baseline,
    run_figures,
)
from isac_mission.experiment.montecarlo import summarize
from isac_mission.experiment.report import (
    against_baseline_table,
    figures_table,
    interval_cell,
    print_table,
    simulate_report,
)


def _run(method: str, seed: int, n: int, pcrb_scale: float, err_m: float) -> RunResult:
    """n slots; tr(C_n) = pcrb_scale * n (slot n, 1-based); position error err_m along x from
    slot 2 on (slot 1: 100 m, which slots 2..N leave out), velocity error err_m / 10 along y."""
    slots = np.arange(1, n + 1, dtype=float)
    pcrb = np.zeros((n, 4, 4))
    pcrb[:, 0, 0] = pcrb_scale * slots  # the whole trace sits in C[0, 0]
    true = np.zeros((n, 4))
    est = np.zeros((n, 4))
    est[:, 0] = err_m
    est[0, 0] = 100.0
    est[:, 3] = err_m / 10
    return RunResult(
        method=method,
        seed=seed,
        est=est,
        true=true,
        pcrb=pcrb,
        solve_s=np.full(n, 0.01),
        status=["ok"] * n,
        uav_xy=np.zeros((n, 1, 2)),
        eta=np.ones((n, 1)),
        assoc=np.zeros((n, 1), dtype=np.int64),
    )


def test_run_figures_follow_their_definitions() -> None:
    n = 20
    f = run_figures([_run("proposed", 1, n, 2.0, 3.0), _run("proposed", 2, n, 4.0, 1.0)])
    slots = np.arange(1, n + 1)
    for r, scale in enumerate((2.0, 4.0)):
        assert f["pcrb"][r] == pytest.approx(scale * slots.mean())
        assert f["pcrb_from11"][r] == pytest.approx(scale * slots[10:].mean())
        assert f["pcrb_late"][r] == pytest.approx(scale * slots[10:].mean())  # N/2 = 10
    assert f["loc_mse"] == pytest.approx([9.0, 1.0])  # slot 1's 100 m left out
    assert f["vel_mse"] == pytest.approx([0.09, 0.01])
    p = pooled(f)
    assert p["loc_rmse"] == pytest.approx(math.sqrt(5.0))
    assert p["pcrb"] == pytest.approx(3.0 * slots.mean())


def test_short_missions_have_no_slots_11_to_n() -> None:
    f = run_figures([_run("sd", 1, 8, 1.0, 1.0)])
    assert math.isnan(f["pcrb_from11"][0])
    assert f["pcrb_late"][0] == pytest.approx(np.arange(5, 9).mean())


def test_summarize_carries_the_new_figures() -> None:
    s = summarize([_run("proposed", 1, 20, 2.0, 3.0), _run("proposed", 2, 20, 4.0, 1.0)])
    assert s.loc_rmse_from2 == pytest.approx(math.sqrt(5.0))
    assert s.vel_rmse_from2 == pytest.approx(math.sqrt(0.05))
    assert s.pcrb_from11 == pytest.approx(3.0 * np.arange(11, 21).mean())
    assert s.loc_rmse > s.loc_rmse_from2  # slots 1..N keep slot 1's 100 m


def test_reductions_are_paired_against_proposed() -> None:
    """A method with 0.75 x proposed's bound on every run and half its errors: 25 % and 50 %
    with zero-width intervals however different the runs are (pairing)."""
    scales, errs = (1.0, 5.0, 2.0, 9.0), (1.0, 4.0, 0.5, 2.0)
    figs = {
        "proposed": run_figures(
            [
                _run("proposed", i, 30, s, e)
                for i, (s, e) in enumerate(zip(scales, errs, strict=True))
            ]
        ),
        "horizon": run_figures(
            [
                _run("horizon", i, 30, 0.75 * s, 0.5 * e)
                for i, (s, e) in enumerate(zip(scales, errs, strict=True))
            ]
        ),
    }
    red = reductions_against_baseline(figs)
    assert list(red) == ["horizon"] and list(red["horizon"]) == list(FIGURES)
    for key, want in (("pcrb", 25.0), ("pcrb_from11", 25.0), ("loc_mse", 50.0), ("vel_mse", 50.0)):
        iv = red["horizon"][key]
        assert iv is not None
        assert (iv.estimate, iv.low, iv.high) == pytest.approx((want, want, want))


def test_no_interval_from_one_run_or_without_proposed() -> None:
    one = {m: run_figures([_run(m, 0, 30, 1.0, 1.0)]) for m in ("proposed", "sd")}
    assert all(v is None for v in reductions_against_baseline(one)["sd"].values())
    assert reductions_against_baseline({"sd": one["sd"]}) == {}


def test_figure_tables_print_whole_to_a_non_terminal() -> None:
    rng = np.random.default_rng(3)
    runs = {
        m: [_run(m, i, 30, rng.uniform(1, 2) * k, rng.uniform(1, 2) * k) for i in range(6)]
        for m, k in (("proposed", 1.0), ("sd", 2.0), ("horizon", 0.7))
    }
    summaries = [summarize(r) for r in runs.values()]
    red = reductions_against_baseline({m: run_figures(r) for m, r in runs.items()})
    out = io.StringIO()
    print_table(Console(file=out), figures_table(summaries, "paper: 6 runs"))
    print_table(Console(file=out), against_baseline_table(red, 6))
    text = out.getvalue()
    assert "…" not in text
    for s in summaries:
        assert f"{s.loc_rmse_from2:.4g}" in text and f"{s.pcrb_from11:.4g}" in text
    for row in red.values():
        for iv in row.values():
            assert interval_cell(iv) in text
    assert "Horizon" in text and "paired bootstrap 95% interval over 6 runs" in text


def test_simulate_report_writes_the_intervals_and_per_run_figures(tmp_path: Path) -> None:
    """summary.json of a short Monte Carlo: every method's per-run figures, and the intervals
    against proposed equal to a bootstrap recomputed from those figures."""
    s = parse_scenario({"timing": {"duration_s": 12, "slot_s": 1.0}}, "short")
    out = io.StringIO()
    simulate_report(
        s,
        ["proposed", "sd"],
        runs=3,
        seed=4,
        out_dir=tmp_path,
        workers=1,
        plots=False,
        console=Console(file=out),
    )
    summary = json.loads((tmp_path / "summary.json").read_text())
    per_run = summary["per_run"]
    assert set(per_run) == {"proposed", "sd"} and all(len(v) == 3 for v in per_run["sd"].values())
    got = summary["against_proposed"]["sd"]["loc_mse"]
    want = paired_bootstrap(
        per_run["proposed"]["loc_mse"], per_run["sd"]["loc_mse"], reduction_of_rms, seed=4
    )
    assert got == pytest.approx(
        {"estimate": want.estimate, "low": want.low, "high": want.high, "level": 0.95}
    )
    assert interval_cell(want) in out.getvalue()
