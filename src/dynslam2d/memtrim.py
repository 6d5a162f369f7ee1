"""Give freed heap memory back to the operating system between the phases of a run.

glibc's allocator keeps freed memory in its heap after large temporary arrays are released (its
mmap threshold grows with the largest freed block, up to 32 MiB, so later arrays of that size come
from the heap and stay there): after a whole log the heap holds tens of MiB of free space, which the
clean-up pass and the figures then stack on top of (issue 13 item 3). ``malloc_trim(0)`` returns
it (:func:`release_free_memory`), and a fixed mmap threshold keeps map-sized arrays out of the heap in the first
place (:func:`map_large_blocks`); elsewhere (macOS, musl, Windows) both are no-ops.
"""

from __future__ import annotations

import ctypes
import sys
from collections.abc import Callable
from functools import cache


@cache
def _glibc(name: str, *argtypes: type) -> Callable[..., int] | None:
    """glibc's function ``name`` (returning int) with these argument types; None elsewhere."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        # the process's own symbols (libc's among them): no ``ctypes.util.find_library``, which runs ldconfig in a
        # subprocess (~6 ms before the first scan, now that the command line calls this at start)
        fn = getattr(ctypes.CDLL(None), name)  # glibc only
    except (OSError, AttributeError):
        return None
    fn.argtypes = list(argtypes)
    fn.restype = ctypes.c_int
    return fn  # type: ignore[no-any-return]


#: glibc ``mallopt`` parameters (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: Blocks from this size on get their own mapping, returned to the OS when freed (:func:`map_large_blocks`).
MMAP_THRESHOLD_BYTES = 4 * 1024 * 1024
#: Free memory at the heap's top that glibc keeps rather than returning it at once (:func:`map_large_blocks`). 3 MiB:
#: with 8 MiB up to that much freed memory stayed resident at the heap's top under MIT CSAIL's last peaks (the loop
#: closure's pose-graph solve); 3 MiB lowers the peak by about 1 MiB for about 7 more page faults a scan in the
#: run loop, 1 MiB by a little more for twice the faults (docs/speed.md, pass mem120).
TRIM_THRESHOLD_BYTES = 3 * 1024 * 1024


def map_large_blocks(threshold: int = MMAP_THRESHOLD_BYTES, trim: int = TRIM_THRESHOLD_BYTES) -> bool:
    """Fix glibc's mmap threshold at ``threshold`` bytes (and its trim threshold at ``trim``) for this process.

    By default glibc raises its mmap threshold to the size of every mapped block that is freed (up to 32 MiB), so
    after the first map-sized array is let go, arrays of up to that size come from the heap, and a freed one
    stays in the process wherever a live block sits above it: on MIT CSAIL the heap held 25–40 MiB of free
    memory at the run loop's end. With the threshold fixed, every block of ``threshold`` bytes or more is its
    own mapping and goes back to the OS when freed; smaller ones (a scan's arrays) stay on the heap as before.
    4 MiB: a lower threshold also maps the few 0.5–4 MiB arrays some scans make, and their page faults cost
    MIT CSAIL about 2 % per scan (512 KiB: 2 % slower for 4 MiB less peak; docs/speed.md "Memory, eighth pass").
    The fixed trim threshold keeps the heap's top from being returned and taken back after every scan (with the
    threshold fixed, glibc no longer raises it either). Process-wide and for the rest of the process: the
    command line calls it (it owns the process); a library user's process is left as it is. Returns whether
    the allocator took both settings (False elsewhere than glibc)."""
    fn = _glibc("mallopt", ctypes.c_int, ctypes.c_int)
    if fn is None:
        return False
    return bool(fn(_M_MMAP_THRESHOLD, int(threshold))) and bool(fn(_M_TRIM_THRESHOLD, int(trim)))


def release_free_memory() -> bool:
    """Return the allocator's free heap memory to the OS; True if the allocator supports it."""
    fn = _glibc("malloc_trim", ctypes.c_size_t)
    if fn is None:
        return False
    fn(0)
    return True


__all__ = ["map_large_blocks", "release_free_memory"]
