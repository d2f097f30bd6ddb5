"""The results room, below the queries and the sampling: what one sample leaves (``outcome``:
its initial state and its rollouts' results, common fields and one mapping of query values) and the
statistics answers are made of (``stats``: intervals, circular statistics). It imports nothing of
the engine's, so queries read samples and the sampling makes them without either importing the other.
"""
