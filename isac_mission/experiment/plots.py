"""Figures in the style of the paper's Fig. 2 (trajectories, bandwidth) and Fig. 3 (bound, RMSE),
and the tracks picture of a run whose tracks were found from unlabelled reports; `save_plots`,
the one entry point of `simulate` and of the live summary, writes what the traces hold.

Each plot function draws into the axes it is given (`ax=` / `axes=`, e.g. a notebook's) or, by
default, into a new `matplotlib.figure.Figure` of a fixed size (the *_SIZE_IN constants, inches)
with an Agg canvas, and returns the Figure. Nothing here calls pyplot or switches the backend
(`matplotlib.use`), so inline notebook plots keep working, and drawing is safe from any thread.
Nothing here writes a file unless asked: `save_png(fig, path, dpi=...)` does, at size_in x dpi
pixels (the CLI's commands call it). Inputs are traces as read by
`isac_mission.records.read_trace`; the config keys used are bs_xy, d_th, area and
uav_start_xy (all optional except bs_xy for the trajectory plot). The tracks picture reads a
tracks trace (docs/trace.md, "Lines of a tracker of several tracks") with `read_tracks_trace`.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Rectangle

from isac_mission.records import Trace, read_trace
from isac_mission.types import FloatArray

TRAJECTORY_SIZE_IN: Final[tuple[float, float]] = (9.5, 6.5)
BANDWIDTH_SIZE_IN: Final[tuple[float, float]] = (7.0, 3.8)
PERFORMANCE_SIZE_IN: Final[tuple[float, float]] = (11.0, 5.0)
TRACKS_SIZE_IN: Final[tuple[float, float]] = (8.0, 7.0)
DEFAULT_DPI: Final[int] = 120

_UAV_COLOURS: Final[tuple[str, ...]] = (
    "tab:blue",
    "tab:orange",
    "tab:green",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:olive",
    "tab:cyan",
)


def _uav_colour(m: int) -> str:
    return _UAV_COLOURS[m % len(_UAV_COLOURS)]


def new_figure(
    size_in: tuple[float, float], *, layout: Literal["constrained", "tight"] | None = "constrained"
) -> Figure:
    """A Figure of `size_in` (width, height) inches on an Agg canvas (no pyplot, no backend)."""
    fig = Figure(figsize=size_in, dpi=DEFAULT_DPI, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def figure_of(ax: Axes) -> Figure:
    """The (root) Figure that `ax` is drawn in."""
    fig = ax.get_figure(root=True)
    if fig is None:
        raise ValueError("the axes belong to no figure")
    return fig


def save_png(fig: Figure, path: str | Path, *, dpi: int = DEFAULT_DPI) -> Path:
    """Write `fig` as a PNG of (figure size in inches) x `dpi` pixels, making the parent folders;
    returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, format="png", dpi=dpi)
    return out


def _side_legend(ax: Axes, handles: Sequence[Any]) -> None:
    """The legend of a plot drawn into a caller's axes: beside them, on the right."""
    ax.legend(handles=list(handles), loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)


