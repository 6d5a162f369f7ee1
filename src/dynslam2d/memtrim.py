"""Give freed heap memory back to the operating system between the phases of a run.

glibc's allocator keeps freed memory in its heap after large temporary arrays are released (its
mmap threshold grows with the largest freed block, up to 32 MiB, so later arrays of that size come
from the heap and stay there): after a whole log the heap holds tens of MiB of free space, which the
clean-up pass and the figures then stack on top of (issue 13 item 3). ``malloc_trim(0)`` returns
it; elsewhere (macOS, musl, Windows) this is a no-op.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from collections.abc import Callable
from functools import lru_cache


@lru_cache(maxsize=1)
def _malloc_trim() -> Callable[[int], int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        fn = libc.malloc_trim  # glibc only
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_size_t]
    fn.restype = ctypes.c_int
    return fn  # type: ignore[no-any-return]


def release_free_memory() -> bool:
    """Return the allocator's free heap memory to the OS; True if the allocator supports it."""
    fn = _malloc_trim()
    if fn is None:
        return False
    fn(0)
    return True


__all__ = ["release_free_memory"]
