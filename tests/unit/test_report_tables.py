"""Report tables print whole when the output is not a terminal (a pipe, a log file, CI), and the
paper comparison table states its sign convention."""

from __future__ import annotations

import dataclasses
import io
import re

import pytest
from rich.console import Console

from isac_mission.experiment.montecarlo import MethodSummary
from isac_mission.experiment.report import (
    LABELS,
    TABLE_WIDTH_NOT_TERMINAL,
    benchmark_rows,
    benchmark_table,
    gospa_table,
    paper_change_pct,
    print_table,
    summary_table,
)


def _summaries() -> dict[str, MethodSummary]:
    out = {}
    for i, method in enumerate(LABELS):
        scale = 1.0 + 0.37 * i
        out[method] = MethodSummary(
            method=method,
            runs=20,
            pcrb_pos=0.0212345 * scale,
            pcrb_vel=0.000412345 * scale,
            pcrb_pos_late=0.0187654 * scale,
            loc_rmse=0.151234 * scale,
            vel_rmse=0.0212987 * scale,
            efficiency=1.01234 + 0.1 * i,
            solve_median_ms=31.25 + i,
            solve_p95_ms=48.75 + i,
            infeasible_slots=i,
            slots=2000,
        )
    return out


def _cells(summaries: dict[str, MethodSummary]) -> list[str]:
    """Every text a row of the summary table shows (as summary_table formats it)."""
    cells = []
    for s in summaries.values():
        cells += [
            LABELS[s.method],
            f"{s.pcrb_pos:.4g}",
            f"{s.pcrb_vel:.4g}",
            f"{s.pcrb_pos_late:.4g}",
            f"{s.loc_rmse:.4g}",
            f"{s.vel_rmse:.4g}",
            f"{s.efficiency:.3f}",
            f"{s.infeasible_slots}/{s.slots}",
            f"{s.solve_median_ms:.1f}",
            f"{s.solve_p95_ms:.1f}",
        ]
    return cells


def _row_cells(text: str) -> list[str]:
    """The cells of every table row in rich's box drawing, stripped."""
    return [cell.strip() for line in text.splitlines() for cell in re.split("[│┃]", line)[1:-1]]


def test_summary_table_prints_every_number_whole_to_a_non_terminal() -> None:
    summaries = _summaries()
    out = io.StringIO()
    console = Console(file=out)  # a file: not a terminal, rich's default width is 80 columns
    assert not console.is_terminal and console.width == 80
    print_table(console, summary_table(list(summaries.values()), "paper: 20 runs"))
    text = out.getvalue()
    assert "…" not in text
    cells = _row_cells(text)
    for cell in _cells(summaries):
        assert cell in cells, (cell, text)
    assert max(len(line) for line in text.splitlines()) <= TABLE_WIDTH_NOT_TERMINAL


def test_benchmark_table_prints_whole_to_a_non_terminal() -> None:
    rows = benchmark_rows(_summaries())
    out = io.StringIO()
    print_table(Console(file=out), benchmark_table(rows))
    text = out.getvalue()
    flat = " ".join(text.split())  # the title and caption wrap at the table's width
    assert "…" not in text
    assert "negative = lower (better) than Proposed" in flat
    assert "(SD 61.1 % / 59.9 %, ABA 22.8 % / 29.1 %, CRB-criterion 9.0 % / 12.0 %)" in flat
    cells = _row_cells(text)
    for r in rows:
        for key in (
            "pcrb_change_pct",
            "loc_change_pct",
            "loc_paper_change_pct",
            "vel_change_pct",
            "vel_paper_change_pct",
        ):
            assert f"{r[key]:+.1f} %" in cells


def test_the_papers_reductions_restated_as_the_benchmarks_change() -> None:
    """The paper: the proposed RMSE 61.1 % below SD's, i.e. SD's 1 / 0.389 of it, +157.1 %."""
    assert paper_change_pct(61.1) == pytest.approx(100 * (1 / 0.389 - 1))
    assert paper_change_pct(0.0) == 0.0
    by_method = _summaries()  # every benchmark above the proposed method: positive changes
    assert all(
        float(r[k]) > 0
        for r in benchmark_rows(by_method)
        for k in ("pcrb_change_pct", "loc_change_pct", "vel_change_pct")
    )


def test_plain_rich_print_would_cut_the_summary_table_at_80_columns() -> None:
    """The failure print_table exists for: the same table through console.print is cut."""
    out = io.StringIO()
    Console(file=out).print(summary_table(list(_summaries().values()), "paper: 20 runs"))
    assert "…" in out.getvalue()


def test_a_table_wider_than_the_fixed_width_still_prints_whole() -> None:
    from rich.table import Table

    table = Table(title="wide")
    values = [f"{1.0 / 7 * (i + 1):.12f}" for i in range(14)]
    for i in range(len(values)):
        table.add_column(f"column {i}")
    table.add_row(*values)
    out = io.StringIO()
    print_table(Console(file=out), table)
    text = out.getvalue()
    assert "…" not in text
    assert all(v in _row_cells(text) for v in values)
    assert max(len(line) for line in text.splitlines()) > TABLE_WIDTH_NOT_TERMINAL


def test_a_terminal_keeps_its_own_width() -> None:
    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=100)
    print_table(console, summary_table(list(_summaries().values()), "paper: 20 runs"))
    plain = re.sub(r"\x1b\[[0-9;]*m", "", out.getvalue())
    assert max(len(line) for line in plain.splitlines()) <= 100


def test_the_gospa_table_shows_each_methods_gospa_and_bound() -> None:
    summaries = {
        m: dataclasses.replace(s, gospa_m=0.5 + 0.25 * i)
        for i, (m, s) in enumerate(_summaries().items())
    }
    out = io.StringIO()
    print_table(Console(file=out), gospa_table(list(summaries.values()), 10.0))
    text = out.getvalue()
    assert "c = 10 m" in text
    for s in summaries.values():
        assert f"{s.gospa_m:.4g}" in text and f"{s.pcrb_pos:.4g}" in text
