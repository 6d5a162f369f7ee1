"""Whether numba's on-disk cache holds the project's compiled kernels.

Every kernel is ``@njit(cache=True)``: the first run after an install or an edit of a
kernel module compiles them (tens of seconds), later runs load them from numba's cache
(``__pycache__/*.nbi`` index + ``*.nbc`` data beside the source, or ``NUMBA_CACHE_DIR``).
The command line uses :func:`kernel_cache_state` to say "compiling kernels" instead of
reporting a misleading speed for such a run.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass


@dataclass(frozen=True)
class KernelCacheState:
    """Cached kernels among the loaded ones (module-level numba dispatchers of dynslam2d)."""

    total: int
    cached: int

    @property
    def missing(self) -> int:
        return self.total - self.cached

    @property
    def cold(self) -> bool:
        """True when at least a quarter of the kernels must be compiled: a first run, or one
        after an update. A few kernels that no run has needed yet do not count as cold."""
        return self.total > 0 and 4 * self.missing >= self.total


def _has_valid_index(dispatcher: object) -> bool | None:
    """Whether numba's cache index of ``dispatcher`` exists and matches its source file
    (numba drops an index whose source stamp differs); None if this cannot be told."""
    cache = getattr(dispatcher, "_cache", None)
    cache_file = getattr(cache, "_cache_file", None)
    load = getattr(cache_file, "_load_index", None)  # numba internals: fail soft if they change
    if load is None:
        return None
    try:
        return bool(load())
    except Exception:
        return None


def kernel_cache_state(prefix: str = "dynslam2d") -> KernelCacheState:
    """Count the module-level numba kernels of the loaded ``prefix`` modules and those whose
    compiled code numba's cache holds (import the pipeline first to load them all)."""
    try:
        from numba.core.registry import CPUDispatcher
    except ImportError:  # pragma: no cover - numba is a dependency
        return KernelCacheState(0, 0)
    total = cached = 0
    for name, module in list(sys.modules.items()):
        if module is None or not (name == prefix or name.startswith(prefix + ".")):
            continue
        for obj in list(vars(module).values()):
            if isinstance(obj, CPUDispatcher) and getattr(obj, "__module__", None) == name:
                state = _has_valid_index(obj)
                if state is None:
                    continue
                total += 1
                cached += state
    return KernelCacheState(total, cached)
