"""``ledgerkernels.kept_beams`` (the evidence ledger's per-track kept beams, kept for the loop closer): the same
beams, dtype and per-track bounds as the numpy gather it replaced in ``EvidenceLedger.before_update``."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.slam.ledgerkernels import kept_beams


def _reference(valid: np.ndarray, beams: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    vb = valid[beams]
    cs = np.concatenate(([0], np.cumsum(vb)))
    return beams[vb].astype(np.int32), cs[ends]


@pytest.mark.parametrize("seed", range(6))
def test_kept_beams_equal_the_numpy_gather(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 700))
    valid = rng.random(n) < (0.0 if seed == 0 else 0.8)
    lens = rng.integers(0, 12, int(rng.integers(1, 30)))  # some tracks list no beam
    beams = rng.integers(-n, n, int(lens.sum())).astype(np.int64)  # negative: from the end, as numpy
    ends = np.concatenate(([0], np.cumsum(lens))).astype(np.int64)
    kb, bounds = kept_beams(valid, beams, ends)
    ref_kb, ref_b = _reference(valid, beams, ends)
    assert kb.dtype == np.int32 and np.array_equal(kb, ref_kb) and np.array_equal(bounds, ref_b)
    if seed:
        assert (kb < 0).any() and kb.shape[0] < beams.shape[0]
    for t in range(lens.shape[0]):  # each track's part is its own beams that are valid
        part = beams[ends[t]:ends[t + 1]]
        assert np.array_equal(kb[bounds[t]:bounds[t + 1]], part[valid[part]])


def test_kept_beams_rejects_a_beam_outside_the_scan() -> None:
    with pytest.raises(IndexError):
        kept_beams(np.ones(4, dtype=bool), np.array([1, 4], dtype=np.int64), np.array([0, 2], dtype=np.int64))
