"""The multi-target picture of one run (docs/trace.md, "Multi-target traces"): the UAVs' paths,
the true targets' paths, and every track's estimates by ID (confirmed: dots, tentative: crosses),
over the BSs. Like experiment/plots.py: a Figure on an Agg canvas (no pyplot), drawn into the
axes given or a new one; `save_png` writes it.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from isac_mission.experiment.plots import DEFAULT_DPI, figure_of, new_figure, save_png
from isac_mission.records.jsonlines import loads_line

TRACKS_SIZE_IN: Final[tuple[float, float]] = (8.0, 7.0)


def read_multi_target_trace(path: str | Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """(config, slot lines) of a multi-target trace (its `end` lines left out)."""
    lines = Path(path).read_text().splitlines()
    head = loads_line(lines[0])
    parsed = [dict(loads_line(line)) for line in lines[1:] if line]
    return dict(head["config"]), [line for line in parsed if "end" not in line]


def plot_tracks(
    config: Mapping[str, Any], slots: Sequence[Mapping[str, Any]], ax: Axes | None = None
) -> Figure:
    """Draw one run: config and slot lines as `read_multi_target_trace` gives them."""
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
    """Read a multi-target trace and write its picture as a PNG; returns the path."""
    config, slots = read_multi_target_trace(trace)
    return save_png(plot_tracks(config, slots), out, dpi=dpi)
