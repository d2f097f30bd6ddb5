"""The compute room: where samples run and where their results are kept.

``pool`` (worker processes: forkserver, crash-tolerant, a map), ``cluster`` (the same map on Dask),
``store`` (a resumable store of results on disk, written only inside itself). Each is a
``map(fn, items, on_lost=...)`` the Monte Carlo loop is given; none knows what it runs.
"""
