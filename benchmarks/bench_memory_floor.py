"""The resident memory a run holds before its first map cell (issue 13 item 3): the interpreter, numpy, numba and
llvmlite, the project's modules, and every numba kernel one ``dynslam2d run INPUT`` calls, loaded from the (warm)
kernel cache — the floor under any peak with numba in the process.

    PYTHONPATH=src python benchmarks/bench_memory_floor.py ../shared/data/mit-csail/mit-csail.clf [--top 12]

First runs ``dynslam2d run INPUT --out TMP -q`` twice (the first fills the cache) and records the signature of
every kernel the second run held (read by ``kernelwarm.parse_signature``: literal types and the project's ``vec4``
too); then, in a fresh interpreter, imports step by step and loads those kernels one at a time
(``Dispatcher.compile`` with a warm cache loads the cached code), printing the RSS after each step, the kernels
that added most, and the cache's size on disk. The loop closure's ``scipy.sparse`` import and SciPy's SuperLU and
connected components loaded without their packages (lazyscipy.py; when a run first needs them) are measured last.
Not run by pytest; numbers go to docs/speed.md with this command.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

RECORD = r"""
import json, sys
from numba.core.registry import CPUDispatcher
from dynslam2d.cli import main
out, inp, run = sys.argv[1], sys.argv[2], sys.argv[3]
sys.argv = ["dynslam2d", "run", inp, "--out", out + "/" + run, "-q"]
try:
    main()
except SystemExit:
    pass
from dynslam2d.jitwarm import signature_text
held = [[f"{name}.{attr}", signature_text(sig)] for name, mod in list(sys.modules.items())
        if mod is not None and name.startswith("dynslam2d") for attr, obj in vars(mod).items()
        if isinstance(obj, CPUDispatcher) and obj.__module__ == name for sig in obj.signatures]
json.dump(held, open(out + "/kernels.json", "w"))
"""

STEPS = r"""
import json, os, sys
PAGE = os.sysconf("SC_PAGE_SIZE")
def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * PAGE / 2**20
rows = [("interpreter", rss())]
import numpy
rows.append(("+ numpy", rss()))
import dynslam2d.jitcache as jc  # what the command line does before numba is imported
jc.plain_numba_errors()
jc.load_blas_alone()
import numba
rows.append(("+ numba, llvmlite", rss()))
from numba.core.registry import cpu_target
cpu_target.target_context.refresh()  # what loading (or compiling) the first kernel does first
rows.append(("+ numba's typing and target contexts (its first kernel)", rss()))
kernels = json.load(open(sys.argv[1]))
import importlib
for name, _sig in kernels:
    importlib.import_module(name.rpartition(".")[0])
rows.append(("+ the kernels' modules (signature-declared kernels load here)", rss()))
import dynslam2d.cli, dynslam2d.pipeline  # noqa: E401
rows.append(("+ the rest of a run's imports (cli, pipeline)", rss()))
sys.path.insert(0, sys.argv[2])  # (benchmarks/: kernelwarm's parser reads literal types, ``Literal[int](64)``)
from kernelwarm import parse_signature
from dynslam2d.jitwarm import _dispatcher
per = []
skipped = []
for name, sig in kernels:
    r0 = rss()
    try:
        args = parse_signature(sig)
    except Exception:  # a type the manifest's text cannot name: listed, not loaded
        skipped.append(f"{name} {sig}")
        continue
    disp = _dispatcher(name)
    if not disp._can_compile:  # declared with its signature: numba compiled or loaded it at import
        continue
    disp.compile(args)
    per.append((name, rss() - r0))
rows.append((f"+ all {len(per)} kernels the run calls, from the cache", rss()))
import scipy.sparse
from dynslam2d import lazyscipy
lazyscipy._loaded("superlu"), lazyscipy._loaded("components")  # the loop closure's SciPy parts (pass mem60)
rows.append(("+ scipy.sparse, SuperLU and connected components: the loop closure's", rss()))
print(json.dumps({"rows": rows, "per": per, "skipped": skipped}))
"""


def cache_bytes(kernels: list[list[str]]) -> int:
    """Bytes on disk of the numba cache files (index and data) of the kernels' modules."""
    import importlib.util

    total = 0
    seen: set[Path] = set()
    for name, _sig in kernels:
        mod = name.rpartition(".")[0]
        spec = importlib.util.find_spec(mod)
        if spec is None or spec.origin is None:
            continue
        origin = Path(spec.origin)
        folders = [origin.parent / "__pycache__"]
        env = os.environ.get("NUMBA_CACHE_DIR")
        if env:
            folders.append(Path(env))
        stem = origin.stem
        for folder in folders:
            if not folder.is_dir():
                continue
            for f in folder.rglob(f"{stem}.*"):
                if f.suffix in (".nbi", ".nbc") and f not in seen:
                    seen.add(f)
                    total += f.stat().st_size
    return total


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input", help="recording (or sim:<scenario>) whose kernels are loaded")
    ap.add_argument("--top", type=int, default=12, help="kernels to list by the memory their loading added")
    args = ap.parse_args()
    env = dict(os.environ)
    with tempfile.TemporaryDirectory(prefix="bench-memory-floor-") as tmp:
        # twice: the first run fills the cache (a cold cache: the callees compiled with their callers are held too,
        # with signatures a warm run never loads apart), the second holds what a warm run calls from Python
        for run in ("fill", "warm"):
            res = subprocess.run([sys.executable, "-c", RECORD, tmp, args.input, run], env=env, capture_output=True,
                                 text=True)
            if res.returncode != 0:
                raise SystemExit(f"run failed: {res.stderr[-2000:]}")
        kfile = Path(tmp) / "kernels.json"
        kernels = json.loads(kfile.read_text())
        here = str(Path(__file__).resolve().parent)
        res = subprocess.run([sys.executable, "-c", STEPS, str(kfile), here], env=env, capture_output=True, text=True)
        if res.returncode != 0:
            raise SystemExit(f"floor probe failed: {res.stderr[-2000:]}")
    out = json.loads(res.stdout.strip().splitlines()[-1])
    prev = 0.0
    for label, mib in out["rows"]:
        print(f"{label:<62} RSS {mib:7.1f} MiB  (+{mib - prev:5.1f})")
        prev = mib
    print(f"\nkernels whose loading added most (of {len(out['per'])}; cache files of their modules on disk: "
          f"{cache_bytes(kernels) / 2**20:.1f} MiB):")
    for name, mib in sorted(out["per"], key=lambda p: -p[1])[:args.top]:
        print(f"  {mib:6.1f} MiB  {name}")
    for text in out["skipped"]:
        print(f"  not loaded (signature not parsed): {text}")


if __name__ == "__main__":
    main()
