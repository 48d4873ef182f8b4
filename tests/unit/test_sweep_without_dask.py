"""Dask is optional (`pip install 'isac-mission[sweep]'`): the sweep package imports without it,
and asking for a cluster without it says which extra to install."""

from __future__ import annotations

import sys

import pytest

from isac_mission.errors import MissingDependencyError
from isac_mission.experiment.sweep.cluster import SWEEP_EXTRA, dask_client, require_dask


@pytest.mark.parametrize("missing", ["dask", "distributed"])
def test_a_cluster_without_dask_names_the_extra(
    monkeypatch: pytest.MonkeyPatch, missing: str
) -> None:
    monkeypatch.setitem(sys.modules, missing, None)  # `import missing` now raises ImportError
    with pytest.raises(MissingDependencyError, match=r"isac-mission\[sweep\]") as info:
        require_dask()
    assert "--serial" in str(info.value)
    with pytest.raises(MissingDependencyError, match=r"isac-mission\[sweep\]"), dask_client():
        pass
    assert SWEEP_EXTRA == "isac-mission[sweep]"