def _area(config: Mapping[str, Any], points: FloatArray) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) of the scenario area in m: config "area" [w, h] from the origin, else the
    bounding box of the plotted points."""
    area = config.get("area")
    if isinstance(area, Sequence) and len(area) == 2:
        return 0.0, float(area[0]), 0.0, float(area[1])
    finite = points[np.all(np.isfinite(points), axis=1)] if points.size else points
    if finite.size == 0:
        return 0.0, 1.0, 0.0, 1.0
    lo, hi = finite.min(axis=0), finite.max(axis=0)
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def _title(trace: Trace, what: str) -> str:
    method = trace.method or "unknown method"
    return f"{what}: {method}, {len(trace.slots)} slots"


def plot_trajectories(trace: Trace, ax: Axes | None = None) -> Figure:
    """Fig. 2(a)-style map of one run: BSs, control-range circles, UAV and target paths.

    BSs (triangles, config bs_xy [K, 2] m) with circles of radius d_th (config d_th, m) around
    them, clipped to the area plus a 10 % margin (the legend says when they lie outside it, as in
    the paper's scenario where d_th is about 24 km); the area's bounds (config area [2] m); each
    UAV's path from its start (config uav_start_xy, circle) through the slots' uav_xy to its last
    position (square), one colour per UAV; the target's true path (black) and the EKF estimate
    (red, dashed). Draws into `ax` if given (legend beside it), else into a new Figure of
    TRAJECTORY_SIZE_IN (legend outside on the right); returns the Figure.
    """
    cfg = trace.config
    bs_xy = np.asarray(cfg.get("bs_xy", []), dtype=float).reshape(-1, 2)
    uav = trace.stack("uav_xy") if trace.slots else np.zeros((0, 0, 2))  # [N, M, 2]
    start = np.asarray(cfg.get("uav_start_xy", []), dtype=float).reshape(-1, 2)
    truth = trace.stack("target_true")[:, :2] if trace.slots else np.zeros((0, 2))
    est = trace.stack("target_est")[:, :2] if trace.slots else np.zeros((0, 2))
    points = np.vstack([bs_xy, start, uav.reshape(-1, 2), truth, est])
    x0, x1, y0, y1 = _area(cfg, points)
    margin = 0.1 * max(x1 - x0, y1 - y0, 1.0)
    view = (x0 - margin, x1 + margin, y0 - margin, y1 + margin)

    own = ax is None
    if ax is None:
        fig = new_figure(TRAJECTORY_SIZE_IN)
        ax = fig.subplots()
    else:
        fig = figure_of(ax)
    handles: list[Any] = []
    if "area" in cfg:
        ax.add_patch(
            Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="0.4", ls=":", lw=1.0, zorder=1)
        )
        handles.append(Line2D([], [], color="0.4", ls=":", label="area"))
    d_th = cfg.get("d_th")
    if isinstance(d_th, int | float) and math.isfinite(d_th) and d_th > 0 and bs_xy.size:
        corners = np.array(
            [[view[0], view[2]], [view[0], view[3]], [view[1], view[2]], [view[1], view[3]]]
        )
        far = float(np.max(np.linalg.norm(corners[:, None, :] - bs_xy[None, :, :], axis=2)))
        for w in bs_xy:
            ax.add_patch(
                Circle(tuple(w), d_th, fill=False, ec="tab:gray", ls="--", lw=0.8, zorder=1)
            )
        where = " (circles lie outside the plot)" if d_th > far else ""
        handles.append(
            Line2D(
                [],
                [],
                color="tab:gray",
                ls="--",
                label=f"control range d_th = {d_th / 1e3:.1f} km{where}",
            )
        )
    if bs_xy.size:
        ax.plot(bs_xy[:, 0], bs_xy[:, 1], "k^", ms=9, zorder=4)
        for k, w in enumerate(bs_xy):
            ax.annotate(f"BS {k}", tuple(w), xytext=(5, 5), textcoords="offset points", fontsize=8)
        handles.append(Line2D([], [], color="k", marker="^", ls="", ms=9, label="base station"))
    n_uav = uav.shape[1] if uav.size else start.shape[0]
    for m in range(n_uav):
        colour = _uav_colour(m)
        path_m = uav[:, m, :] if uav.size else np.zeros((0, 2))
        if m < start.shape[0]:
            path_m = np.vstack([start[m : m + 1], path_m])
        ax.plot(path_m[:, 0], path_m[:, 1], "-", color=colour, lw=1.6, zorder=3)
        if len(path_m):
            ax.plot(*path_m[0], "o", color=colour, ms=7, mfc="white", mew=2, zorder=5)
            ax.plot(*path_m[-1], "s", color=colour, ms=6, zorder=5)
        handles.append(Line2D([], [], color=colour, lw=1.6, label=f"UAV {m}"))
    handles.append(Line2D([], [], color="0.3", marker="o", mfc="white", ls="", label="start"))
    handles.append(Line2D([], [], color="0.3", marker="s", ls="", label="end"))
    if np.isfinite(truth).any():
        ax.plot(truth[:, 0], truth[:, 1], "-", color="k", lw=1.4, zorder=3)
        first = truth[np.all(np.isfinite(truth), axis=1)][0]
        ax.plot(*first, "D", color="k", ms=6, mfc="white", mew=1.5, zorder=5)
        handles.append(Line2D([], [], color="k", lw=1.4, label="target (true)"))
        handles.append(
            Line2D([], [], color="k", marker="D", mfc="white", ls="", label="target at first slot")
        )
    if np.isfinite(est).any():
        ax.plot(est[:, 0], est[:, 1], "--", color="tab:red", lw=1.4, zorder=3)
        handles.append(
            Line2D([], [], color="tab:red", ls="--", lw=1.4, label="target (EKF estimate)")
        )
    ax.set_xlim(view[0], view[1])
    ax.set_ylim(view[2], view[3])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    ax.set_title(_title(trace, "UAV and target trajectories"))
    ax.grid(True, alpha=0.3)
    if own:
        fig.legend(handles=handles, loc="outside right upper", fontsize=8)
    else:
        _side_legend(ax, handles)
    return fig


def plot_bandwidth(trace: Trace, ax: Axes | None = None) -> Figure:
    """Fig. 2(b)-style stacked bandwidth shares eta [M] over slots, one colour per UAV.

    Slots whose status is not "ok" are shaded. Draws into `ax` if given (legend beside it), else
    into a new Figure of BANDWIDTH_SIZE_IN; returns the Figure.
    """
    own = ax is None
    if ax is None:
        fig = new_figure(BANDWIDTH_SIZE_IN)
        ax = fig.subplots()
    else:
        fig = figure_of(ax)
    if trace.slots:
        slots = np.array([rec.slot for rec in trace.slots], dtype=float)
        eta = trace.stack("eta")  # [N, M]
        n_uav = eta.shape[1]
        ax.stackplot(
            slots,
            np.nan_to_num(eta.T),
            labels=[f"UAV {m}" for m in range(n_uav)],
            colors=[_uav_colour(m) for m in range(n_uav)],
            alpha=0.85,
            step="mid",
        )
        bad = [rec.slot for rec in trace.slots if rec.status != "ok"]
        for i, n in enumerate(bad):
            ax.axvspan(
                n - 0.5,
                n + 0.5,
                facecolor="none",
                edgecolor="k",
                hatch="//",
                lw=0,
                zorder=3,
                label=None if i else 'status not "ok"',
            )
        ax.set_xlim(slots.min() - 0.5, slots.max() + 0.5)
    ax.set_ylim(0.0, 1.0)
    ax.set_xlabel("slot n (Δt each)")
    ax.set_ylabel("bandwidth share η [-]")
    ax.set_title(_title(trace, "Bandwidth allocation"))
    ax.grid(True, alpha=0.3)
    if trace.slots:
        if own:
            fig.legend(*ax.get_legend_handles_labels(), loc="outside right upper", fontsize=8)
        else:
            _side_legend(ax, ax.get_legend_handles_labels()[0])
    return fig


def _information_to_covariance(J: FloatArray) -> FloatArray:
    """J^-1 [4, 4] after Jacobi (diagonal) scaling; NaN if J is not invertible."""
    d = np.diag(J)
    if not (np.all(np.isfinite(J)) and np.all(d > 0)):
        return np.full((4, 4), np.nan)
    s = 1.0 / np.sqrt(d)
    try:
        inv = np.linalg.inv(J * s[:, None] * s[None, :])
    except np.linalg.LinAlgError:
        return np.full((4, 4), np.nan)
    return np.asarray(inv * s[:, None] * s[None, :])


def performance_curves(traces: Sequence[Trace]) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Per-slot averages over runs, keyed "pcrb_pos", "pcrb_vel", "rmse_pos", "rmse_vel".

    Each value is (slots [S], values [S]): sqrt(mean over runs of tr(J^-1)[:2, :2]) in m and of
    tr(J^-1)[2:, 2:] in m/s; sqrt(mean over runs of ||p_true - p_est||^2) in m and of the
    velocity error in m/s. A slot is averaged over the runs that have it (and, for the RMSE,
    that know target_true); slots no run has are absent.
    """
    acc: dict[str, dict[int, list[float]]] = {
        k: {} for k in ("pcrb_pos", "pcrb_vel", "rmse_pos", "rmse_vel")
    }
    for trace in traces:
        for rec in trace.slots:
            C = _information_to_covariance(rec.J)
            acc["pcrb_pos"].setdefault(rec.slot, []).append(float(np.trace(C[:2, :2])))
            acc["pcrb_vel"].setdefault(rec.slot, []).append(float(np.trace(C[2:, 2:])))
            if rec.target_true is not None and np.all(np.isfinite(rec.target_true)):
                err = rec.target_est - rec.target_true
                acc["rmse_pos"].setdefault(rec.slot, []).append(float(err[:2] @ err[:2]))
                acc["rmse_vel"].setdefault(rec.slot, []).append(float(err[2:] @ err[2:]))
    out: dict[str, tuple[FloatArray, FloatArray]] = {}
    for key, by_slot in acc.items():
        slots = np.array(sorted(by_slot), dtype=float)
        vals = np.array([math.sqrt(float(np.mean(by_slot[int(n)]))) for n in slots], dtype=float)
        out[key] = (slots, vals)
    return out


def plot_performance(
    traces_by_method: Mapping[str, Sequence[Trace]],
    axes: tuple[Axes, Axes] | None = None,
) -> Figure:
    """Fig. 3-style comparison of methods over Monte Carlo runs, two panels (log scale).

    (a) sqrt of the PCRB's location part tr(J^-1)[:2, :2] (m, solid) and velocity part
    tr(J^-1)[2:, 2:] (m/s, dashed), averaged over runs per slot, from each slot's logged J;
    (b) location RMSE (m, solid) and velocity RMSE (m/s, dashed) of target_est against
    target_true over runs per slot. One colour per method. Draws into `axes` = (a, b) if given
    (legend in b), else into a new Figure of PERFORMANCE_SIZE_IN (legend below, a title);
    returns the Figure.
    """
    own = axes is None
    if axes is None:
        fig = new_figure(PERFORMANCE_SIZE_IN)
        ax_bound, ax_err = fig.subplots(1, 2)
    else:
        ax_bound, ax_err = axes
        fig = figure_of(ax_bound)
    method_handles: list[Any] = []
    for i, (method, traces) in enumerate(traces_by_method.items()):
        colour = f"C{i % 10}"
        curves = performance_curves(traces)
        for ax, pos, vel in (
            (ax_bound, "pcrb_pos", "pcrb_vel"),
            (ax_err, "rmse_pos", "rmse_vel"),
        ):
            ax.plot(*curves[pos], "-", color=colour, lw=1.5)
            ax.plot(*curves[vel], "--", color=colour, lw=1.5)
        method_handles.append(
            Line2D([], [], color=colour, lw=1.5, label=f"{method} ({len(traces)} runs)")
        )
    style_handles = [
        Line2D([], [], color="0.3", ls="-", label="location [m]"),
        Line2D([], [], color="0.3", ls="--", label="velocity [m/s]"),
    ]
    for ax, title, ylabel in (
        (ax_bound, "(a) PCRB", "sqrt(PCRB): location [m], velocity [m/s]"),
        (ax_err, "(b) Target state error", "RMSE: location [m], velocity [m/s]"),
    ):
        ax.set_title(title)
        ax.set_xlabel("slot n")
        ax.set_ylabel(ylabel)
        ys = [np.asarray(line.get_ydata(), dtype=float) for line in ax.get_lines()]
        if any(np.any(np.isfinite(y) & (y > 0)) for y in ys):
            ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    if not own:
        ax_err.legend(handles=method_handles + style_handles, fontsize=8)
        return fig
    fig.legend(
        handles=method_handles + style_handles,
        loc="outside lower center",
        ncols=min(6, len(method_handles) + 2),
        fontsize=8,
    )
    fig.suptitle("Sensing performance over Monte Carlo runs")
    return fig


def read_tracks_trace(path: str | Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """(config, slot lines) of a trace (`read_trace`; its `end` lines left out)."""
    trace = read_trace(path)
    return dict(trace.config), [dict(line.line) for line in trace.lines]


def is_tracks_trace(path: str | Path) -> bool:
    """Whether the trace at `path` is a tracker's of several tracks (its slot lines are not the
    labelled target's slot records); False for a file without a complete first line."""
    with Path(path).open("rb") as f:
        if not f.readline().endswith(b"\n"):
            return False
    return not read_trace(path).labelled


def plot_tracks(
    config: Mapping[str, Any], slots: Sequence[Mapping[str, Any]], ax: Axes | None = None
) -> Figure:
    """Draw one run of a tracks trace: the UAVs' paths, the true targets' paths, and every
    track's estimates by ID (confirmed: dots, tentative: crosses), over the BSs; config and slot
    lines as `read_tracks_trace` gives them. Into `ax` if given, else a new Figure of
    TRACKS_SIZE_IN; returns the Figure."""
    if ax is None:
        ax = new_figure(TRACKS_SIZE_IN).add_subplot()
    bs = np.asarray(config.get("bs_xy", []), dtype=float).reshape(-1, 2)
    ax.scatter(bs[:, 0], bs[:, 1], marker="^", c="black", s=40, label="BS")
    uav = np.array([s["uav_xy"] for s in slots], dtype=float)  # [N, M, 2]
    for m in range(uav.shape[1]):
        ax.plot(uav[:, m, 0], uav[:, m, 1], c="0.55", lw=1, label="UAVs" if m == 0 else None)
    truth: dict[int, list[list[float]]] = defaultdict(list)
    for s in slots:
        for t in s["targets"]:
            truth[int(t["index"])].append(t["state"][:2])
    names = [t.get("name", f"target-{i}") for i, t in enumerate(config.get("targets", []))]
    for i, path in sorted(truth.items()):
        xy = np.array(path, dtype=float)
        label = names[i] if i < len(names) else f"target {i}"
        ax.plot(xy[:, 0], xy[:, 1], c="black", lw=2.2, alpha=0.35)
        ax.annotate(label, xy[-1], fontsize=8)
    tracks: dict[int, list[tuple[float, float, bool]]] = defaultdict(list)
    for s in slots:
        for t in s["tracks"]:
            tracks[int(t["id"])].append((t["x"][0], t["x"][1], bool(t["confirmed"])))
    for k, (track_id, points) in enumerate(sorted(tracks.items())):
        xy = np.array([(x, y) for x, y, _ in points], dtype=float)
        confirmed = np.array([c for _, _, c in points], dtype=bool)
        colour = f"C{k % 10}"
        ax.scatter(xy[confirmed, 0], xy[confirmed, 1], s=8, c=colour, label=f"track {track_id}")
        ax.scatter(xy[~confirmed, 0], xy[~confirmed, 1], s=14, c=colour, marker="x")
    area = config.get("area")
    if area is not None:
        ax.set_xlim(0, float(area[0]))
        ax.set_ylim(0, float(area[1]))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{config.get('method', '')}: targets (grey), tracks by ID (x: tentative)")
    ax.legend(fontsize=7, loc="upper right", ncol=2)
    return figure_of(ax)


def save_tracks_png(trace: str | Path, out: str | Path, dpi: int = DEFAULT_DPI) -> Path:
    """Read a tracks trace and write its picture as a PNG; returns the path."""
    config, slots = read_tracks_trace(trace)
    return save_png(plot_tracks(config, slots), out, dpi=dpi)


def save_plots(
    traces: Mapping[str, Sequence[Path]],
    out_dir: Path,
    labels: Mapping[str, str] | None = None,
) -> list[Path]:
    """Write the plots of each method's traces (runs 0.. in order) under out_dir; returns their
    paths. Tracks traces: each method's first run's picture, tracks_<method>.png. The labelled
    target's traces: Fig. 2's trajectories and bandwidth of `proposed`'s first run (else the
    first method's), fig2a_trajectories.png and fig2b_bandwidth.png, and Fig. 3 over every run,
    fig3_performance.png, its methods named by `labels` (else by name)."""
    methods = list(traces)
    written: list[Path] = []
    tracks = [m for m in methods if is_tracks_trace(traces[m][0])]
    for m in tracks:
        written.append(save_tracks_png(traces[m][0], out_dir / f"tracks_{m}.png"))
    labelled = [m for m in methods if m not in tracks]
    if not labelled:
        return written
    names = labels or {}
    first = "proposed" if "proposed" in labelled else labelled[0]
    run0 = read_trace(traces[first][0])
    performance = plot_performance(
        {names.get(m, m): [read_trace(p) for p in traces[m]] for m in labelled}
    )
    return [
        *written,
        save_png(plot_trajectories(run0), out_dir / "fig2a_trajectories.png"),
        save_png(plot_bandwidth(run0), out_dir / "fig2b_bandwidth.png"),
        save_png(performance, out_dir / "fig3_performance.png"),
    ]


__all__ = [
    "BANDWIDTH_SIZE_IN",
    "DEFAULT_DPI",
    "PERFORMANCE_SIZE_IN",
    "TRACKS_SIZE_IN",
    "TRAJECTORY_SIZE_IN",
    "figure_of",
    "is_tracks_trace",
    "new_figure",
    "performance_curves",
    "plot_bandwidth",
    "plot_performance",
    "plot_tracks",
    "plot_trajectories",
    "read_tracks_trace",
    "save_plots",
    "save_png",
    "save_tracks_png",
]
