"""`sharedctl faults montecarlo`: a Monte-Carlo of fault cases, run in chunks on a Dask cluster."""
