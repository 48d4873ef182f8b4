"""experiment/comparison.py and its report tables: per-run figures on hand-made runs, changes
(and summary.json's reductions) against `proposed` with paired intervals, the tables printed
whole, and one sign convention in every comparison table of `simulate`, stated in each title."""

from __future__ import annotations

import io
import json
import math
import re
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

import isac_mission.experiment.report as report_module
from isac_mission.config import Scenario, load_scenario, parse_scenario
from isac_mission.experiment.bootstrap import (
    change_of_means,
    change_of_rms,
    change_pct,
    paired_bootstrap,
    reduction_of_means,
    reduction_of_rms,
)
from isac_mission.experiment.closed_loop import RunResult
from isac_mission.experiment.comparison import (
    CHANGES,
    FIGURES,
    changes_against_reference,
    pooled,
    reductions_against_baseline,
    run_figures,
)
from isac_mission.experiment.montecarlo import summarize
from isac_mission.experiment.report import (
    against_reference_table,
    change_cell,
    figures_table,
    interval_cell,
    print_table,
    simulate_report,
)
from isac_mission.experiment.runs import MissionRun
from isac_mission.experiment.track_metrics import RunFigures

CONVENTION = "negative = lower (better) than Proposed"
"""What every comparison table of `simulate` states in its title."""


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


def test_changes_are_paired_against_proposed_and_negative_when_lower() -> None:
    """The same runs as above: -25 % and -50 %, the reductions' numbers with the opposite sign."""
    scales, errs = (1.0, 5.0, 2.0, 9.0), (1.0, 4.0, 0.5, 2.0)
    figs = {
        m: run_figures(
            [
                _run(m, i, 30, k * s, k * e)
                for i, (s, e) in enumerate(zip(scales, errs, strict=True))
            ]
        )
        for m, k in (("proposed", 1.0), ("horizon", 0.75))
    }
    figs["horizon"]["loc_mse"] = figs["horizon"]["loc_mse"] * (0.5 / 0.75) ** 2
    figs["horizon"]["vel_mse"] = figs["horizon"]["vel_mse"] * (0.5 / 0.75) ** 2
    ch = changes_against_reference(figs)
    assert list(ch) == ["horizon"] and list(ch["horizon"]) == list(CHANGES)
    red = reductions_against_baseline(figs)
    for key, want in (("pcrb", -25.0), ("loc_mse", -50.0), ("vel_mse", -50.0)):
        c = ch["horizon"][key]
        assert c.interval is not None and c.missing is None
        assert (c.estimate, c.interval.low, c.interval.high) == pytest.approx((want, want, want))
        legacy = red["horizon"][key]
        assert legacy is not None and legacy.estimate == pytest.approx(-want)


def test_one_function_gives_every_change() -> None:
    r, o = np.array([2.0, 4.0, 6.0]), np.array([1.0, 1.0, 1.0])
    assert float(change_pct(3.0, 4.0)) == pytest.approx(-25.0)
    assert float(change_of_means(r, o)) == pytest.approx(float(change_pct(1.0, 4.0)))
    assert float(change_of_rms(r, o)) == pytest.approx(float(change_pct(1.0, 2.0)))
    assert float(change_of_means(r, o)) == pytest.approx(-float(reduction_of_means(r, o)))
    assert float(change_of_rms(r, o)) == pytest.approx(-float(reduction_of_rms(r, o)))


def test_no_interval_from_one_run_or_without_proposed() -> None:
    one = {m: run_figures([_run(m, 0, 30, 1.0, 1.0)]) for m in ("proposed", "sd")}
    assert all(v is None for v in reductions_against_baseline(one)["sd"].values())
    assert reductions_against_baseline({"sd": one["sd"]}) == {}
    ch = changes_against_reference(one)["sd"]
    assert all(c.interval is None and c.estimate == pytest.approx(0.0) for c in ch.values())
    assert {c.missing for c in ch.values()} == {"a paired bootstrap interval needs at least 2 runs"}
    assert changes_against_reference({"sd": one["sd"]}) == {}
    short = {m: run_figures([_run(m, i, 8, 1.0, 1.0) for i in range(3)]) for m in one}
    no_value = changes_against_reference(short)["sd"]["pcrb_from11"]
    assert no_value.estimate is None and no_value.missing == "slots 11..N need N >= 11"


