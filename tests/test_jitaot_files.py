"""The AOT kernel module's files (dynslam2d.jitaot): atomic install, the lock of a build, an unwritable folder,
``kernels status`` / ``kernels clear``. Fake module files: these tests are about files and keys, not code (a fake
module that a run tries to load fails to load and the run uses numba's kernels)."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from dynslam2d import jitaot
from dynslam2d.jitaot import MODULE_FILE, SIDECAR, TEMP_FILE, BuildError, build_lock, install, status

SRC = str(Path(__file__).resolve().parents[1] / "src")
ABI = ".cpython-311-x86_64-linux-gnu.so"


def _env(folder: Path) -> dict[str, str]:
    """A child process's environment: this checkout's sources, kernels folder ``folder``, mode auto, no compile
    worker, a terminal wide enough that no message wraps."""
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env[jitaot.DIR_ENV] = str(folder)
    env[jitaot.MODE_ENV] = "auto"
    env["DYNSLAM2D_COMPILE_WORKER"] = "0"
    env["COLUMNS"] = "400"
    return env


def _fake(scratch: Path, content: bytes) -> tuple[Path, dict[str, object]]:
    scratch.mkdir(parents=True, exist_ok=True)
    so = scratch / f"{jitaot.MODULE_NAME}{ABI}"
    so.write_bytes(content)
    info = {"format": jitaot.FORMAT, "key": jitaot.current_key(), "exports": {}, "cpu_target": "host",
            "cpu_name": "a test CPU", "numba_imported": "0.0-test", "built": "2026-12-05T22:00:00Z"}
    return so, info


def _complete(folder: Path) -> None:
    """Every module file whose name holds a hash holds that content (no partial file under a final name)."""
    for path in folder.iterdir():
        m = MODULE_FILE.match(path.name)
        if m and m.group(1):
            assert hashlib.sha256(path.read_bytes()).hexdigest()[:16] == m.group(1)[1:], path.name


class _Stop(BaseException):
    """An interruption (as Ctrl-C's KeyboardInterrupt) injected before a file-system call."""


def test_install_switches_module_and_sidecar_at_once_whenever_interrupted(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    old, new = b"old module" * 200, b"new module" * 300
    sha_old, sha_new = hashlib.sha256(old).hexdigest(), hashlib.sha256(new).hexdigest()
    calls = {"replace": os.replace, "fsync": os.fsync, "unlink": os.unlink, "rename": os.rename}
    finished = False
    for k in range(40):
        folder = tmp_path / f"k{k}"
        folder.mkdir()
        install(folder, *_fake(tmp_path / "a", old))
        assert status(folder).valid
        count = [0]

        def interrupt(real, *args, _count=count, _k=k, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
            if _count[0] == _k:  # the k-th file-system call of the install is interrupted before it happens
                raise _Stop
            _count[0] += 1
            return real(*args, **kwargs)

        for name, real in calls.items():
            monkeypatch.setattr(os, name, lambda *a, _r=real, **kw: interrupt(_r, *a, **kw))
        try:
            install(folder, *_fake(tmp_path / "b", new))
            finished = True
        except _Stop:
            pass
        finally:
            monkeypatch.undo()
        st = status(folder)
        assert st.valid, (k, st.reason)  # the old pair or the new one, whatever the step interrupted
        assert st.info["sha256"] in (sha_old, sha_new)
        _complete(folder)
        if finished:
            assert st.info["sha256"] == sha_new
            names = sorted(p.name for p in folder.iterdir())
            assert names == sorted([SIDECAR, st.info["file"]]), names  # the old module and temp files removed
            break
    assert finished


def test_module_file_that_does_not_match_its_sidecar_is_not_loaded(tmp_path: Path) -> None:
    info = install(tmp_path, *_fake(tmp_path / "s", b"x" * 4096))
    path = tmp_path / info["file"]
    assert status(tmp_path).valid
    path.write_bytes(b"y" * 4096)  # the same size, other bytes
    st = status(tmp_path)
    assert not st.valid and "does not match" in st.reason
    path.write_bytes(b"x" * 100)  # truncated
    assert not status(tmp_path).valid
    side = json.loads((tmp_path / SIDECAR).read_text())
    side["file"] = "../elsewhere.so"  # a sidecar names only a module file of the folder
    (tmp_path / SIDECAR).write_text(json.dumps(side))
    assert not status(tmp_path).valid
    (tmp_path / SIDECAR).write_text("{not json")
    assert not status(tmp_path).valid


def test_a_run_given_a_module_that_fails_to_load_uses_numba(tmp_path: Path) -> None:
    install(tmp_path, *_fake(tmp_path / "s", b"not an ELF file" * 10))
    assert status(tmp_path).valid  # (its sidecar's key and hash are right; the content is no extension module)
    probe = "import sys, dynslam2d.pipeline; from dynslam2d import jitbox; print(jitbox.AOT is None)"
    res = subprocess.run([sys.executable, "-c", probe], env=_env(tmp_path), capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0 and res.stdout.split() == ["True"], res.stderr[-2000:]


def test_one_build_at_a_time(tmp_path: Path) -> None:
    folder = tmp_path / "k"
    with build_lock(folder):
        with pytest.raises(BuildError, match=f"another `dynslam2d kernels build` \\(pid {os.getpid()}\\)"):
            with build_lock(folder):
                pass
        if jitaot.build_requirements() is None:  # the command, from another process: refused at once
            res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "build", "--quiet"],
                                 env=_env(folder), capture_output=True, text=True, timeout=120)
            assert res.returncode == 2 and "another `dynslam2d kernels build`" in res.stderr, res.stderr[-2000:]
        res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "clear"], env=_env(folder),
                             capture_output=True, text=True, timeout=120)
        assert res.returncode == 2 and "another" in res.stderr, res.stderr[-2000:]
    with build_lock(folder):  # released with the block
        pass
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from pathlib import Path; "
                               "from dynslam2d.jitaot import build_lock\nwith build_lock(Path(sys.argv[1])):\n"
                               "    print('held', flush=True); time.sleep(60)", str(folder)],
                              env=_env(folder), stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        with pytest.raises(BuildError, match="another"):
            with build_lock(folder):
                pass
    finally:
        holder.kill()  # a build killed (or crashed) releases its lock: no stale lock
        holder.wait()
    with build_lock(folder):
        pass


