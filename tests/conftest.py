"""Shared test fixtures.

Real datasets live in ``../shared/data`` beside the repository (CI has it; a
user's machine usually does not). Tests that need them take the ``shared_data``
fixture (or call ``shared_file``) and are skipped with a clear reason when the folder is absent;
``pytest_collection_modifyitems`` below marks all of them ``shared_data``.
"""

from __future__ import annotations

import inspect
import os
import types
from pathlib import Path

import pytest

#: The suite tests numba's JIT kernels (their compile clock, cache, manifest, IR), in this process and in the
#: processes it starts, even when the user has built the kernels ahead of time (``dynslam2d kernels build``): a valid
#: AOT module would replace them. The AOT path has its own tests (tests/test_jitaot.py), which set the mode per process.
os.environ["DYNSLAM2D_KERNELS"] = "jit"

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("DYNSLAM2D_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))


def shared_file(relative: str) -> Path:
    """Path of a file under ../shared/data, skipping the test if it is absent."""
    path = SHARED_DATA / relative
    if not path.exists():
        pytest.skip(f"real dataset {relative} not found under {SHARED_DATA} (only in CI / with ../shared/data)")
    return path


@pytest.fixture
def shared_data() -> Path:
    """The ../shared/data folder; skips the test when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real datasets not available: {SHARED_DATA} does not exist")
    return SHARED_DATA


SHARED_NAMES = frozenset({"shared_file", "shared_data", "SHARED_DATA"})


def _uses_shared_data(code: types.CodeType, module: types.ModuleType, seen: set) -> bool:
    """Whether ``code`` (or a nested function, or a function of its own test module it calls) names
    the shared-data helpers; found by the names the bytecode refers to, so no test has to be run."""
    if code in seen:
        return False
    seen.add(code)
    names = set(code.co_names) | set(code.co_varnames)
    if names & SHARED_NAMES:
        return True
    for const in code.co_consts:
        if isinstance(const, types.CodeType) and _uses_shared_data(const, module, seen):
            return True
    for name in code.co_names:
        obj = getattr(module, name, None)
        if inspect.isfunction(obj) and obj.__module__ == module.__name__:
            if _uses_shared_data(obj.__code__, module, seen):
                return True
    return False


def pytest_collection_modifyitems(config, items):
    """Mark every test that needs ../shared/data with ``shared_data``, whether it takes the
    ``shared_data`` fixture or calls ``shared_file`` (directly or through a helper of its module), so
    ``pytest -m "not shared_data"`` selects exactly the tests that run without the datasets."""
    for item in items:
        func = getattr(item, "function", None)
        if func is None:
            continue
        uses = "shared_data" in getattr(item, "fixturenames", ())
        if not uses:
            uses = _uses_shared_data(inspect.unwrap(func).__code__, item.module, set())
        if uses and item.get_closest_marker("shared_data") is None:
            item.add_marker(pytest.mark.shared_data)


class ScanList:
    """A scan source over scans already in memory (one read of a recording for several runs)."""

    def __init__(self, scans, meta):
        self.scans, self.meta = list(scans), meta

    def __iter__(self):
        return iter(self.scans)

    def __len__(self):
        return len(self.scans)


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    """Run ``dynslam2d ARGS`` in-process: (exit code, stdout, stderr)."""
    import sys

    from dynslam2d.cli import main

    old = sys.argv
    sys.argv = ["dynslam2d", *args]
    code = 0
    try:
        main()
    except SystemExit as exc:
        code = int(exc.code or 0)
    finally:
        sys.argv = old
    out, err = capsys.readouterr()
    return code, out, err


def room_box_scan(pose, box: tuple[float, float, float, float], stamp: float, seed: int, n: int = 360):
    """A simulated 360° scan (n beams, 5 mm range noise) from ``pose`` in a 12 × 10 m room holding one box
    ``(cx, cy, width, height)`` m, map frame; no return = inf."""
    import math

    import numpy as np

    from dynslam2d.sim import cast_rays, rect_segments
    from dynslam2d.types import Scan

    angles = -math.pi + np.arange(n) * 2 * math.pi / n
    segs = np.vstack([rect_segments(0.0, 0.0, 0.0, 12.0, 10.0), rect_segments(box[0], box[1], 0.0, box[2], box[3])])
    ids = np.zeros(segs.shape[0], dtype=np.int32)
    dist, _ = cast_rays((pose.x, pose.y), pose.theta + angles, segs, ids, np.zeros((0, 3)),
                        np.zeros(0, dtype=np.int32))
    r = dist + np.random.default_rng(seed).normal(0.0, 0.005, dist.shape)
    r[~np.isfinite(dist)] = np.inf
    return Scan(stamp=stamp, angle_min=-math.pi, angle_increment=2 * math.pi / n, ranges=r, range_min=0.1,
                range_max=20.0)


def scan_rays(pose, hits, clear, grazing: float, min_sin: float):
    """The rays ``MultiResMap.integrate`` casts for returns ``hits`` (n, 2) and clearing-ray ends ``clear`` (m, 2, or
    None) in the laser frame at ``pose``: (map-frame ends (n + m, 2), hit flags, per-ray free-space stop or None
    when ``grazing`` is 0), for checking its update level by level."""
    import numpy as np

    from dynslam2d.slam.grid import grazing_stop

    ends = pose.transform_points(hits)
    hit = np.ones(ends.shape[0], dtype=bool)
    if clear is not None:
        ends = np.vstack((ends, pose.transform_points(clear)))
        hit = np.concatenate((hit, np.zeros(clear.shape[0], dtype=bool)))
    stop = None
    if grazing > 0.0:
        stop = np.zeros(hit.shape[0])
        stop[: hits.shape[0]] = grazing_stop(hits, grazing, min_sin)
    return ends, hit, stop


def paper_room_scan(pose, stamp: float = 0.0):
    """A noise-free 720-beam scan of the simulator's paper room seen from ``pose`` (map frame, m, rad)."""
    import numpy as np

    from dynslam2d.sim import LidarModel, cast_rays, paper_room

    lidar = LidarModel(beams=720, noise_sigma=0.0)
    dist, _ = cast_rays((pose.x, pose.y), pose.theta + lidar.angles, paper_room().segments)
    ranges, _ = lidar.measure(dist, np.random.default_rng(0))
    return lidar.make_scan(stamp, ranges)


def paper_room_slam(levels: int | None = None):
    """A ``HectorSlam`` (``levels`` map levels, the default when None) whose map holds three noise-free scans of the
    paper room taken around the laser pose (0.3, -0.4, 0.2); returns it and that first pose."""
    from dynslam2d.slam import HectorSlam, SlamConfig
    from dynslam2d.types import Pose2D

    slam = HectorSlam(SlamConfig() if levels is None else SlamConfig(map_levels=levels))
    first = Pose2D(0.3, -0.4, 0.2)
    slam.update_map(paper_room_scan(first), Pose2D(), force=True)
    for d in (Pose2D(0.3, 0.1, 0.1), Pose2D(-0.2, 0.3, -0.15)):
        p = first.compose(d)
        slam.update_map(paper_room_scan(p), first.between(p), force=True)
    return slam, first


def paper_room_slam_points():
    """:func:`paper_room_slam` with the default levels and the laser-frame points (m) of a fourth paper-room scan
    taken 0.2 m ahead of and 0.1 rad turned from its first pose: a map and a scan to search it with."""
    from dynslam2d.types import Pose2D

    slam, first = paper_room_slam()
    pts, _ = slam.scan_points(paper_room_scan(first.compose(Pose2D(0.2, 0.0, 0.1))))
    return slam, pts


# The tail of a subprocess script that checks a patched numba still raises its own typing error: sets ``error`` to
# the error's type and first line ("" if none was raised). Used by the jit-patch tests (test_jitwarm,
# test_jitcache_stack), whose scripts concatenate it.
TYPING_ERROR_PROBE = r"""
import numba
@numba.njit
def bad(x):
    return min(x, "a")
try:
    bad(1.0)
    error = ""
except numba.core.errors.TypingError as e:
    error = type(e).__name__ + str(e).split("\n")[0]
"""