def test_figure_tables_print_whole_to_a_non_terminal() -> None:
    rng = np.random.default_rng(3)
    runs = {
        m: [_run(m, i, 30, rng.uniform(1, 2) * k, rng.uniform(1, 2) * k) for i in range(6)]
        for m, k in (("proposed", 1.0), ("sd", 2.0), ("horizon", 0.7))
    }
    summaries = [summarize(r) for r in runs.values()]
    ch = changes_against_reference({m: run_figures(r) for m, r in runs.items()})
    out = io.StringIO()
    print_table(Console(file=out), figures_table(summaries, "paper: 6 runs"))
    print_table(Console(file=out), against_reference_table(ch, 6))
    text = out.getvalue()
    assert "…" not in text
    for s in summaries:
        assert f"{s.loc_rmse_from2:.4g}" in text and f"{s.pcrb_from11:.4g}" in text
    for row in ch.values():
        for c in row.values():
            assert c.interval is not None and change_cell(c) in text
    flat = " ".join(text.split())  # the title wraps at the table's width
    assert "Horizon" in text and "paired bootstrap 95% interval over 6 runs" in flat


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
    shown = paired_bootstrap(
        per_run["proposed"]["loc_mse"], per_run["sd"]["loc_mse"], change_of_rms, seed=4
    )
    assert summary["change_against_proposed"]["sd"]["loc_mse"] == pytest.approx(
        {"estimate": shown.estimate, "low": shown.low, "high": shown.high, "level": 0.95}
        | {"missing": None}
    )
    assert shown.estimate == pytest.approx(-want.estimate)
    assert interval_cell(shown) in out.getvalue()


def _labelled(run: RunResult) -> MissionRun:
    """A run whose one labelled track is `run` (its tracks' figures left empty)."""
    z = np.zeros(len(run.status))
    return MissionRun(run.method, run.seed, run.solve_s, RunFigures(z, z, z, z, (), ()), run)


def _fake_monte_carlo(
    scales: dict[str, float],
) -> Callable[..., dict[str, list[MissionRun]]]:
    """A stand-in for run_monte_carlo: each method's runs are proposed's (per-run bound and error
    differing from run to run) times scales[method], bound and errors alike."""
    base = ((1.0, 1.0), (5.0, 4.0), (2.0, 0.5), (9.0, 2.0))

    def fake(
        s: Scenario, methods: Sequence[str], runs: int, seed: int, **_: object
    ) -> dict[str, list[MissionRun]]:
        return {
            m: [
                _labelled(_run(m, seed + r, 30, scales[m] * base[r][0], scales[m] * base[r][1]))
                for r in range(runs)
            ]
            for m in methods
        }

    return fake


def _simulate_text(monkeypatch: pytest.MonkeyPatch, tmp_path: Path, runs: int) -> str:
    """What simulate_report prints on hand-made runs: ABA half of proposed's bound and errors
    (lower, better), SD twice them (higher)."""
    scales = {"proposed": 1.0, "sd": 2.0, "aba": 0.5}
    monkeypatch.setattr(report_module, "run_monte_carlo", _fake_monte_carlo(scales))
    s = parse_scenario({"timing": {"duration_s": 30, "slot_s": 1.0}}, "short")
    out = io.StringIO()
    simulate_report(
        s,
        list(scales),
        runs=runs,
        seed=1,
        out_dir=tmp_path,
        workers=1,
        plots=False,
        console=Console(file=out),
    )
    return out.getvalue()


def _percentages(text: str, label: str) -> list[list[str]]:
    """The signs of the % figures ('-12.3 %': estimates, not interval ends) of every table row of
    `label` that holds any (one list per row)."""
    rows = [ln for ln in text.splitlines() if re.match(rf"[│┃]\s*{re.escape(label)}\s*[│┃]", ln)]
    found = [re.findall(r"([+-])\d+\.\d %", ln) for ln in rows]
    return [f for f in found if f]


