"""What both checks share: the trace (a file, or anything with `.config` and `.slots`) and
its config values, named when missing. numpy only; `isac_mission.records` for the file format."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


class TraceLike(Protocol):
    """A trace: the config mapping and the slot records (docs/trace.md field names)."""

    @property
    def config(self) -> dict[str, Any]: ...

    @property
    def slots(self) -> Sequence[Any]: ...


def as_trace(trace: Any) -> TraceLike:
    """trace itself, or the trace read from a path."""
    if isinstance(trace, str | Path):
        from isac_mission.records import read_trace  # the file format only

        return read_trace(trace)
    return trace  # type: ignore[no-any-return]


def config_value(config: Mapping[str, Any], key: str) -> Any:
    """config[key], or ValueError naming the key the check needs."""
    if key not in config:
        raise ValueError(f"trace config lacks {key!r}, which the check needs")
    return config[key]
