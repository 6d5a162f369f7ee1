"""Both roles of a lockstep A/B (``bench_pipeline_ab.py``) and their geometric mean (not run by pytest).

A lockstep run is not symmetric: the checkout in the "this" role reads ≈ 2-4 % apart from the same checkout in the
"other" role. ``release_figures.sh`` therefore runs the lockstep twice: this checkout's script with ``--other`` the
previous release (new in the "this" role) and the previous release's own script with ``--other`` this checkout
(new in the "other" role). This reads both outputs and prints, per input and stage, new / previous of each role
(the second role's ratio inverted) and their geometric mean, in which a role's bias cancels:

    python benchmarks/ab_roles.py OUT/ab_2.txt OUT/ab_2s.txt

Inputs only one of the two runs has are listed with one role.
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

_HEAD = re.compile(r"^(\S+): \d+ scans, pipeline CPU ms/scan median: other [\d.]+, this [\d.]+, ratio ([\d.]+)")
_LOADS = re.compile(r"kernels loaded or compiled: other (\d+), this (\d+)")
_MEAN = re.compile(r"^  pipeline CPU ms/scan mean: other [\d.]+, this [\d.]+, ratio ([\d.]+)")
_STAGE = re.compile(r"^  (\w+) +other +[\d.]+ +this +[\d.]+ +ratio ([\d.]+) +mean: .* ratio ([\d.]+)$")


def read(path: Path, loads: dict[str, int] | None = None) -> dict[str, dict[str, tuple[float, float]]]:
    """{input: {"pipeline" or stage: (ratio of the medians, ratio of the means)}} of a ``bench_pipeline_ab.py``
    output, ratios "this" / "other"; adds to ``loads`` the kernels loaded or compiled inside its measured runs per
    input (both sides)."""
    loads = {} if loads is None else loads
    out: dict[str, dict[str, tuple[float, float]]] = {}
    cur: dict[str, tuple[float, float]] | None = None
    median = 0.0
    for line in path.read_text().splitlines():
        if m := _HEAD.match(line):
            cur = out.setdefault(m.group(1), {})
            median = float(m.group(2))
            if lo := _LOADS.search(line):
                loads[m.group(1)] = loads.get(m.group(1), 0) + int(lo.group(1)) + int(lo.group(2))
        elif cur is not None and (m := _MEAN.match(line)):
            cur["pipeline"] = (median, float(m.group(1)))
        elif cur is not None and (m := _STAGE.match(line)):
            cur[m.group(1)] = (float(m.group(2)), float(m.group(3)))
    return out


def both_roles(new_this: Path, new_other: Path) -> list[str]:
    """The table lines: per input and row, new / previous with the new release as "this" (first file), as
    "other" (second file, its ratio inverted) and their geometric mean, for the medians and the means."""
    loads: dict[str, int] = {}
    a, b = read(new_this, loads), read(new_other, loads)
    lines = [f"{'input':<18} {'row':<10} {'median: new this':>16} {'new other':>10} {'geomean':>8}   "
             f"{'mean: new this':>14} {'new other':>10} {'geomean':>8}"]
    logs: list[tuple[float, float]] = []
    for name in list(a) + [n for n in b if n not in a]:
        rows = list(a.get(name, {})) + [r for r in b.get(name, {}) if r not in a.get(name, {})]
        for row in rows:
            ra, rb = a.get(name, {}).get(row), b.get(name, {}).get(row)
            cols = []
            for k in (0, 1):
                x = ra[k] if ra else None
                y = 1.0 / rb[k] if rb else None
                g = math.sqrt(x * y) if x and y else None
                cols.append([x, y, g])
            if row == "pipeline" and cols[0][2] and cols[1][2]:
                logs.append((math.log(cols[0][2]), math.log(cols[1][2])))

            def f(v: float | None, w: int) -> str:
                return f"{v:>{w}.3f}" if v else f"{'-':>{w}}"

            lines.append(f"{name:<18} {row:<10} {f(cols[0][0], 16)} {f(cols[0][1], 10)} {f(cols[0][2], 8)}   "
                         f"{f(cols[1][0], 14)} {f(cols[1][1], 10)} {f(cols[1][2], 8)}"
                         + (f"   ({loads[name]} kernels loaded inside the measured runs: mean unusable)"
                            if row == "pipeline" and loads.get(name) else ""))
    if logs:
        gm = [math.exp(sum(v[k] for v in logs) / len(logs)) for k in (0, 1)]
        lines.append(f"whole pipeline, geometric mean over the {len(logs)} inputs with both roles: median "
                     f"{gm[0]:.3f}, mean {gm[1]:.3f} (new / previous)")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("new_this", type=Path, help="bench_pipeline_ab.py output, the new release in the 'this' role")
    ap.add_argument("new_other", type=Path, help="the previous release's bench_pipeline_ab.py output with --other "
                                                 "the new release")
    args = ap.parse_args()
    print("\n".join(both_roles(args.new_this, args.new_other)))


if __name__ == "__main__":
    main()
