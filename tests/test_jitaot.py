"""The kernels compiled ahead of time (dynslam2d.jitaot, ``dynslam2d kernels build``): same results as numba's
kernels, no numba in the process, argument checks, stale modules not loaded.

One AOT module is built per test session into a temporary folder (about a minute of one CPU); the tests that need
it are skipped when this machine has no C compiler or setuptools."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dynslam2d import jitaot, jitmanifest
from dynslam2d.jitaot import KernelArgumentError, make_kernel, parse_types

SRC = str(Path(__file__).resolve().parents[1] / "src")


def _env(folder: Path | None, mode: str = "auto") -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env[jitaot.MODE_ENV] = mode
    env["DYNSLAM2D_COMPILE_WORKER"] = "0"
    if folder is not None:
        env[jitaot.DIR_ENV] = str(folder)
    return env


# --- the argument check, without a build -------------------------------------------------------------------------

def _kernel(a, b, n, flag, pair, x=0.5):  # noqa: ANN001, ANN202 - a stand-in kernel
    return "python"


def _checked() -> object:
    def first(*args: object) -> str:
        return "first"

    def second(*args: object) -> str:
        return "second"

    sig1 = "(Array(float64, 1, 'C'), Array(bool, 2, 'C', True), int64, bool, UniTuple(Array(float32, 2, 'C'), 2), " \
           "float64,)"
    sig2 = "(Array(int64, 1, 'A'), Array(bool, 2, 'C', True), int64, bool, UniTuple(Array(float32, 2, 'C'), 2), " \
           "float64,)"
    return make_kernel(_kernel, "tests.kernel", [(first, parse_types(sig1)), (second, parse_types(sig2))])


def _good() -> list[object]:
    ro = np.zeros((2, 3), dtype=bool)
    ro.flags.writeable = False
    return [np.zeros(4), ro, 3, True, (np.zeros((2, 2), np.float32), np.ones((1, 2), np.float32)), 1.5]


def test_arguments_choose_the_export_of_their_types() -> None:
    k = _checked()
    assert k(*_good()) == "first"
    assert k(*_good()[:5]) == "first"  # the default (a float) passed as the export takes it
    args = _good()
    args[0] = np.arange(8)[::2]  # int64, strided: only the second export ('A' layout) takes it
    assert k(*args) == "second"
    args[1] = np.zeros((2, 3), dtype=bool)  # writable where a read-only array is declared: fine
    assert k(*args) == "second"
    assert k.py_func is _kernel and k.__name__ == "_kernel" and k.__module__ == __name__


@pytest.mark.parametrize("pos, bad, what", [
    (0, np.zeros(4, np.float32), "float32"),  # dtype
    (0, np.zeros((4, 1)), "2"),  # ndim
    (0, np.zeros(8)[::2], "'A'"),  # not C-contiguous
    (0, [0.0, 1.0], "list"),  # not an array
    (2, 3.0, "float"),  # a float where an int64 is declared
    (2, True, "bool"),  # a bool is no int64 for numba
    (3, 1, "int"),
    (4, (np.zeros((2, 2), np.float64), np.zeros((1, 2), np.float32)), "float64"),  # a tuple item's dtype
    (4, (np.zeros((2, 2), np.float32),), "tuple"),  # a tuple's length
    (5, np.float32(1.0), "float32"),
])
def test_wrong_arguments_raise_a_clear_error_not_a_crash(pos: int, bad: object, what: str) -> None:
    k = _checked()
    args = _good()
    args[pos] = bad
    with pytest.raises(KernelArgumentError, match="kernel tests.kernel") as err:
        k(*args)
    assert what in str(err.value) and f"position {pos}" in str(err.value) and jitaot.MODE_ENV in str(err.value)


def test_read_only_array_where_a_writable_one_is_declared_is_refused() -> None:
    k = make_kernel(lambda a: None, "tests.ro", [(lambda a: "ok", parse_types("(Array(float64, 1, 'C'),)"))])
    a = np.zeros(3)
    assert k(a) == "ok"
    a.flags.writeable = False
    with pytest.raises(KernelArgumentError, match="read-only"):
        k(a)


def test_types_an_export_cannot_take_are_refused_at_parse() -> None:
    for text in ("(Literal[int](64),)", "(omitted(default=0.5),)", "(vec4,)", "(none,)"):
        with pytest.raises(ValueError):
            parse_types(text)
    assert parse_types("(UniTuple(Array(int32, 2, 'C', False, aligned=True), 3), uint8,)")[1] == "uint8"


# --- with a built module -------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    why = jitaot.build_requirements()
    if why:
        pytest.skip(f"cannot build the AOT kernels here: {why}")
    folder = tmp_path_factory.mktemp("aot")
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "build", "--quiet", "--duration", "3"],
                         env=_env(folder), capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    return folder


RUN = r"""
import json, sys
from dynslam2d.cli import main
if sys.argv[2] == "fallback":  # a call of types the AOT module lacks first: the whole process turns to numba
    import numpy as np
    from dynslam2d.detect.freespace import _ref_arrays
    _ref_arrays(np.ones(4, np.float32), np.ones(4, bool), -1.5, 0.2, 0.0, 0.0, 0.0, 0.1, 30.0)
