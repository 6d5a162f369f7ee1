"""Pass mem63 (issue 13 item 3): the clean-up counter's tile pool (slam/cleanup.py ``VisibilityCounter``) is made
anew only when the counted extent grows, with a row for every tile of the extent in zeroed memory of its own (its
unwritten rows take no memory), instead of growing by a scan's beams or a quarter with a copy each time (MIT CSAIL:
283 copies, heap blocks of up to 5 MiB). The counts themselves are checked against the former path in
tests/test_cleanup_counter_speed.py."""

from __future__ import annotations

from conftest import room_box_scan

from dynslam2d.slam.cleanup import VisibilityCounter
from dynslam2d.types import Pose2D


def test_the_pool_is_made_anew_only_when_the_extent_grows() -> None:
    """A pose that drifts across a room: after every scan the pool holds a row for
    each tile of the extent, is the same array as long as the extent keeps its tiles, and its rows past those in
    use are zero."""
    counter = VisibilityCounter(0.05)
    pools, grown = 0, 0
    prev_pool, prev_tiles = None, -1
    for k in range(60):
        pose = Pose2D(2.0 + 0.12 * k, 3.0 + 0.05 * k, 0.03 * k)
        counter.add(room_box_scan(pose, (8.0, 5.0, 1.0, 1.0), 0.1 * k, seed=k), pose)
        pool, tiles = counter._pool, counter._table.size
        assert pool.shape[0] == tiles and 0 < counter._n_tiles < tiles
        assert not pool[counter._n_tiles:].any()
        if pool is not prev_pool:
            pools += 1
            assert tiles != prev_tiles  # (a new pool only with a new extent)
        grown += tiles != prev_tiles
        prev_pool, prev_tiles = pool, tiles
    assert 1 <= pools <= grown
    assert counter.resident_bytes == counter._n_tiles * 2048 + counter._table.nbytes
