"""Re-run the commands printed in the docs and compare the figures quoted beside them (issue 15 item 6).

The registry ``benchmarks/doc_figures.yaml`` lists, per entry: the doc file, the commands
exactly as the doc prints them, and for each quoted figure a regular expression that
finds it in the doc (it must match exactly once) and where the command's result holds
it (its output, a file it wrote, or a key of a JSON file it wrote). This script runs the
commands in a scratch folder laid out like the repository (``../shared`` → the datasets,
``benchmarks/`` → this folder's scripts), with this checkout's ``src`` first on
``PYTHONPATH``, and prints quoted vs measured for every number:

    python benchmarks/check_docs.py              # the fast entries
    python benchmarks/check_docs.py --all        # also the long ones (the paper's experiment, speed, ...)
    python benchmarks/check_docs.py --only readme-csail slam-datmo-parallel
    python benchmarks/check_docs.py --list

Exit status 0 when every compared number agrees, 1 on any mismatch or failed command.

A number agrees when it equals the measured value rounded to the quoted number of
decimals (so "0.024" needs a measured 0.0235 … 0.0245), unless the figure gives
``rel_tol`` (speeds, which vary with the machine's load: |measured / quoted − 1| ≤ rel_tol)
or ``abs_tol``. ``ignore`` lists positions of numbers that are not compared (e.g. -1: the last,
the scans/s column of a results table).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))  # (imported by the tests from its file: the shared scratch module beside it)
from scratch import scratch_dir  # noqa: E402

REGISTRY = HERE / "doc_figures.yaml"
NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


def load_registry(path: Path = REGISTRY) -> list[dict[str, Any]]:
    """The registry's entries (a list of mappings with id, doc, commands, figures)."""
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    return list(data["entries"])


def numbers(texts: list[str]) -> list[str]:
    """Every number in ``texts``, in order, as written."""
    return [n for t in texts for n in NUMBER.findall(t)]


def quoted(doc_text: str, figure: dict[str, Any]) -> list[str]:
    """The numbers the doc quotes for ``figure`` (its ``quoted`` regex must match exactly once)."""
    matches = list(re.finditer(figure["quoted"], doc_text, re.MULTILINE))
    if len(matches) != 1:
        raise ValueError(f"quoted pattern {figure['quoted']!r} matches {len(matches)} times (must be once)")
    return numbers(list(matches[0].groups()) or [matches[0].group(0)])


def measured(figure: dict[str, Any], output: str, workdir: Path) -> list[str]:
    """The numbers the commands produced for ``figure``: from ``output``, a file's text, or JSON keys."""
    spec = figure["measured"]
    if "json" in spec:
        data = json.loads((workdir / spec["json"]).read_text(encoding="utf-8"))
        values = []
        for key in spec["keys"]:
            node: Any = data
            for part in key.split("."):
                node = node[int(part)] if isinstance(node, list) else node[part]
            values.append(repr(float(node)))
        return values
    text = (workdir / spec["file"]).read_text(encoding="utf-8") if "file" in spec else output
    m = re.search(spec["pattern"], text, re.MULTILINE)
    if m is None:
        raise ValueError(f"measured pattern {spec['pattern']!r} not found in {spec.get('file', 'the output')}")
    found = numbers(list(m.groups()) or [m.group(0)])
    if "order" in spec:  # the doc quotes them in another order than the output prints them
        found = [found[i] for i in spec["order"]]
    return found


def agrees(q: str, v: str, figure: dict[str, Any]) -> bool:
    """True if the measured ``v`` reproduces the quoted ``q`` (rules in the module docstring)."""
    qf, vf = float(q), float(v)
    if "rel_tol" in figure:
        return abs(vf - qf) <= float(figure["rel_tol"]) * abs(qf) + 1e-12
    if "abs_tol" in figure:
        return abs(vf - qf) <= float(figure["abs_tol"]) + 1e-12
    decimals = len(q.split(".")[1]) if "." in q else 0
    return abs(vf - qf) <= 0.5 * 10.0 ** -decimals + 1e-9


@dataclass
class FigureResult:
    name: str
    quoted: list[str]
    measured: list[str]
    ok: bool
    problem: str = ""


@dataclass
class EntryResult:
    id: str
    ok: bool
    seconds: float
    figures: list[FigureResult] = field(default_factory=list)
    problem: str = ""


def compare(figure: dict[str, Any], doc_text: str, output: str, workdir: Path) -> FigureResult:
    """Quoted vs measured numbers of one figure."""
    name = figure.get("name", figure["quoted"])
    try:
        q = quoted(doc_text, figure)
        v = measured(figure, output, workdir)
    except (ValueError, OSError, KeyError, IndexError) as exc:
        return FigureResult(name, [], [], False, str(exc))
    skip = {i if i >= 0 else len(q) + i for i in figure.get("ignore", [])}
    if len(q) != len(v):
        return FigureResult(name, q, v, False, f"{len(q)} numbers quoted, {len(v)} measured")
    bad = [i for i, (a, b) in enumerate(zip(q, v)) if i not in skip and not agrees(a, b, figure)]
    return FigureResult(name, q, v, not bad, f"differ at positions {bad}" if bad else "")


