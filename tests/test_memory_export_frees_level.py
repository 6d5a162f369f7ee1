"""The finest level's export lets go of the level's arrays as it reads them (``_MapExport.of(take=True)``: the end
of the run loop and of the loop closure's re-render, issue 13 item 3): the same export, the level's arrays freed,
the update indices before the log-odds are copied."""

from __future__ import annotations

import gc
import weakref

import numpy as np


def _map():
    from dynslam2d.slam.grid import MultiResMap

    rng = np.random.default_rng(8)
    m = MultiResMap(0.05, 2, -0.4, 0.85)
    for lv in m.levels:
        lv.ensure(0, 0, 399, 299)
        lv.logodds[:] = rng.normal(0.0, 3.0, lv.shape).astype(np.float32)
        lv.uidx[:] = np.where(rng.uniform(size=lv.shape) < 0.6, 4, 0).astype(np.int32)
        lv.uidx[:20] = 0  # (unobserved rows and columns: the export crops them)
        lv.uidx[:, -30:] = 0
    return m


class _Probe(np.ndarray):
    """Log-odds whose copy checks that the level's update indices are gone by then."""

    uidx_ref: weakref.ref | None = None

    def copy(self, *a, **k):  # type: ignore[override]
        gc.collect()
        assert _Probe.uidx_ref is not None and _Probe.uidx_ref() is None, "update indices alive at the copy"
        return np.asarray(self).copy(*a, **k)


def test_taken_export_is_the_same_and_frees_the_level() -> None:
    from dynslam2d.pipeline import _MapExport

    a = _MapExport.of(_map())
    m = _map()
    lv = m.levels[0]
    lv.logodds = lv.logodds.view(_Probe)
    refs = [weakref.ref(lv.logodds), weakref.ref(lv.uidx), weakref.ref(lv.prob)]
    _Probe.uidx_ref = refs[1]
    try:
        b = _MapExport.of(m, take=True)
    finally:
        _Probe.uidx_ref = None
    gc.collect()
    assert all(r() is None for r in refs)  # the level's three arrays are freed
    assert lv.empty and lv.nbytes == 0
    assert type(b.logodds) is np.ndarray and b.logodds.dtype == np.float32
    np.testing.assert_array_equal(a.logodds, b.logodds)
    np.testing.assert_array_equal(a.unknown, b.unknown)
    full = _map().levels[0].shape
    assert a.logodds.shape[0] < full[0] and a.logodds.shape[1] < full[1]  # (cropped)
    assert a.origin == b.origin and a.resolution == b.resolution


def test_export_without_take_leaves_the_level() -> None:
    from dynslam2d.pipeline import _MapExport

    m = _map()
    lv = m.levels[0]
    before = lv.logodds.copy(), lv.uidx.copy()
    _MapExport.of(m)
    np.testing.assert_array_equal(lv.logodds, before[0])
    np.testing.assert_array_equal(lv.uidx, before[1])
