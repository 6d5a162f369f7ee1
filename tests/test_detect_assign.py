"""The association's assignment kernel (detect/kernels_assign.py) against SciPy's solver and the numpy glue it
replaces (docs/speed.md, pass trk21)."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.detect.kernels_assign import LSAP_INFEASIBLE, LSAP_INVALID, LSAP_OK, assign_groups, lsap
from dynslam2d.detect.lsap import linear_sum_assignment

_BIG = 1e12


def _matrices(rng: np.random.Generator):
    """Square, wide and tall matrices: continuous costs, small integer costs (many ties), constant ones, and gated
    costs with the tracker's large value."""
    for _ in range(400):
        nr, nc = int(rng.integers(1, 12)), int(rng.integers(1, 12))
        kind = int(rng.integers(0, 4))
        if kind == 0:
            c = rng.random((nr, nc)) * 30.0
        elif kind == 1:
            c = rng.integers(0, 4, (nr, nc)).astype(float)
        elif kind == 2:
            c = np.full((nr, nc), 2.5)
        else:
            c = np.where(rng.random((nr, nc)) < 0.6, _BIG, rng.random((nr, nc)) * 9.0)
        yield c


def test_lsap_matches_scipy_bit_for_bit():
    rng = np.random.default_rng(13)
    for c in _matrices(rng):
        status, r, k = lsap(c)
        r2, k2 = linear_sum_assignment(c)
        assert status == LSAP_OK
        assert r.dtype == np.int64 and k.dtype == np.int64
        assert np.array_equal(r, r2) and np.array_equal(k, k2), c


def test_lsap_reports_scipy_errors():
    c = np.array([[1.0, np.nan], [0.0, 2.0]])
    assert lsap(c)[0] == LSAP_INVALID
    with pytest.raises(ValueError, match="invalid numeric entries"):
        linear_sum_assignment(c)
    c = np.array([[np.inf, np.inf], [0.0, 2.0]])
    assert lsap(c)[0] == LSAP_INFEASIBLE
    with pytest.raises(ValueError, match="infeasible"):
        linear_sum_assignment(c)
    assert lsap(np.zeros((0, 3)))[0] == LSAP_OK


def _reference(ok: np.ndarray, d2: np.ndarray, firm: np.ndarray) -> tuple[list[int], list[int]]:
    """Tracker._associate's assignment before pass trk21: numpy glue around SciPy's solver, group by group."""
    m = ok.shape[1]
    cost = np.where(ok, d2, _BIG)
    firm_r = [i for i in range(ok.shape[0]) if firm[i]]
    tent_r = [i for i in range(ok.shape[0]) if not firm[i]]
    ti, di = [], []
    taken = None
    for group in (firm_r, tent_r):
        if not group:
            continue
        rows_idx = np.array(group, dtype=np.int64)
        if taken is None:
            cols_idx = None
            sub = cost[rows_idx]
        else:
            cols_idx = (~taken).nonzero()[0]
            sub = cost[rows_idx][:, cols_idx]
        if sub.size == 0:
            continue
        rr, cc = linear_sum_assignment(sub)
        ii = rows_idx[rr]
        jj = cc if cols_idx is None else cols_idx[cc]
        good = ok[ii, jj]
        ti += ii[good].tolist()
        di += jj[good].tolist()
        if group is firm_r and tent_r:
            taken = np.zeros(m, dtype=bool)
            taken[jj[good]] = True
    return ti, di


def test_assign_groups_matches_the_numpy_glue():
    rng = np.random.default_rng(7)
    for _ in range(500):
        n, m = int(rng.integers(1, 14)), int(rng.integers(1, 14))
        ok = rng.random((n, m)) < rng.choice([0.1, 0.3, 0.7])
        d2 = rng.random((n, m)) * 16.0
        if rng.random() < 0.3:
            d2 = np.round(d2)  # ties
        firm = rng.random(n) < rng.choice([0.0, 0.5, 1.0])
        status, ii, jj = assign_groups(ok, d2, firm, _BIG)
        assert status == LSAP_OK
        ti, di = _reference(ok, d2, firm)
        assert ii.tolist() == ti and jj.tolist() == di
        assert ii.dtype == np.int64 and jj.dtype == np.int64