def scratch_folder(root: Path) -> Path:
    """A working folder laid out like the repository root: ``../shared`` and ``benchmarks/`` beside it."""
    work = root / "repo"
    work.mkdir(parents=True, exist_ok=True)
    shared = REPO.parent / "shared"
    if shared.exists():
        (root / "shared").symlink_to(shared.resolve())
    (work / "benchmarks").symlink_to(HERE)
    return work


#: Commands already run in this invocation (entries of two docs often print the same commands).
_RUNS: dict[tuple[str, ...], tuple[int, str, Path, float]] = {}


def run_commands(commands: list[str], repo: Path = REPO, keep: Path | None = None) -> tuple[int, str, Path, float]:
    """Run ``commands`` in one bash (stops at the first failure) in a fresh scratch folder:
    (exit status, stdout + stderr, the folder, seconds). Cached per invocation."""
    key = (str(repo), *commands)
    if key in _RUNS:
        return _RUNS[key]
    root = Path(scratch_dir("check-docs-", keep=keep is not None, dir=keep))  # removed at exit unless --keep
    work = scratch_folder(root)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(repo / "src"), *filter(None, [env.get("PYTHONPATH")])])
    script = "set -e\n" + "\n".join(commands) + "\n"
    t0 = time.perf_counter()
    proc = subprocess.run(["bash", "-c", script], cwd=work, env=env, capture_output=True, text=True)
    _RUNS[key] = (proc.returncode, proc.stdout + proc.stderr, work, time.perf_counter() - t0)
    return _RUNS[key]


def run_entry(entry: dict[str, Any], repo: Path = REPO, keep: Path | None = None) -> EntryResult:
    """Run an entry's commands (one bash script, stops at the first failure) and compare its figures."""
    doc_text = (repo / entry["doc"]).read_text(encoding="utf-8")
    returncode, output, work, seconds = run_commands(entry["commands"], repo, keep)
    if returncode != 0:
        last = [ln for ln in output.splitlines() if ln.strip()][-3:]
        return EntryResult(entry["id"], False, seconds, problem=f"commands failed (exit {returncode}): "
                                                                f"{' / '.join(last)}")
    figs = [compare(f, doc_text, output, work) for f in entry["figures"]]
    return EntryResult(entry["id"], all(f.ok for f in figs), seconds, figs)


def _selected(entries: list[dict[str, Any]], only: list[str] | None, all_: bool) -> list[dict[str, Any]]:
    if only:
        ids = {e["id"] for e in entries}
        unknown = [o for o in only if o not in ids]
        if unknown:
            raise SystemExit(f"unknown id(s): {', '.join(unknown)}; see --list")
        return [e for e in entries if e["id"] in only]
    return [e for e in entries if all_ or not e.get("slow", False)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", metavar="ID", help="run these entries (see --list)")
    ap.add_argument("--all", action="store_true", help="also the slow entries")
    ap.add_argument("--list", action="store_true", help="list the entries and exit")
    ap.add_argument("--keep", type=Path, help="put the scratch folders here (default: a temporary folder)")
    args = ap.parse_args(argv)
    entries = load_registry()
    if args.list:
        for e in entries:
            print(f"{e['id']:<26} {'slow' if e.get('slow') else 'fast':<5} {e['doc']:<18} {len(e['figures'])} figures: "
                  f"{' && '.join(e['commands'])}")
        return 0
    chosen = _selected(entries, args.only, args.all)
    if not (REPO.parent / "shared" / "data").exists():
        needing = [e["id"] for e in chosen if e.get("needs_data")]
        if needing:
            print(f"skipped (no ../shared/data): {', '.join(needing)}")
        chosen = [e for e in chosen if not e.get("needs_data")]
    failed = 0
    for e in chosen:
        print(f"== {e['id']} ({e['doc']}): {' && '.join(e['commands'])}", flush=True)
        r = run_entry(e, keep=args.keep)
        if r.problem:
            print(f"   FAILED after {r.seconds:.0f} s: {r.problem}")
        for f in r.figures:
            mark = "ok " if f.ok else "MISMATCH"
            print(f"   {mark} {f.name}: quoted {' '.join(f.quoted) or '—'} | measured {' '.join(f.measured) or '—'}"
                  + (f"  ({f.problem})" if f.problem else ""))
        print(f"   {'ok' if r.ok else 'MISMATCH'} in {r.seconds:.0f} s", flush=True)
        failed += not r.ok
    print(f"{len(chosen) - failed} of {len(chosen)} entries reproduce their documented figures")
    if args.keep:
        print(f"scratch folders kept in {args.keep}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
