"""A whole ``dynslam2d run`` with the AOT kernel module against numba's JIT kernels (warm cache), alternated pairs.

    PYTHONPATH=src taskset -c 1 python benchmarks/bench_aot_run.py INPUT --pairs 3 --out SCRATCH

Each pair runs ``dynslam2d run INPUT --out SCRATCH/<mode><k> -q`` once with ``DYNSLAM2D_KERNELS=jit`` and once with
the AOT module (``auto``; a valid module is required: ``dynslam2d kernels build``), in turn first. Per run: peak
RSS (``peak_mib``: the process's own ``VmHWM`` at its end where Linux gives it; ``time_mib``: ``/usr/bin/time``'s
maximum resident set size; the two agree here, and both read ≈ 4 MiB lower than the same run started from a shell:
docs/speed.md, pass mem116 and its lead's note), wall time of the process, the summary's first
scan time and steady scans/s, and whether numba was imported (the run's ``kernel_compile_s`` is 0 either way with a
warm cache). Then every result file other than summary.json / run.json (timings) of each AOT run compared byte for
byte with the JIT run of its pair. Prints one line per run and the medians. Not run by pytest; numbers go to
docs/speed.md (pass aot41).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

RUN = r"""
import json, sys
from dynslam2d.cli import main
out = sys.argv[2]
sys.argv = ["dynslam2d", "run", sys.argv[1], "--out", out, "-q", "--force"]
try:
    main()
except SystemExit as exc:
    assert exc.code in (0, None), exc.code
hwm = None
try:  # the process's own peak resident set (Linux), beside /usr/bin/time's %M
    with open("/proc/self/status") as st:
        hwm = next((int(line.split()[1]) for line in st if line.startswith("VmHWM:")), None)
except OSError:
    pass
with open(out + ".modules.json", "w") as fh:
    json.dump({"numba": "numba" in sys.modules, "llvmlite": "llvmlite" in sys.modules, "vmhwm_kib": hwm}, fh)
"""

TIMINGS = ("summary.json", "run.json")


def one(inp: str, out: Path, mode: str) -> dict[str, float]:
    env = dict(os.environ, DYNSLAM2D_KERNELS=mode, DYNSLAM2D_COMPILE_WORKER="0")
    t0 = time.perf_counter()
    res = subprocess.run(["/usr/bin/time", "-f", "%M", sys.executable, "-c", RUN, inp, str(out)], env=env,
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(res.stderr[-3000:])
    summary = json.loads((out / "summary.json").read_text())
    mods = json.loads(Path(str(out) + ".modules.json").read_text())
    time_kib = int(res.stderr.strip().splitlines()[-1])
    hwm_kib = mods.get("vmhwm_kib")
    # peak_mib: the run's own VmHWM where the kernel gives it, else /usr/bin/time's %M (time_mib; pass mem116)
    return {"peak_mib": (hwm_kib if hwm_kib else time_kib) / 1024, "time_mib": time_kib / 1024, "wall_s": wall,
            "first_scan_ms": summary["first_scan_ms"], "steady_scans_per_s": summary["steady_scans_per_s"],
            "compile_s": summary.get("kernel_compile_s", 0.0), "numba": mods["numba"]}


def same_files(a: Path, b: Path) -> tuple[int, list[str]]:
    names = sorted(p.name for p in a.iterdir() if p.is_file() and p.name not in TIMINGS)
    differ = [n for n in names if not (b / n).is_file() or (a / n).read_bytes() != (b / n).read_bytes()]
    return len(names), differ


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input")
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows: dict[str, list[dict[str, float]]] = {"jit": [], "auto": []}
    for k in range(args.pairs):
        for mode in ("jit", "auto") if k % 2 == 0 else ("auto", "jit"):
            r = one(args.input, out / f"{mode}{k}", mode)
            rows[mode].append(r)
            print(f"pair {k} {'AOT' if mode == 'auto' else 'JIT'}: " + ", ".join(f"{key} {v}" for key, v in r.items()),
                  flush=True)
        n, differ = same_files(out / f"jit{k}", out / f"auto{k}")
        extra = f", differ: {differ}" if differ else ""
        print(f"pair {k}: {n - len(differ)}/{n} result files byte-identical{extra}", flush=True)
    for mode, label in (("jit", "JIT"), ("auto", "AOT")):
        med = {key: statistics.median(r[key] for r in rows[mode]) for key in rows[mode][0] if key != "numba"}
        print(f"{label} medians: " + ", ".join(f"{key} {v:.4g}" for key, v in med.items())
              + f"; numba imported: {sorted({r['numba'] for r in rows[mode]})}")


if __name__ == "__main__":
    main()
