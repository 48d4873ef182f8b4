"""Monte Carlo studies over parameter grids (`isac-mission sweep CONFIG --grid GRID.yaml`).

One module per job, imported by name (this package re-exports nothing):

- `grid`: the grid file (dotted scenario paths -> values, methods, runs, seed, slots), its
  validation and the grid points (every point validated before any work starts);
- `runs`: the tasks (grid point x method x run, noise seed = seed + run), one run per task flown
  and measured as `simulate` flies one (experiment/runs.py), with BLAS limited to one thread
  (threadpoolctl); a method that cannot plan for a point's tracks is refused before any work;
  the serial runner;
- `summary`: aggregates per (point, method) with 95 % t-intervals (GOSPA, and the tracks'
  figures of a point without a labelled track, from `track_metrics`), the CSV files, the table;
- `plots`: RMSE- and GOSPA-vs-parameter Figures (the caller saves them);
- `cluster`: the Dask runner (optional extra `isac-mission[sweep]`, imported lazily).
"""
