"""Monte Carlo studies over parameter grids (`isac-mission sweep CONFIG --grid GRID.yaml`).

One module per job, imported by name (this package re-exports nothing):

- `grid`: the grid file (dotted scenario paths -> values, methods, runs, seed, slots), its
  validation and the grid points (every point validated before any work starts);
- `runs`: the tasks (grid point x method x run, noise seed = seed + run), one closed-loop run per
  task with BLAS limited to one thread (threadpoolctl), the serial runner;
- `summary`: aggregates per (point, method) with 95 % t-intervals, the CSV files, the table;
- `plots`: RMSE-vs-parameter Figures (the caller saves them);
- `cluster`: the Dask runner (optional extra `isac-mission[sweep]`, imported lazily).
"""
