"""The correlative search's two per-search kernels give what the array code they replace gave (issue 13, pass
cor98): ``_search_table`` (the score pyramid of a crop of a level's cache written straight into the zero-padded
search table, and the ≤ 1 test) against ``_score_pyramid`` copied into ``np.zeros``, on a reused buffer full of
garbage; ``_search_cells`` against ``_rotated_cells`` less the crop's and the table's offsets; ``_search_points``
(pass cor100) against the subsample divided by the cell size and ``_percentile95`` of ``np.hypot``."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.slam.correlative import (
    _all_rows,
    _percentile95,
    _rotated_cells,
    _score_pyramid,
    _search_cells,
    _search_points,
    _search_table,
    _table_buffer,
    even_indices,
)
from dynslam2d.slam.grid import encode_probs


@pytest.mark.parametrize("pad", [(0, 0, 0, 0), (3, 0, 5, 0), (0, 4, 0, 2), (2, 7, 1, 3), (9, 1, 0, 6)])
@pytest.mark.parametrize("hmax", [0, 1, 3, 4])
def test_search_table_equals_the_pyramid_in_a_zeroed_table(pad: tuple[int, int, int, int], hmax: int) -> None:
    rng = np.random.default_rng(5)
    big = rng.uniform(0.0, 1.0, (60, 80)).astype(np.float32)
    big[rng.uniform(size=big.shape) < 0.3] = 0.5
    big[rng.uniform(size=big.shape) < 0.1] = 1.0
    words = encode_probs(big)
    r0, c0, ch, cw = 7, 11, 33, 41
    top, bottom, left, right = pad
    hh, ww = ch + top + bottom, cw + left + right
    pyr = _score_pyramid(words[r0:r0 + ch, c0:c0 + cw], hmax)
    want = np.zeros((hmax + 1, hh, ww), dtype=np.float32)
    want[:, top:top + ch, left:left + cw] = pyr
    buf = _table_buffer((hmax + 1) * hh * ww + 2 * ch * cw)
    buf[:] = np.nan  # (a buffer a former search wrote: every cell the table holds is written again)
    tab, merge = _search_table(words, r0, c0, ch, cw, hmax, top, left, hh, ww, buf)
    assert tab.shape == ((hmax + 1) * hh * ww,)
    np.testing.assert_array_equal(tab.reshape(want.shape).view(np.int32), want.view(np.int32))  # (bit for bit)
    assert bool(merge) is bool(pyr[0].max() <= 1.0) is True
    over = big.copy()
    over[r0 + 5, c0 + 9] = 1.5  # a value above 1 (not a probability; the ≤ 1 test sees it)
    _, merge = _search_table(encode_probs(over), r0, c0, ch, cw, hmax, top, left, hh, ww, buf)
    assert not merge


@pytest.mark.parametrize("w", [0, 3, 12, 200])
def test_search_cells_are_the_rotated_cells_in_the_table_frame(w: int) -> None:
    rng = np.random.default_rng(6)
    pc = rng.uniform(-150.0, 150.0, (240, 2))
    th = 0.2 + np.arange(-15, 16) * 0.01
    for mx, my in ((400.25, 380.5), (20.0, 300.0), (310.0, 8.5)):  # inside, and near the map's first column / row
        qx, qy, x0, x1, y0, y1 = _rotated_cells(pc, np.cos(th), np.sin(th), mx, my)
        c0 = max(x0 - w - 1, 0)
        r0 = max(y0 - w - 1, 0)
        ox = min(0, x0 - c0 - w)
        oy = min(0, y0 - r0 - w)
        gx, gy, *ext = _search_cells(pc, np.cos(th), np.sin(th), mx, my, w)
        assert tuple(ext) == (x0, x1, y0, y1)
        np.testing.assert_array_equal(gx, qx - c0 - ox)
        np.testing.assert_array_equal(gy, qy - r0 - oy)


@pytest.mark.parametrize("n", [1, 2, 3, 19, 20, 21, 40, 239, 240, 241, 700])
def test_search_points_equal_the_array_code(n: int) -> None:
    rng = np.random.default_rng(n)
    pts = rng.normal(0.0, 6.0, (n, 2))
    pts[rng.uniform(size=n) < 0.3] = pts[0]  # repeated ranges: the order statistics among equal values
    pts[rng.uniform(size=n) < 0.1, 1] = 0.0
    r = 0.05
    idx = even_indices(n, 240) if n > 240 else _all_rows(n)
    pc, p95 = _search_points(pts, idx, r)
    want = pts[idx] / r
    assert pc.tobytes() == want.tobytes()
    assert p95 == _percentile95(np.hypot(want[:, 0], want[:, 1]))
    for _ in range(5):  # the ranges in other orders: ascending, descending, shuffled
        for p in (np.sort(pts, axis=0), pts[::-1].copy(), rng.permutation(pts)):
            got = _search_points(np.ascontiguousarray(p), _all_rows(n), r)[1]
            assert got == _percentile95(np.hypot(p[:, 0] / r, p[:, 1] / r))


def test_table_buffer_keeps_at_most_one_mebibyte() -> None:
    """Pass mem107: the reused search buffer is kept up to 1 MiB (MIT CSAIL's widest searches, ≈ 3 MiB, get arrays
    of their own); a larger kept buffer stays resident all run, on the AOT run's peak memory."""
    import dynslam2d.slam.correlative as correlative

    kept = correlative._BUF[0]
    try:
        for size in (1000, 200_000, 774_150, 2_000_000):
            buf = _table_buffer(size)
            assert buf.shape[0] >= size
            assert correlative._BUF[0].nbytes <= 1 << 20
    finally:
        correlative._BUF[0] = kept
