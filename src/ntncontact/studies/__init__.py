"""Studies of many runs: parameter sweeps on Dask."""
