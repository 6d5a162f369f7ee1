"""A scan's births in one batch (``Tracker._births`` with ``kernels_update.birth_rows``, docs/speed.md pass trk38)
against the former per-detection ``Tracker._birth``: two pipelines in lockstep over simulated scenes (with the SLAM
map, so the map evidence is written too), one of them making its births one by one; after every scan every live
track's record and rows (state, covariance, shape, counters, last hit, windows, birth place) are the same, bit for
bit, and births of every kind (rectangle, circle, point) happened."""

from __future__ import annotations

import numpy as np

from dynslam2d.config import Config
from dynslam2d.detect.layout import KIND_NAMES
from dynslam2d.pipeline import Pipeline
from dynslam2d.sim import simulate


def _one_by_one(tr):
    """``_births`` as the former loop of ``_birth`` calls (each birth's id added to ``updated``)."""

    def births(dets, t, js, updated):
        for j in js:
            tr._birth(dets[j], t, j)
            updated.add(tr._tracks[-1].id)

    return births


def _rows(tr, k) -> tuple:
    r = k.row
    nm = tr._WN.item(r, 0)
    return (tr._X[r].tobytes(), tr._P[r].tobytes(), tr._G[r].tobytes(), tr._Gi[r].tobytes(), tr._CI[r].tobytes(),
            tr._CL[r].tobytes(), tr._WN[r].tobytes(), tr._MEV[r, :nm].tobytes(), np.asarray(k.birth_xy).tobytes(),
            # (each view of its own row: the tables are views of two buffers since pass trk129)
            np.shares_memory(k.x, tr._X[r]), np.shares_memory(k.P, tr._P[r]), np.shares_memory(k.g, tr._G[r]),
            np.shares_memory(k.gi, tr._Gi[r]), np.shares_memory(k.ci, tr._CI[r]), np.shares_memory(k.cl, tr._CL[r]))


def _fields(k) -> tuple:
    return (k.id, k.row, k.born, k.beams.tobytes(), len(k.free), len(k.past), k.past_a, k.reason, k.fast, k.in_m,
            k.state, k.hits, k.misses, k.last_hit, k.kind, k.size, k.size_known, k.radius, k.theta_box)


def test_births_in_one_batch_equal_the_births_one_by_one() -> None:
    kinds = {name: 0 for name in KIND_NAMES}
    births = 0
    for name, seed, duration in (("crowd", None, 12.0), ("drive", 11, 20.0)):
        pa, pb = Pipeline(Config()), Pipeline(Config())
        ta, tb = pa.tracker, pb.tracker
        tb._births = _one_by_one(tb)
        own = ta._births

        def counted(dets, t, js, updated, _own=own, _tr=ta):
            nonlocal births
            _own(dets, t, js, updated)
            births += len(js)
            for k in _tr._tracks[len(_tr._tracks) - len(js):]:
                kinds[k.kind] += 1

        ta._births = counted
        for scan in simulate(name, seed=seed, duration=duration).scans:
            pa.process(scan)
            pb.process(scan)
            assert len(ta._tracks) == len(tb._tracks)
            assert ta._free_rows == tb._free_rows and ta._next_id == tb._next_id
            for ka, kb in zip(ta._tracks, tb._tracks):
                assert _fields(ka) == _fields(kb), ka.id
                assert _rows(ta, ka) == _rows(tb, kb), ka.id
            assert ta.stats == tb.stats
    assert births > 50
    assert all(n > 0 for n in kinds.values()), kinds
