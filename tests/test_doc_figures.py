"""The documented-figure registry (benchmarks/doc_figures.yaml) agrees with the docs, and
benchmarks/check_docs.py tells a reproduced figure from a wrong one (no documented command is run here)."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _check_docs():
    spec = importlib.util.spec_from_file_location("check_docs", ROOT / "benchmarks" / "check_docs.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("check_docs", mod)
    spec.loader.exec_module(mod)
    return mod


cd = _check_docs()
ENTRIES = cd.load_registry()


def test_registry_covers_the_readme_and_slam_figures():
    ids = {e["id"] for e in ENTRIES}
    assert {"readme-csail", "readme-experiment", "readme-speed", "slam-csail", "slam-datmo-parallel"} <= ids
    assert len(ids) == len(ENTRIES)


@pytest.mark.parametrize("entry", ENTRIES, ids=[e["id"] for e in ENTRIES])
def test_registry_matches_its_doc(entry):
    doc = (ROOT / entry["doc"]).read_text(encoding="utf-8")
    for command in entry["commands"]:
        assert command in doc, f"{entry['doc']} does not print {command!r}"
    assert entry["figures"]
    for fig in entry["figures"]:
        hits = re.findall(fig["quoted"], doc, re.MULTILINE)
        assert len(hits) == 1, f"{fig['quoted']!r} matches {len(hits)} times in {entry['doc']}"
        numbers = cd.quoted(doc, fig)
        assert numbers and all(re.fullmatch(r"-?\d+(\.\d+)?", n) for n in numbers)
        spec = fig["measured"]
        assert ("pattern" in spec) != ("json" in spec), spec
        re.compile(spec.get("pattern", ""))
        assert all(-len(numbers) <= i < len(numbers) for i in fig.get("ignore", []))


def test_agreement_rule():
    assert cd.agrees("0.024", "0.0236", {}) and cd.agrees("0.33", "0.329", {})
    assert not cd.agrees("0.024", "0.0234", {})  # the README's old CSAIL figure against today's 0.023
    assert cd.agrees("0.33", "0.326", {}) and not cd.agrees("0.32", "0.326", {})  # rounding to the quoted digits
    assert cd.agrees("474", "560", {"rel_tol": 0.35}) and not cd.agrees("474", "700", {"rel_tol": 0.35})


def test_run_entry_reports_quoted_vs_measured(tmp_path, monkeypatch):
    doc = tmp_path / "doc.md"
    doc.write_text("Run `python -c \"print('rmse 0.1234 m'); open('r.json', 'w').write('{\\\"a\\\": {\\\"b\\\": "
                   "2.5}}')\"`:\n"
                   "| bag | 0.123 | 2.5 |\n| other | 0.124 |\n")
    cmd = "python -c \"print('rmse 0.1234 m'); open('r.json', 'w').write('{\\\"a\\\": {\\\"b\\\": 2.5}}')\""
    assert cmd in doc.read_text()
    entry = {"id": "t", "doc": "doc.md", "commands": [cmd], "figures": [
        {"name": "from output", "quoted": r"^\| bag \| (\S+) \|", "measured": {"pattern": r"rmse (\S+) m"}},
        {"name": "from json", "quoted": r"^\| bag \| \S+ \| (\S+) \|", "measured": {"json": "r.json", "keys": ["a.b"]}},
        {"name": "wrong quote", "quoted": r"^\| other \| (\S+) \|", "measured": {"pattern": r"rmse (\S+) m"}},
    ]}
    r = cd.run_entry(entry, repo=tmp_path, keep=tmp_path)
    assert [f.ok for f in r.figures] == [True, True, False] and not r.ok
    assert r.figures[0].quoted == ["0.123"] and r.figures[0].measured == ["0.1234"]
    assert r.figures[2].problem == "differ at positions [0]"
    failing = {**entry, "commands": ["false"]}
    assert "exit 1" in cd.run_entry(failing, repo=tmp_path, keep=tmp_path).problem
