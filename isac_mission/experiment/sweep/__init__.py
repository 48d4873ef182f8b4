"""Monte Carlo studies over parameter grids (`isac-mission sweep CONFIG --grid GRID.yaml`).

One module per job, imported by name (this package re-exports nothing):

- `grid`: the grid file (dotted scenario paths -> values, methods, runs, seed, slots), its
  validation and the grid points (every point validated before any work starts);
- `runs`: the tasks (grid point x method x run, noise seed = seed + run), one closed-loop run per
  task with BLAS limited to one thread (threadpoolctl), of one target or of several (the
  multi-target loop and its figures; a method that plans one target only is refused before any
  work), the serial runner;
- `summary`: aggregates per (point, method) with 95 % t-intervals (GOSPA, and a multi-target
  point's figures from `multi_target_metrics`), the CSV files, the table;
- `plots`: RMSE- and GOSPA-vs-parameter Figures (the caller saves them);
- `cluster`: the Dask runner (optional extra `isac-mission[sweep]`, imported lazily).
"""