sys.argv = ["dynslam2d", "run", "sim:paper", "--duration", "4", "--out", sys.argv[1], "-q"]
try:
    main()
except SystemExit as exc:
    assert exc.code in (0, None), exc.code
from dynslam2d import jitaot, jitbox
print(json.dumps({"numba": "numba" in sys.modules, "llvmlite": "llvmlite" in sys.modules,
                  "aot": jitbox.AOT is not None, "in_use": jitaot.in_use(), "note": jitaot.unused_reason("IN")}))
"""

#: Result files of a run that hold what the kernels computed (the summary and run.json hold timings).
RESULTS = ("map_logodds.npy", "map_logodds_online.npy", "kept_mask.npz", "map.pgm", "map_online.pgm",
           "trajectory.tum", "trajectory_frontend.tum", "tracks.csv", "graph.g2o")


def test_aot_run_gives_the_jit_runs_bytes_without_numba(built: Path, tmp_path: Path) -> None:
    out = {}
    for mode in ("jit", "auto", "fallback"):
        env = _env(built, "auto" if mode == "fallback" else mode)
        res = subprocess.run([sys.executable, "-c", RUN, str(tmp_path / mode), mode], env=env,
                             capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stderr[-2000:]
        out[mode] = json.loads(res.stdout.strip().splitlines()[-1])
    notes = {mode: out[mode].pop("note") for mode in out}
    assert out["jit"] == {"numba": True, "llvmlite": True, "aot": False, "in_use": "jit"}
    assert out["auto"] == {"numba": False, "llvmlite": False, "aot": True, "in_use": "aot"}
    # switched to numba's kernels by the first call (float32 ranges), and the run's note names that kernel
    assert out["fallback"] == {"numba": True, "llvmlite": True, "aot": False, "in_use": "aot+jit"}
    assert notes["jit"] is None and notes["auto"] is None  # (jit: the user's choice, nothing to say)
    assert "lack the argument types of a call of dynslam2d.detect.freespace._ref_arrays" in notes["fallback"]
    assert "dynslam2d kernels build --input IN" in notes["fallback"]
    compared = 0
    for name in RESULTS:
        a = tmp_path / "jit" / name
        for other in ("auto", "fallback"):
            b = tmp_path / other / name
            assert a.is_file() == b.is_file(), name
            if a.is_file():
                assert a.read_bytes() == b.read_bytes(), (other, name)
                compared += 1
    assert compared >= 12


CALL = r"""
import sys, numpy as np
from dynslam2d.slam.raycast import ray_ends
from dynslam2d.jitaot import KernelArgumentError
assert "numba" not in sys.modules
h = np.linspace(1.0, 5.0, 16).reshape(8, 2)
cl = np.linspace(-2.0, 2.0, 8).reshape(4, 2)
good = ray_ends(h, cl, 1.0, 0.0, 0.0, 0.0)
bad = {"dtype": (h.astype(np.float32), cl), "ndim": (h.ravel(), cl), "strided": (np.repeat(h, 2, axis=0)[::2], cl),
       "clear": (h, cl.astype(np.int64))}
