"""What a user is told about kernels built ahead of time that a process does not use (dynslam2d.jitaot's
``status`` / ``unused_reason``, the line ``dynslam2d run`` prints after a run): which part of a stale module's key
differs, a module that fails to load. Fake module files, as in test_jitaot_files.py: no build needed."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from test_jitaot_files import ABI, _env

from dynslam2d import jitaot
from dynslam2d.jitaot import SIDECAR, install, status


def _install(folder: Path, content: bytes = b"not an ELF file" * 10, **key: str) -> None:
    """A fake module whose sidecar's key is this process's with ``key``'s parts replaced."""
    scratch = folder.parent / f"{folder.name}-scratch"
    scratch.mkdir(parents=True)
    so = scratch / f"{jitaot.MODULE_NAME}{ABI}"
    so.write_bytes(content)
    info = {"format": jitaot.FORMAT, "key": {**jitaot.current_key(), **key}, "exports": {}, "cpu_target": "host",
            "cpu_name": jitaot.cpu_name(), "numba_imported": "0.0-test", "built": "2026-12-05T22:00:00Z"}
    folder.mkdir(parents=True, exist_ok=True)
    install(folder, so, info)


@pytest.mark.parametrize(("part", "value", "said"), [
    ("numba", "0.0-old", "another numba version (built with 0.0-old, now {numba})"),
    ("python", "cpython-00-0.0.0", "another Python (built for cpython-00-0.0.0, now {python})"),
    ("sources", "0123456789abcdef", "the kernel sources changed (dynslam2d updated or edited since the build)"),
    ("cpu", "0123456789abcdef", "another CPU (the same model, {cpu_name}, with other feature flags)"),
])
def test_status_names_the_part_of_the_key_that_differs(tmp_path: Path, part: str, value: str, said: str) -> None:
    _install(tmp_path / "k", **{part: value})
    st = status(tmp_path / "k")
    assert st.present and not st.valid and st.stale == (part,)
    assert st.reason == "stale: " + said.format(**jitaot.current_key(), cpu_name=jitaot.cpu_name())


def test_status_names_every_differing_part_and_the_cpu_built_on(tmp_path: Path) -> None:
    _install(tmp_path / "k", numba="0.0-old", cpu="0123456789abcdef")
    side = json.loads((tmp_path / "k" / SIDECAR).read_text())
    side["cpu_name"] = "Another CPU @ 1 GHz"
    (tmp_path / "k" / SIDECAR).write_text(json.dumps(side))
    st = status(tmp_path / "k")
    assert st.stale == ("numba", "cpu")
    assert st.reason.startswith("stale: another numba version (built with 0.0-old, ")
    assert st.reason.endswith(f", another CPU (built on Another CPU @ 1 GHz, this is {jitaot.cpu_name()})")
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "status", "--json"],
                         env=_env(tmp_path / "k"), capture_output=True, text=True, timeout=120)
    row = json.loads(res.stdout)
    assert row["stale"] == ["numba", "cpu"] and row["reason"] == st.reason and not row["used"]


def _run(folder: Path, out: Path, *extra: str) -> list[str]:
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "run", "sim:paper", "--duration", "2", "--out", str(out),
                          *extra], env=_env(folder), capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    return [ln for ln in res.stderr.splitlines() if "ahead of time" in ln]


def test_a_run_says_once_why_the_built_kernels_were_not_used(tmp_path: Path) -> None:
    _install(tmp_path / "k", numba="0.0-old")  # as after `pip install -U numba`
    lines = _run(tmp_path / "k", tmp_path / "a")
    assert len(lines) == 1, lines  # one line, not also the generic `kernels build` hint of a cold run
    assert lines[0].startswith("the kernels built ahead of time were not used, stale: another numba version "
                               "(built with 0.0-old, now ")
    assert "run `dynslam2d kernels build` again" in lines[0]
    assert _run(tmp_path / "k", tmp_path / "b", "-q") == []  # --quiet: nothing


def test_a_module_that_fails_to_load_is_named(tmp_path: Path) -> None:
    _install(tmp_path / "k")  # its key and hash are right; the content is no extension module
    assert status(tmp_path / "k").valid
    probe = ("import dynslam2d.pipeline; from dynslam2d import jitaot; "
             "print(jitaot.in_use()); print(jitaot.unused_reason())")
    res = subprocess.run([sys.executable, "-c", probe], env=_env(tmp_path / "k"), capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    used, note = res.stdout.strip().splitlines()
    assert used == "jit"
    assert note.startswith(f"the kernels built ahead of time were not used, {status(tmp_path / 'k').info['file']} "
                           "failed to load (ImportError: ")
    empty = subprocess.run([sys.executable, "-c", probe], env=_env(tmp_path / "none"), capture_output=True, text=True,
                           timeout=300)
    assert empty.stdout.split() == ["jit", "None"]  # no module built: nothing to say


def test_a_module_of_another_sidecar_format_gives_the_remedy_once(tmp_path: Path) -> None:
    """A module built by an older dynslam2d (another sidecar format, as after an upgrade): ``status`` says "build
    again", and the line after a run names the reason and the remedy once, not twice."""
    _install(tmp_path / "k")
    side = tmp_path / "k" / SIDECAR
    info = json.loads(side.read_text())
    side.write_text(json.dumps({**info, "format": -1}))
    st = status(tmp_path / "k")
    assert st.present and not st.valid and st.reason == "built by another version of dynslam2d (build again)"
    probe = "import dynslam2d.pipeline; from dynslam2d import jitaot; print(jitaot.unused_reason())"
    res = subprocess.run([sys.executable, "-c", probe], env=_env(tmp_path / "k"), capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    note = res.stdout.strip()
    assert note == ("the kernels built ahead of time were not used, built by another version of dynslam2d; numba's "
                    "kernels ran instead: run `dynslam2d kernels build` again")
