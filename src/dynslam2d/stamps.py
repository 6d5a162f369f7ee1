"""Nearest-stamp lookup, the one association rule every evaluation uses.

Ties go to the earlier stamp (evo's rule). Stamps in s.
"""

from __future__ import annotations

import numpy as np


def nearest_sorted(sorted_stamps: np.ndarray, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each ``query`` stamp: the index of the nearest of ``sorted_stamps`` (non-decreasing,
    non-empty) and the absolute time difference, s."""
    s = np.asarray(sorted_stamps, dtype=np.float64)
    q = np.asarray(query, dtype=np.float64)
    k = np.searchsorted(s, q, side="left")
    lo = np.clip(k - 1, 0, s.size - 1)
    hi = np.clip(k, 0, s.size - 1)
    d_lo = np.abs(q - s[lo])
    d_hi = np.abs(s[hi] - q)
    take_hi = d_hi < d_lo
    return np.where(take_hi, hi, lo).astype(np.int64), np.where(take_hi, d_hi, d_lo)


def match_nearest(query: np.ndarray, pool: np.ndarray, max_dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Pair each ``query`` stamp with the nearest ``pool`` stamp (any order) within ``max_dt`` s.

    Returns ``(query indices, pool indices)`` of the pairs kept (both int64).
    """
    pool = np.asarray(pool, dtype=np.float64)
    if pool.size == 0 or np.asarray(query).size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.argsort(pool, kind="stable")
    idx, dist = nearest_sorted(pool[order], query)
    ok = dist <= max_dt
    return np.flatnonzero(ok), order[idx[ok]]