for what, (a, m) in bad.items():
    try:
        ray_ends(a, m, 1.0, 0.0, 0.0, 0.0)
    except KernelArgumentError as exc:
        print(what, "refused:", exc)
    else:
        print(what, "ACCEPTED")
print("numba" in sys.modules, type(good).__name__)
"""


def test_aot_kernel_refuses_wrong_arrays_without_crashing(built: Path) -> None:
    # DYNSLAM2D_KERNELS=aot: the AOT module and no fallback to numba
    res = subprocess.run([sys.executable, "-c", CALL], env=_env(built, "aot"), capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    lines = res.stdout.strip().splitlines()
    assert lines[-1] == "False tuple"
    assert len([ln for ln in lines if "refused: kernel dynslam2d.slam.raycast.ray_ends" in ln]) == 4, lines


def test_stale_or_foreign_module_is_not_loaded(built: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert jitaot.status(built).valid
    from dynslam2d import jitcache

    monkeypatch.setattr(jitcache, "kernel_sources_fingerprint", lambda: "0123456789abcdef")  # a kernel edited
    st = jitaot.status(built)
    assert st.present and not st.valid and "kernel sources changed" in st.reason
    monkeypatch.undo()
    copy = tmp_path / "copy"
    copy.mkdir()
    for path in built.iterdir():
        (copy / path.name).write_bytes(path.read_bytes())
    side = json.loads((copy / jitaot.SIDECAR).read_text())
    side["key"]["cpu"] = "another"
    (copy / jitaot.SIDECAR).write_text(json.dumps(side))
    probe = ("import sys, dynslam2d.pipeline; from dynslam2d import jitbox; "
             "print(jitbox.AOT is None, 'numba' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", probe], env=_env(copy), capture_output=True, text=True, timeout=300)
    assert res.stdout.split() == ["True", "True"], res.stderr[-2000:]
    assert "another CPU" in jitaot.status(copy).reason
    res = subprocess.run([sys.executable, "-c", probe], env=_env(built, "jit"), capture_output=True, text=True,
                         timeout=300)
    assert res.stdout.split() == ["True", "True"], res.stderr[-2000:]  # DYNSLAM2D_KERNELS=jit
    res = subprocess.run([sys.executable, "-c", probe], env=_env(built), capture_output=True, text=True, timeout=300)
    assert res.stdout.split() == ["False", "False"], res.stderr[-2000:]


def test_kernels_status_and_clear_commands(built: Path, tmp_path: Path) -> None:
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "status", "--json"], env=_env(built),
                         capture_output=True, text=True, timeout=120)
    row = json.loads(res.stdout)
    exports = json.loads((built / jitaot.SIDECAR).read_text())["exports"]
    assert row["valid"] and row["used"] and row["kernels"] == len(exports) and row["folder"] == str(built)
    # the build holds every kernel the README's first command compiles (the manifest's, recorded from a real run)
    assert {qual for qual, _types in jitmanifest.KERNELS} <= set(exports)
    # the build left its module under its content-hash name, the sidecar naming it, its lock file: nothing else
    assert sorted(p.name for p in built.iterdir()) == sorted([jitaot.SIDECAR, jitaot.LOCK, row["file"]])
    assert row["file"].startswith(f"{jitaot.MODULE_NAME}-{row['sha256'][:16]}.") and row["numba"] and row["built"]
    empty = tmp_path / "none"
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "status", "--json"], env=_env(empty),
                         capture_output=True, text=True, timeout=120)
    assert json.loads(res.stdout)["present"] is False
    copy = tmp_path / "copy"
    copy.mkdir()
    for path in built.iterdir():
        (copy / path.name).write_bytes(path.read_bytes())
    res = subprocess.run([sys.executable, "-m", "dynslam2d", "kernels", "clear"], env=_env(copy),
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "removed 2" in res.stdout
    assert not jitaot.status(copy).present


FALLBACK = r"""
import json, sys, numpy as np
from dynslam2d.detect import freespace
from dynslam2d.slam import correlative
from dynslam2d.detect.freespace import _ref_arrays
started_without_numba = "numba" not in sys.modules
r = np.linspace(1.0, 5.0, 16)
ok = np.ones(16, dtype=bool)
args = (-1.5, 0.2, 0.0, 0.0, 0.0, 0.1, 30.0)
out = [_ref_arrays(r.astype(np.float32), ok, *args), _ref_arrays(r, ok, *args)]
from dynslam2d.slam.grid import encode_probs
prob = encode_probs(np.random.default_rng(1).random((12, 10)))  # (a level's probability cache words)
frozen = prob.copy()
frozen.flags.writeable = False  # read-only: a type the AOT module lacks
out.append(correlative._score_pyramid(frozen, 2))
out.append(correlative._score_pyramid(prob, 2))
print(json.dumps({"started_without_numba": started_without_numba, "numba": "numba" in sys.modules,
                  "module_kernel": type(freespace._ref_arrays).__name__,
                  "bytes": [[np.asarray(a).tobytes().hex() for a in (o if isinstance(o, tuple) else (o,))]
                            for o in out]}))