def test_both_simulate_tables_give_the_same_sign_to_the_same_pair(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """ABA below proposed on every figure reads negative in the paper table and in the interval
    table alike, SD above it positive, and the tables' tr(PCRB) change is the same number."""
    text = _simulate_text(monkeypatch, tmp_path, runs=4)
    for label, sign in (("ABA", "-"), ("SD", "+")):
        tables = _percentages(text, label)
        assert len(tables) == 2, text
        paper_table, interval_table = tables
        assert paper_table[0] == interval_table[0] == sign, (label, text)  # tr(PCRB)
        measured = [paper_table[i] for i in (0, 1, 3)]  # tr(PCRB), loc, vel (2 and 4: the paper)
        assert set(measured) == {sign} and interval_table == [sign] * len(CHANGES), (label, text)
    aba_rows = [ln for ln in text.splitlines() if re.match(r"[│┃]\s*ABA\s*[│┃]", ln) and "%" in ln]
    assert aba_rows[0].split("│")[2].strip() == "-50.0 %"
    assert aba_rows[1].split("│")[2].strip().startswith("-50.0 % [")


def test_every_simulate_comparison_table_states_its_convention(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    flat = " ".join(_simulate_text(monkeypatch, tmp_path, runs=4).split())  # titles wrap
    assert flat.count(CONVENTION) == 2
    assert "Each benchmark against Proposed" in flat and "Each method against Proposed" in flat
    assert "needs at least 2 runs" not in flat


def test_one_run_prints_the_estimates_and_says_why_there_is_no_interval(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    text = _simulate_text(monkeypatch, tmp_path, runs=1)
    flat = " ".join(text.split())
    assert "no interval: a paired bootstrap interval needs at least 2 runs (1 run here)" in flat
    _, interval_table = _percentages(text, "ABA")
    assert interval_table == ["-"] * len(CHANGES)  # an estimate in every cell, no interval
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["against_proposed"]["aba"]["pcrb"] is None  # as before: no interval
    assert summary["change_against_proposed"]["aba"]["pcrb"] == pytest.approx(
        {"estimate": -50.0, "low": None, "high": None, "level": 0.95}
        | {"missing": "a paired bootstrap interval needs at least 2 runs"}
    )


def _gospa_runs(gospa_m: Sequence[float], method: str) -> list[MissionRun]:
    """A method's runs with the given mission-mean GOSPA (m), no targets followed."""
    z = np.zeros(5)
    return [
        MissionRun(method, r, np.full(5, 0.01), RunFigures(np.full(5, g), z, z, z, (), ()), None)
        for r, g in enumerate(gospa_m)
    ]


@pytest.mark.parametrize("runs", [1, 3])
def test_the_multi_target_gospa_table_keeps_the_convention(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, runs: int
) -> None:
    """ABA's GOSPA 80 % of proposed's: -20 % under the same title, and with one run the estimate
    with the reason for no interval; summary.json keeps the reduction (+20 %) beside it."""
    base = [2.0, 3.0, 4.0][:runs]
    by_method = {
        "proposed": _gospa_runs(base, "proposed"),
        "aba": _gospa_runs([0.8 * g for g in base], "aba"),
    }
    monkeypatch.setattr(report_module, "run_monte_carlo", lambda *a, **k: by_method)
    s = load_scenario("multi-target")
    out = io.StringIO()
    summary = simulate_report(
        s,
        list(by_method),
        runs=runs,
        seed=1,
        out_dir=tmp_path,
        workers=1,
        plots=False,
        console=Console(file=out),
    )
    text = out.getvalue()
    flat = " ".join(text.split())
    assert CONVENTION in flat
    assert ("needs at least 2 runs (1 run here)" in flat) == (runs == 1)
    (aba,) = _percentages(text, "ABA")
    assert aba == ["-"]
    assert ("-20.0 % [-20.0, -20.0]" in text) == (runs > 1)
    row = summary["against_baseline"]["aba"]
    assert row["gospa_change_pct"][0] == pytest.approx(-20.0)
    if runs > 1:
        assert row["gospa_reduction_pct"] == pytest.approx([20.0, 20.0, 20.0])


def test_a_single_target_summary_reports_its_gospa() -> None:
    """One target, one estimate: GOSPA (c = 10 m, p = 2) is the position error up to c. Slot 1's
    100 m error counts c; the others err_m (here 3 m, then 4 m in the second run)."""
    s = summarize([_run("proposed", 1, 20, 2.0, 3.0), _run("proposed", 2, 20, 4.0, 4.0)])
    want = np.mean([(10.0 + 19 * 3.0) / 20, (10.0 + 19 * 4.0) / 20])
    assert s.gospa_m == pytest.approx(want, rel=1e-12)
    far = summarize([_run("proposed", 1, 5, 1.0, 25.0)], gospa_cutoff_m=30.0)
    assert far.gospa_m == pytest.approx((30.0 + 4 * 25.0) / 5, rel=1e-12)
