"""Thread-CPU timers wrapped around named functions, shared by the per-part benchmarks (not run by pytest).

``bench_pipeline_ab.py --parts``, ``bench_parts_ab.py`` and ``bench_tracker_ab.py`` time the parts of one
``Pipeline.process`` by replacing each part (a method, a module function, a kernel's dispatcher) with a wrapper
that adds the thread CPU time of every call to a counter under the part's tag.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable
from typing import Any


def thread_cpu_wrapper(acc: collections.Counter,
                       calls: collections.Counter | None = None) -> Callable[[Any, str, str], None]:
    """``wrap(obj, attr, tag)``: replace ``obj.attr`` by a call that adds its thread CPU ns to ``acc[tag]`` and, with
    ``calls``, counts each tag's calls there (outside the timed window)."""

    def wrap(obj: Any, attr: str, tag: str) -> None:
        f = getattr(obj, attr)

        def timed(*a: Any, **k: Any) -> Any:
            if calls is not None:
                calls[tag] += 1
            t0 = time.thread_time_ns()
            r = f(*a, **k)
            acc[tag] += time.thread_time_ns() - t0
            return r

        setattr(obj, attr, timed)

    return wrap