"""


def test_types_the_module_lacks_fall_back_to_numba(built: Path) -> None:
    res = {}
    for mode in ("auto", "jit"):
        run = subprocess.run([sys.executable, "-c", FALLBACK], env=_env(built, mode), capture_output=True, text=True,
                             timeout=300)
        assert run.returncode == 0, run.stderr[-2000:]
        res[mode] = json.loads(run.stdout.strip().splitlines()[-1])
    assert res["auto"]["started_without_numba"] and res["auto"]["numba"]
    assert res["auto"]["module_kernel"] == "CPUDispatcher"  # the module's global is numba's dispatcher now
    assert res["auto"]["bytes"] == res["jit"]["bytes"]


def test_batch_workers_use_the_aot_module(built: Path, tmp_path: Path) -> None:
    # every process of `dynslam2d batch -j 2` (the command and its two spawned workers) lists its imports on stderr;
    # with a valid module none imports numba, with DYNSLAM2D_KERNELS=jit the workers do (the probe sees them)
    imported = {}
    for mode in ("auto", "jit"):
        env = dict(_env(built, mode), PYTHONPROFILEIMPORTTIME="1")
        res = subprocess.run([sys.executable, "-m", "dynslam2d", "batch", "sim:paper", "--set",
                              "filter.mode=none,box", "--duration", "2", "-j", "2", "-o", str(tmp_path / mode)],
                             env=env, capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stderr[-3000:]
        rows = [ln.rsplit("|", 1)[-1].strip() for ln in res.stderr.splitlines() if ln.startswith("import time:")]
        imported[mode] = {"numba": rows.count("numba"), "llvmlite": rows.count("llvmlite"),
                          "workers": rows.count("dynslam2d.slam.matcher")}
    assert imported["auto"]["numba"] == imported["auto"]["llvmlite"] == 0, imported
    assert imported["auto"]["workers"] >= 2 and imported["jit"]["numba"] >= 2, imported


def test_ray_workers_use_the_kernels_the_driver_chose(built: Path, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    # Ray started here before the choice: its workers inherit this process's environment (the suite's
    # DYNSLAM2D_KERNELS=jit, no kernel folder), so only the tasks' runtime_env gives them the driver's later one
    ray = pytest.importorskip("ray", reason="Ray is not installed (the optional extra: pip install "
                                            "'dynslam2d[cluster]')")
    from dynslam2d.batch import make_jobs, run_batch

    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    kernels = {}
    try:
        for mode in ("auto", "jit"):
            monkeypatch.setenv(jitaot.MODE_ENV, mode)
            monkeypatch.setenv(jitaot.DIR_ENV, str(built))
            res = run_batch(make_jobs(["sim:paper"], [], None, {"duration": 2.0}), tmp_path / mode, ray="auto")
            assert [o.status for o in res.outcomes] == ["done"], [o.error for o in res.outcomes]
            kernels[mode] = res.outcomes[0].value["kernels"]  # the worker's jitaot.in_use()
            assert json.loads((tmp_path / mode / "batch.json").read_text())["runs"][0]["kernels"] == kernels[mode]
    finally:
        if started:
            ray.shutdown()
    assert kernels == {"auto": "aot", "jit": "jit"}
