"""The clean-up counter's fused, branch-free counting (issue 13, the CLI's time per scan) gives the counts of the
former code path: numpy-masked hit and clearing ends and the branching per-cell ray walk (kept here as the
reference), on simulated scans and on negative_2's /right_scan when the shared data is there."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import paper_room_scan, room_box_scan
from numba import njit

from dynslam2d.slam.cleanup import COUNT_MAX, VisibilityCounter
from dynslam2d.types import Pose2D


@njit(cache=False)
def _reference_count(counts, last, scan_id, ox, oy, hx, hy, cx, cy, core):  # pragma: no cover - numba
    """The counting kernel before this pass (branching per cell), verbatim."""
    h = counts.shape[0]
    w = counts.shape[1]
    hit_code = 2 * scan_id + 1
    for k in range(hx.shape[0]):
        ix = int(math.floor(hx[k] + 0.5))
        iy = int(math.floor(hy[k] + 0.5))
        if 0 <= ix < w and 0 <= iy < h:
            lt = last[iy, ix]
            if lt != hit_code:
                if lt != 0 and (lt & 1) == 0 and counts[iy, ix, 2] < COUNT_MAX:
                    counts[iy, ix, 2] += 1
                last[iy, ix] = hit_code
                if counts[iy, ix, 0] < COUNT_MAX:
                    counts[iy, ix, 0] += 1
    for k in range(cx.shape[0]):
        dx = cx[k] - ox
        dy = cy[k] - oy
        x_major = abs(dx) >= abs(dy)
        if x_major:
            a0 = int(math.floor(ox + 0.5))
            a1 = int(math.floor(cx[k] + 0.5))
            slope = dy / dx if dx != 0.0 else 0.0
            m0 = ox
            n0 = oy
        else:
            a0 = int(math.floor(oy + 0.5))
            a1 = int(math.floor(cy[k] + 0.5))
            slope = dx / dy
            m0 = oy
            n0 = ox
        step = 1 if a1 >= a0 else -1
        a = a0
        while True:
            b = n0 + slope * (a - m0)
            ib = int(math.floor(b + 0.5))
            if abs(b - ib) <= core:
                if x_major:
                    x = a
                    y = ib
                else:
                    x = ib
                    y = a
                if 0 <= x < w and 0 <= y < h:
                    lt = last[y, x]
                    if (lt >> 1) != scan_id:
                        if (lt & 1) == 1 and counts[y, x, 2] < COUNT_MAX:
                            counts[y, x, 2] += 1
                        last[y, x] = 2 * scan_id
                        if counts[y, x, 1] < COUNT_MAX:
                            counts[y, x, 1] += 1
            if a == a1:
                break
            a += step


class _ReferenceCounter(VisibilityCounter):
    """:meth:`VisibilityCounter.add` as it was: masked numpy copies into the reference kernel, on dense count
    arrays over the counted extent (grown as the tiled counter grows its extent)."""

    def __init__(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        super().__init__(*args, **kwargs)
        self._cells = np.zeros((0, 0, 3), dtype=np.uint16)
        self._last = np.zeros((0, 0), dtype=np.uint16)

    def _ensure(self, imin, jmin, imax, jmax):  # type: ignore[no-untyped-def]
        i0, j0, (h, w) = self.i0, self.j0, self.shape
        if not super()._ensure(imin, jmin, imax, jmax):
            return False
        if self.shape != (h, w):
            cells = np.zeros((*self.shape, 3), dtype=np.uint16)
            last = np.zeros(self.shape, dtype=np.uint16)
            cells[j0 - self.j0:j0 - self.j0 + h, i0 - self.i0:i0 - self.i0 + w] = self._cells
            last[j0 - self.j0:j0 - self.j0 + h, i0 - self.i0:i0 - self.i0 + w] = self._last
            self._cells, self._last = cells, last
        return True

    def add(self, scan, pose, removed=None):  # type: ignore[no-untyped-def]
        res = self.resolution
        valid = self._valid(scan)
        if not valid.any():
            self.scans += 1
            return
        ex, ey, cx, cy, kept, clear = self._geometry(scan, pose, valid, removed)
        ox, oy = pose.x / res, pose.y / res
        if not self._ensure(*self._cell_bounds(ox, oy, ex, ey, valid)):
            self.too_large += 1
            return
        assert self.scans + 1 < 32767
        _reference_count(self._cells, self._last, self.scans + 1, ox - self.i0, oy - self.j0, ex[kept] - self.i0,
                         ey[kept] - self.j0, cx[clear] - self.i0, cy[clear] - self.j0, float(self.config.ray_core))
        self.scans += 1


def _assert_same(feed) -> VisibilityCounter:  # type: ignore[no-untyped-def]
    new, ref = VisibilityCounter(0.05), _ReferenceCounter(0.05)
    for scan, pose, removed in feed:
        new.add(scan, pose, removed)
        ref.add(scan, pose, removed)
    assert (new.i0, new.j0, new.shape) == (ref.i0, ref.j0, ref._last.shape)
    for a, b in ((new.hits, ref._cells[:, :, 0]), (new.through, ref._cells[:, :, 1]),
                 (new.switches, ref._cells[:, :, 2]), (new.last_touch(), ref._last)):
        np.testing.assert_array_equal(a, b)
    # the tiles hold only where beams ended or passed: every allocated tile has a counted cell
    assert new._n_tiles < new._table.size and new.resident_bytes <= new._table.size * 2048 + new._table.nbytes
    assert all(new._pool[t].any() for t in range(new._n_tiles))
    return new


def test_counts_match_the_former_path_on_simulated_scenes():
    """A box that leaves and comes back (hits, passes, switches), beams marked removed, and the paper room seen
    from a moving pose: every count grid and the latest-touch array are those of the former path."""
    rng = np.random.default_rng(5)
    feed = []
    for k in range(40):
        pose = Pose2D(3.0 + 0.1 * k, 4.0 + 0.03 * k, 0.02 * k)
        box = (8.0, 5.0, 1.0, 1.0) if (k // 10) % 2 == 0 else (8.0, 8.5, 1.0, 0.6)
        scan = room_box_scan(pose, box, 0.1 * k, seed=k)
        removed = rng.random(scan.ranges.shape[0]) < 0.1
        feed.append((scan, pose, removed))
    for k in range(20):
        pose = Pose2D(1.0 + 0.2 * k, 1.0 + 0.1 * k, -0.05 * k)
        feed.append((paper_room_scan(pose, 10.0 + 0.1 * k), pose, None))
    counter = _assert_same(feed)
    assert counter.switches.sum() > 100 and counter.through.max() > 30 and counter.hits.sum() > 1000


def test_counts_match_the_former_path_on_negative_2(shared_data):
    """negative_2's first 300 /right_scan scans (real returns: gaps, mixed pixels, people) at a slowly drifting
    pose (the SLAM's own poses would take a whole run; any poses exercise the same walk)."""
    bag = shared_data / "dynamic" / "leg_tracker" / "negative_2.bag"
    if not bag.exists():
        pytest.skip(f"negative_2 not in the shared data ({bag})")
    from itertools import islice

    from dynslam2d.inputs import open_source

    src = open_source(str(bag), topic="/right_scan")
    feed = [(scan, Pose2D(0.01 * k, -0.005 * k, 0.002 * k), None) for k, scan in enumerate(islice(iter(src), 300))]
    counter = _assert_same(feed)
    assert counter.through.sum() > 10000
