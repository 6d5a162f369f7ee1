"""Python's cyclic garbage collector during the per-scan loop (issue 13 item 1; docs/speed.md, pass gc27).

CPython collects its youngest generation whenever the number of tracked containers (lists, dicts, tuples, class
instances, …) allocated minus those freed since the last collection exceeds generation 0's threshold, 700 by
default. The pipeline keeps a few thousand young containers alive from scan to scan (the tracker's detections,
tracks and boxes, the evidence ledger's entries), so each of those collections walks them all — 250–330 µs each,
about 20 per 434 scans of negative_2 /right_scan, ≈ 10–15 µs per scan — and finds no garbage there (0 objects
collected; 28 in 1988 scans of MIT CSAIL): the pipeline's per-scan objects are freed by reference counting, not
by the collector. :func:`scan_loop_gc` raises generation 0's threshold for the duration of the loop and puts the
previous thresholds back afterwards.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

#: Generation 0's threshold during :func:`dynslam2d.pipeline.run`'s per-scan loop, in allocations (tracked
#: containers allocated minus those freed since the last young collection; CPython's default is 700).
SCAN_LOOP_GC_THRESHOLD0 = 10_000


@contextmanager
def scan_loop_gc(threshold0: int | None = SCAN_LOOP_GC_THRESHOLD0) -> Iterator[bool]:
    """Raise the cyclic garbage collector's generation-0 threshold to ``threshold0`` allocations while the block
    runs, and restore the previous thresholds when it ends (also when it raises).

    Only generation 0's threshold changes (generations 1 and 2 keep theirs: they count young collections, so
    they also run about ``threshold0`` / 700 times less often). Nothing is changed when ``threshold0`` is None
    or not positive, when the collector is disabled (``gc.disable()`` or a zero threshold), or when the
    threshold already is ``threshold0`` or more (a cold command-line run's compile setting,
    :data:`dynslam2d.jitcache.COMPILE_GC_THRESHOLD`). On leaving, the previous thresholds come back unless code
    inside the block set others (those are left). Garbage in reference cycles then waits for up to
    ``threshold0`` allocations instead of 700 before it is freed; nothing the pipeline computes depends on it.
    Yields whether it changed the thresholds."""
    before = gc.get_threshold()
    if threshold0 is None or threshold0 <= 0 or not gc.isenabled() or before[0] <= 0 or before[0] >= threshold0:
        yield False
        return
    mine = (int(threshold0), *before[1:])
    gc.set_threshold(*mine)
    try:
        yield True
    finally:
        if gc.get_threshold() == mine:
            gc.set_threshold(*before)