@pytest.mark.parametrize("how", ["file", "under-a-file", "read-only"])
def test_unwritable_folder_fails_the_build_in_one_line_and_runs_go_on(tmp_path: Path, how: str) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("a file in the way")
    folder = {"file": blocker, "under-a-file": blocker / "aot", "read-only": tmp_path / "ro"}[how]
    if how == "read-only":
        if os.geteuid() == 0:
            pytest.skip("root writes into read-only folders")
        folder.mkdir()
        folder.chmod(0o500)
    try:
        with pytest.raises(BuildError, match=jitaot.DIR_ENV):
            with build_lock(folder):
                pass
        if jitaot.build_requirements() is None:
            res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "build", "--quiet"],
                                 env=_env(folder), capture_output=True, text=True, timeout=120)
            err = res.stderr.strip()
            assert res.returncode == 2 and "\n" not in err, err[-2000:]
            assert str(folder) in err and jitaot.DIR_ENV in err and "cannot write" in err, err
        res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "status", "--json"],
                             env=_env(folder), capture_output=True, text=True, timeout=120)
        assert res.returncode == 0 and json.loads(res.stdout)["present"] is False, res.stderr[-2000:]
        probe = "import dynslam2d.pipeline; from dynslam2d import jitbox; print(jitbox.AOT is None)"
        res = subprocess.run([sys.executable, "-c", probe], env=_env(folder), capture_output=True, text=True,
                             timeout=300)
        assert res.returncode == 0 and res.stdout.split() == ["True"], res.stderr[-2000:]
    finally:
        if how == "read-only":
            folder.chmod(0o700)


def test_status_names_the_module_file_and_clear_removes_its_files_only(tmp_path: Path) -> None:
    info = install(tmp_path, *_fake(tmp_path / "s", b"module" * 50))
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "status", "--json"], env=_env(tmp_path),
                         capture_output=True, text=True, timeout=120)
    row = json.loads(res.stdout)
    assert row["valid"] and row["file"] == info["file"] and row["numba"] == "0.0-test"
    assert row["cpu"] == "a test CPU" and row["built"] == "2026-12-05T22:00:00Z"
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "status"], env=_env(tmp_path),
                         capture_output=True, text=True, timeout=120)
    assert info["file"] in res.stdout and "numba 0.0-test" in res.stdout and "a test CPU" in res.stdout, res.stdout
    ours = [f"{jitaot.MODULE_NAME}{ABI}",  # aot41's module file (no hash)
            f".{info['file']}.tmp-123-abcd0123", f".{SIDECAR}.tmp-9-00ff", jitaot.LOCK]
    theirs = ["notes.txt", f"{jitaot.MODULE_NAME}_backup.txt", f"{SIDECAR}.bak", "other.cpython-311.so"]
    for name in ours + theirs:
        (tmp_path / name).write_text("x")
    assert all(TEMP_FILE.match(n) for n in ours[1:3])
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "clear"], env=_env(tmp_path),
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "removed 5" in res.stdout, (res.stdout, res.stderr[-2000:])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["s", *theirs])
