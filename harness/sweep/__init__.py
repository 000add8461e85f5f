"""Benchmark sweeps: suites with sweep axes expanded into cached, resumable jobs, run
serially, in a pool of spawned processes, or on Dask."""
