"""``kernels_update.manage_scan``'s per-track bits (docs/speed.md, pass upd91) against the Python expressions of
``TrackManage._manage`` they replace (main 18c84e1): the structure exit's window mean, clutter retirement's window
minimum and the slow reason's text — and its other outputs against ``manage_counters``'."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.kernels_update import (
    _UP_N,
    AUX_EXIT,
    AUX_NEAR,
    AUX_RETIRE,
    AUX_SLOW_SHIFT,
    C_STATE,
    C_UPD,
    UP_MAX_COAST,
    UP_MAX_POS_SIG,
    UP_MAX_SPEED,
    UP_NEED,
    UP_RETIRE_N,
    UP_RETIRE_S,
    UP_S_EXIT,
    UP_SUSTAIN,
    UP_WINDOW,
    manage_counters,
    manage_scan,
)
from dynslam2d.detect.trackmanage import _slow_reason, _slow_reason_texts


def _rows(rng: np.random.Generator, n: int, w: int) -> tuple:
    """Random state / counter rows and map-evidence windows: fractions on a coarse grid (exact ties with the
    thresholds, sums whose order matters), NaN and -0.0 entries, counts 0 … w, speeds at and near the slow texts'
    rounding ties and above 10 m/s."""
    A = rng.normal(size=(n, 4, 4))
    P = A @ A.transpose(0, 2, 1) * 0.01
    X = rng.normal(size=(n, 4))
    sp = np.concatenate([rng.uniform(0.0, 0.6, n // 2), (np.arange(n - n // 2) % 120 + 0.5) / 100.0])
    sp[::37] = 12.5
    sp[1::41] = 0.0
    ang = rng.uniform(-math.pi, math.pi, n)
    X[:, 2], X[:, 3] = sp * np.cos(ang), sp * np.sin(ang)
    CI = np.zeros((n, 6), dtype=np.int64)
    CI[:, C_STATE] = rng.integers(0, 3, n)
    CI[:, C_UPD] = rng.integers(0, 2, n)
    MEV = rng.choice([0.0, 0.1, 0.25, 0.3, 0.5, 0.55, 0.6, 0.7, 1.0, 1 / 3, 2 / 3], size=(n, w, 3))
    MEV[::13, 0, 0] = np.nan
    MEV[5::29, 2, 0] = np.nan
    MEV[3::31, :, 0] = -0.0
    WN = np.zeros((n, 3), dtype=np.int64)
    WN[:, 0] = rng.integers(0, w + 1, n)
    WN[:, 2] = rng.integers(0, 3, n)
    return P, X, CI, MEV, WN


def test_manage_scan_bits_are_the_former_python_tests() -> None:
    rng = np.random.default_rng(91)
    n, w = 4000, 6
    P, X, CI, MEV, WN = _rows(rng, n, w)
    rows = rng.permutation(n)
    for s_exit, nsus, retire_n, retire_s in ((0.5, 3, 2, 0.55), (0.0, 1, 4, 0.5), (0.7, 5, 0, 0.5), (1.0, 0, 6, 0.0)):
        q = np.zeros(_UP_N)
        q[UP_WINDOW], q[UP_NEED], q[UP_MAX_COAST], q[UP_MAX_SPEED], q[UP_MAX_POS_SIG] = 3, 2, 1.0, np.inf, 1.5
        q[UP_S_EXIT], q[UP_SUSTAIN], q[UP_RETIRE_N], q[UP_RETIRE_S] = s_exit, nsus, retire_n, retire_s
        CI0 = CI.copy()
        out, sig, speed, aux = manage_scan(P, X, CI0, np.zeros(n), WN, MEV, rows, q, 0.0)
        CI1 = CI.copy()
        out1, sig1, speed1, near1 = manage_counters(P, X, CI1, np.zeros(n), WN, rows, q, 0.0)
        assert out.tobytes() == out1.tobytes() and sig.tobytes() == sig1.tobytes()
        assert speed.tobytes() == speed1.tobytes() and CI0.tobytes() == CI1.tobytes()
        aux = aux.tolist()
        assert [a & AUX_NEAR for a in aux] == near1.tolist()
        texts = _slow_reason_texts(1.0)
        tail = f" m/s ≤ v_min {1.0:.2f}"
        n_exit = n_retire = n_fmt = 0
        for i, r in enumerate(rows.tolist()):
            a = aux[i]
            # the structure exit's test as _manage wrote it (on_map true)
            nm = WN.item(r, 0)
            exit_py = bool(nm and nm >= nsus and sum(MEV[r, :nm, 0].tolist()) / nm >= s_exit)
            assert bool(a & AUX_EXIT) == exit_py, (r, nm, MEV[r, :nm, 0])
            n_exit += exit_py
            # clutter retirement's window test as _manage wrote it (retire_n > 0 there)
            ret_py = bool(retire_n and nm >= retire_n and min(MEV[r, nm - retire_n:nm, 0].tolist()) >= retire_s)
            assert bool(a & AUX_RETIRE) == ret_py, (r, nm, MEV[r, :nm, 0])
            n_retire += ret_py
            # the slow reason's text for a speed ≤ v_min (1 m/s here)
            s = speed[i]
            if s <= 1.0:
                si = a >> AUX_SLOW_SHIFT
                got = texts[si - 1] if si and texts else f"not in M: speed {s:.2f}{tail}"
                assert got == _slow_reason(s, texts, tail) == f"not in M: speed {s:.2f}{tail}"
                n_fmt += not si
        assert 0 < n_exit < n and (retire_n == 0 or 0 < n_retire < n) and n_fmt > 0
