"""bench_parts_ab.py's split of "unattributed" (pass prc124): the counted wrapper returns what the wrapped call
returns, counts each tag's calls and times them; the calibrated cost of a wrapper outside its window is positive."""

from __future__ import annotations

import collections
import math
import sys
from pathlib import Path


def test_counted_wrapper_counts_and_times_each_tag_and_its_outside_cost_is_calibrated() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_parts_ab import HARNESS, MOVERS, OWN, _counted_wrapper, _wrapper_cost

    class Obj:
        def f(self, a: int, b: int = 0) -> int:
            return sum(range(a)) + b

        def g(self) -> str:
            return "g"

    acc: collections.Counter = collections.Counter()
    calls: collections.Counter = collections.Counter()
    wrap = _counted_wrapper(acc, calls)
    o = Obj()
    wrap(o, "f", "F")
    wrap(o, "g", "G")
    assert [o.f(10, b=2), o.f(3), o.g()] == [47, 3, "g"]
    assert dict(calls) == {"F": 2, "G": 1}
    assert set(acc) == {"F", "G"} and all(v >= 0 for v in acc.values())
    cost = _wrapper_cost(_counted_wrapper, n=200, reps=5)
    assert math.isfinite(cost) and cost > 0.0
    # (the sub-parts of "unattributed" are printed indented, after the top-level parts)
    assert all(t.startswith("  ") and t.strip() != t for t in (HARNESS, MOVERS, OWN))
