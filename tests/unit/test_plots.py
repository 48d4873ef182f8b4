"""Plots: each function returns a Figure that saves to a PNG of the documented size from synthetic
traces, draws into the caller's axes when given them, and never switches the matplotlib backend."""

from __future__ import annotations

import struct
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

from isac_mission.experiment.plots import (
    BANDWIDTH_SIZE_IN,
    PERFORMANCE_SIZE_IN,
    TRAJECTORY_SIZE_IN,
    performance_curves,
    plot_bandwidth,
    plot_performance,
    plot_trajectories,
    save_png,
)
from isac_mission.records import SlotRecord, Trace

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
DPI = 80


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    width, height = struct.unpack(">II", data[16:24])  # IHDR comes first
    return width, height


def expected_px(size_in: tuple[float, float]) -> tuple[int, int]:
    return round(size_in[0] * DPI), round(size_in[1] * DPI)


def synthetic_trace(method: str, seed: int, n_slots: int = 12, d_th: float = 24e3) -> Trace:
    rng = np.random.default_rng(seed)
    start = np.array([[1500.0, 2300.0], [807.0, 1100.0], [2193.0, 1100.0]])
    target = np.array([600.0, 1600.0, 30.0, 0.0])
    uav = start.copy()
    slots = []
    C = np.diag([100.0, 100.0, 4.0, 4.0])
    for n in range(1, n_slots + 1):
        target = target + np.array([30.0, 0.0, 0.0, 0.0])
        uav = uav + 20.0 * (target[:2] - uav) / np.linalg.norm(target[:2] - uav, axis=1)[:, None]
        C = 0.8 * C + 0.01 * np.eye(4)
        eta = rng.dirichlet(np.ones(3))
        slots.append(
            SlotRecord(
                slot=n,
                method=method,
                status="infeasible" if n == 5 else "ok",
                uav_xy_m=uav,
                bandwidth_share=eta,
                assoc=np.array([0, 1, 2]),
                target_true=target,
                target_est=target + rng.normal(0, [5, 5, 1, 1]),
                target_pred=target,
                r_diag=np.ones(6),
                pcrb_trace=float(np.trace(C)),
                solve_ms=3.0,
                P=C,
                J=np.linalg.inv(C),
            )
        )
    config = {
        "M": 3,
        "area": [3000.0, 3000.0],
        "bs_xy": [[200.0, 300.0], [2800.0, 400.0], [1500.0, 2900.0]],
        "d_th": d_th,
        "uav_start_xy": start.tolist(),
        "method": method,
    }
    return Trace(config=config, slots=slots)


@pytest.mark.parametrize("d_th", [24e3, 800.0])
def test_trajectory_plot_is_a_png_of_the_documented_size(tmp_path: Path, d_th: float) -> None:
    fig = plot_trajectories(synthetic_trace("proposed", 1, d_th=d_th))
    assert isinstance(fig, Figure)
    out = save_png(fig, tmp_path / "traj.png", dpi=DPI)
    assert out == tmp_path / "traj.png"
    assert out.stat().st_size > 10_000
    assert png_size(out) == expected_px(TRAJECTORY_SIZE_IN)


def test_bandwidth_plot_is_a_png_of_the_documented_size(tmp_path: Path) -> None:
    out = save_png(
        plot_bandwidth(synthetic_trace("proposed", 2)), tmp_path / "sub" / "bw.png", dpi=DPI
    )
    assert out.stat().st_size > 5_000
    assert png_size(out) == expected_px(BANDWIDTH_SIZE_IN)


def test_performance_plot_is_a_png_of_the_documented_size(tmp_path: Path) -> None:
    traces = {
        "proposed": [synthetic_trace("proposed", s) for s in range(3)],
        "SD": [synthetic_trace("SD", s, n_slots=8) for s in range(2)],
    }
    out = save_png(plot_performance(traces), tmp_path / "perf.png", dpi=DPI)
    assert out.stat().st_size > 10_000
    assert png_size(out) == expected_px(PERFORMANCE_SIZE_IN)


def test_performance_curves_are_root_mean_squares_over_runs() -> None:
    runs = [synthetic_trace("proposed", s, n_slots=4) for s in range(3)]
    curves = performance_curves(runs)
    slots, rmse = curves["rmse_pos"]
    np.testing.assert_array_equal(slots, [1, 2, 3, 4])
    err = np.array(
        [[np.sum((r.target_est - r.target_true)[:2] ** 2) for r in t.slots] for t in runs]
    )
    np.testing.assert_allclose(rmse, np.sqrt(err.mean(axis=0)), rtol=1e-12)
    _, bound_vel = curves["pcrb_vel"]
    C_vel = np.array([[np.trace(r.P[2:, 2:]) for r in t.slots] for t in runs])  # P = J^-1 here
    np.testing.assert_allclose(bound_vel, np.sqrt(C_vel.mean(axis=0)), rtol=1e-10)


def test_plots_accept_an_empty_trace(tmp_path: Path) -> None:
    empty = Trace(config={"bs_xy": [[0.0, 0.0]], "area": [100.0, 100.0]}, slots=[])
    assert png_size(save_png(plot_trajectories(empty), tmp_path / "t.png", dpi=DPI)) == expected_px(
        TRAJECTORY_SIZE_IN
    )
    assert png_size(save_png(plot_bandwidth(empty), tmp_path / "b.png", dpi=DPI)) == expected_px(
        BANDWIDTH_SIZE_IN
    )


def test_plots_draw_into_the_callers_axes_and_write_no_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    trace = synthetic_trace("proposed", 3)
    fig = Figure(figsize=(12.0, 8.0))
    ax_traj, ax_bw, ax_bound, ax_err = fig.subplots(2, 2).ravel()
    assert plot_trajectories(trace, ax=ax_traj) is fig
    assert plot_bandwidth(trace, ax=ax_bw) is fig
    assert plot_performance({"proposed": [trace]}, axes=(ax_bound, ax_err)) is fig
    assert len(fig.axes) == 4  # nothing added beside the caller's axes
    # M UAV paths, the target's true and estimated paths at least, on the caller's axes.
    assert len(ax_traj.get_lines()) >= trace.stack("uav_xy").shape[1] + 2
    assert ax_traj.get_legend() is not None
    assert len(ax_bw.collections) >= 1  # the stacked shares
    assert ax_bw.get_ylim() == (0.0, 1.0)
    # (a): a location and a velocity bound line; (b): the same for the errors, per method.
    assert len(ax_bound.get_lines()) == 2 and len(ax_err.get_lines()) == 2
    assert ax_bound.get_yscale() == "log"
    assert list(tmp_path.iterdir()) == []


def test_an_axes_in_a_subfigure_returns_the_root_figure() -> None:
    fig = Figure()
    (sub,) = fig.subfigures(1, 1, squeeze=False)[0]
    ax = sub.subplots()
    assert plot_bandwidth(synthetic_trace("proposed", 4), ax=ax) is fig


def test_plotting_keeps_the_matplotlib_backend() -> None:
    before = matplotlib.get_backend()
    plot_trajectories(synthetic_trace("proposed", 5))
    assert matplotlib.get_backend() == before


def test_no_module_switches_the_backend_or_uses_pyplot() -> None:
    root = Path(__file__).resolve().parents[2]
    offenders = [
        str(path.relative_to(root))
        for folder in ("isac_mission", "sim")
        for path in sorted((root / folder).rglob("*.py"))
        if "matplotlib.use(" in (text := path.read_text()) or "matplotlib.pyplot" in text
    ]
    assert offenders == []
