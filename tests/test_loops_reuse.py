"""The loop closer's reuse of work (docs/speed.md, pass loop18): every result stays the one of the former path.

* far searches read a submap's kept far level instead of rebuilding the submap, and build that level alone for a
  submap never built (pass lcl41);
* the pose graph builds its edge arrays once per optimisation and adds the Levenberg–Marquardt damping to H's
  diagonal itself instead of SciPy's general sparse sum.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from test_loops import _block_loop_world, _drifted, _loop_path, _scans

import dynslam2d.slam.posegraph as pg
from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.loopconfig import LoopConfig
from dynslam2d.slam.loops import LoopCloser
from dynslam2d.types import Pose2D


class _NoKeep(dict):
    """A dict that keeps nothing: the loop closer without its far-level store (the former path)."""

    def __setitem__(self, key, value) -> None:  # noqa: ANN001
        pass


def _whole_grid(lc: LoopCloser) -> None:
    """Let ``lc``'s far searches build a submap's whole grid where they need its far level (the former path)."""
    lc._build_far_level = lambda s: lc._submap(s).levels[min(lc.config.far_level, lc._n_levels() - 1)]


def _run(scans: list, front: np.ndarray, keep: bool, drop_at: int | None = None, drop_sub: int = -1,
         alone: bool | None = None) -> tuple:
    lc = LoopCloser(LoopConfig(), SlamConfig())
    lc._cache_size = 1  # evict at once: every far search on an older submap would rebuild it
    if not keep:
        lc._far_levels = _NoKeep()
    if not (keep if alone is None else alone):
        _whole_grid(lc)
    builds = [0]
    submap = lc._submap_grid

    def counted(s: int):  # noqa: ANN202
        builds[0] += s not in lc._cache
        return submap(s)

    lc._submap_grid = counted
    for k, (s, p) in enumerate(zip(scans, front)):
        lc.add(s.stamp, Pose2D(*p), s, np.zeros(s.ranges.shape, bool), keyframe=k % 2 == 0)
        if drop_at is not None and k == drop_at:
            if keep:
                drop_sub = min(lc._far_levels)
            lc.drop_beams([(lc.keyframes[drop_sub * lc.config.submap_keyframes].scan_index, np.arange(40))])
            assert drop_sub not in lc._far_levels  # its submap changed: its far level goes with it
    return lc, lc.finish(), builds[0], drop_sub


@pytest.fixture(scope="module")
def far_runs() -> tuple:
    world = _block_loop_world()
    gt = _loop_path()
    front = _drifted(gt, 0.006)  # the far search closes this loop (test_loops.py)
    scans = _scans(world, gt)
    return scans, front, _run(scans, front, True), _run(scans, front, False)


def _same(a, b) -> None:  # noqa: ANN001
    assert np.array_equal(a.poses, b.poses) and np.array_equal(a.node_poses, b.node_poses)
    assert a.loops == b.loops
    assert {k: v for k, v in a.stats.items() if not k.endswith("_ms")} == {
        k: v for k, v in b.stats.items() if not k.endswith("_ms")}


def test_far_levels_kept_give_the_same_loops_with_fewer_submap_builds(far_runs: tuple) -> None:
    _scans_, _front, (lc, res, builds, _s), (_lc0, res0, builds0, _s0) = far_runs
    assert lc.stats["far_searches"] > 20 and lc.stats["far_loops"] >= 3 and res.corrected
    _same(res, res0)
    assert builds < builds0  # far searches read the kept levels (each far level is a few kB)
    assert not lc._far_levels  # finish lets them go with the grids


def test_drop_beams_drops_the_far_level_of_its_submap(far_runs: tuple) -> None:
    scans, front, _new, _old = far_runs
    lc, res, _b, s = _run(scans, front, True, drop_at=len(scans) * 3 // 4)
    _lc0, res0, _b0, _s = _run(scans, front, False, drop_at=len(scans) * 3 // 4, drop_sub=s)
    _same(res, res0)


def test_far_level_built_alone_is_the_whole_grids_level(far_runs: tuple) -> None:
    _scans_, _front, (lc, _res, _b, _s), _old = far_runs
    lc2 = LoopCloser(lc.config, lc.slam)
    lc2.keyframes = lc.keyframes
    k = min(lc.config.far_level, lc._n_levels() - 1)
    n = len(lc.keyframes) // lc.config.submap_keyframes
    assert n >= 5
    for s in range(n):
        whole = lc2._submap(s).levels[k]
        cached = list(lc2._cache)
        alone = lc2._build_far_level(s)
        assert lc2._far_levels[s] is alone and list(lc2._cache) == cached  # kept with the far levels, not cached
        assert alone.resolution == whole.resolution and alone.shape == whole.shape
        assert (alone.i0, alone.j0) == (whole.i0, whole.j0)
        assert alone.prob.dtype == whole.prob.dtype and np.array_equal(alone.prob, whole.prob)
        assert alone.prob.any()


def test_far_levels_built_alone_give_the_same_loops_with_fewer_submap_builds(far_runs: tuple) -> None:
    scans, front, (_lc, res, builds, _s), _old = far_runs
    lc0, res0, builds0, _s0 = _run(scans, front, True, alone=False)
    _same(res, res0)
    assert lc0.stats["far_searches"] > 20
    assert builds < builds0  # far searches of submaps never built build their far level alone


def _random_h(rng: np.random.Generator, diag: bool = True) -> sp.csc_matrix:
    n = int(rng.integers(3, 40))
    m = int(rng.integers(n, 5 * n))
    r = rng.integers(0, n, m)
    c = rng.integers(0, n, m)
    if diag:
        r, c = np.r_[r, np.arange(n)], np.r_[c, np.arange(n)]
    v = rng.normal(size=r.size)
    v[rng.random(v.size) < 0.3] = 0.0  # stored zeros (the Jacobians' structural zeros give some)
    v[rng.random(v.size) < 0.1] = -0.0
    return sp.coo_matrix((v, (r, c)), shape=(n, n)).tocsc()[1:, 1:]


@pytest.mark.parametrize("diag", [True, False])
def test_damped_is_scipys_sum_bit_for_bit(diag: bool) -> None:
    rng = np.random.default_rng(18)
    for _ in range(300):
        h = _random_h(rng, diag)
        d = rng.random(h.shape[0]) * 10.0 ** rng.integers(-12, 3) + 1e-12
        a = h + sp.diags(d)
        b = pg._damped(h, d, sp)
        assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
        assert np.array_equal(a.data, b.data) and np.array_equal(np.signbit(a.data), np.signbit(b.data))


def _graph(rng: np.random.Generator) -> pg.PoseGraph:
    g = pg.PoseGraph()
    p = np.zeros(3)
    g.add_node(p)
    for k in range(1, 60):
        z = np.array([0.5, 0.0, 0.1]) + rng.normal(0, 0.02, 3)
        p = pg.compose(p, z)
        g.add_node(p + rng.normal(0, 0.05, 3))
        g.add_diag_edge(k - 1, k, z, 0.05, 0.01)
    for _ in range(8):  # loops, a few of them wrong
        i, j = sorted(rng.choice(60, 2, replace=False))
        z = pg.relative(g.poses[i], g.poses[j]) + rng.normal(0, 0.3 if rng.random() < 0.3 else 0.01, 3)
        g.add_edge(int(i), int(j), z, pg.diag_info(0.1, 0.05), loop=True)
    return g


def test_optimise_equals_the_former_path(monkeypatch: pytest.MonkeyPatch) -> None:
    for seed in range(4):
        a = _graph(np.random.default_rng(seed))
        b = _graph(np.random.default_rng(seed))
        ra = a.optimise("dcs", 1.0, 30, 9.0)
        with monkeypatch.context() as m:  # the former path: arrays from the edges at every use, SciPy's sum
            m.setattr(pg, "_damped", lambda h, d, s: h + s.diags(d))
            def former(self, rep, *args, real=pg.PoseGraph._optimise):  # noqa: ANN001, ANN202
                self._all = None  # chi2 and every solve build their arrays from the edges
                return real(self, rep, *args)

            m.setattr(pg.PoseGraph, "_optimise", former)
            rb = b.optimise("dcs", 1.0, 30, 9.0)
        assert np.array_equal(a.poses, b.poses)
        assert ra.iterations == rb.iterations and ra.cost_end == rb.cost_end
        assert ra.rejected_loops == rb.rejected_loops
        assert [e.weight for e in a.edges] == [e.weight for e in b.edges]
