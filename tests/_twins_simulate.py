"""Slow, obviously correct twins of cutkit.simulate._kernels."""

import numpy as np


def lookup_springs_twin(springs, n, a, b):
    """Spring index of each pair (either orientation), -1 where none or a node >= n."""
    index = {}
    for s, (u, w) in enumerate(np.asarray(springs)):
        index.setdefault((int(u), int(w)), s)
        index.setdefault((int(w), int(u)), s)
    return np.array([index.get((int(u), int(w)), -1) if u < n and w < n else -1 for u, w in zip(a, b)], np.int64)
