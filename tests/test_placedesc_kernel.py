"""The place index's ring-correlation kernel and batched descriptors (slam/placedesc.py) against plain NumPy."""

from __future__ import annotations

import numpy as np

from dynslam2d.slam.placedesc import (
    PlaceIndex,
    _ring_correlation,
    _spectra,
    _spectra_many,
    polar_descriptor,
    polar_descriptors,
)


def _reference(q_cols: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
    """The computation the kernel replaced: NumPy's einsum over the rings of the conjugated stored spectra."""
    return np.einsum("rf,nrf->nf", q_cols, np.conj(cols[:n]))


def _clouds(rng: np.random.Generator, k: int) -> list[np.ndarray]:
    """``k`` point sets like a place's (a few hundred points within ±20 m), some empty, some with NaN / inf."""
    out = []
    for i in range(k):
        n = 0 if i % 7 == 3 else int(rng.integers(1, 600))
        p = rng.normal(0.0, 8.0, (n, 2))
        if n and i % 5 == 1:
            p[rng.integers(n)] = (np.nan, 1.0)
            p[rng.integers(n)] = (np.inf, -2.0)
        if n and i % 4 == 2:  # points exactly on sector and ring borders
            p[: min(n, 4)] = [(-3.0, 0.0), (0.0, 0.0), (15.0, 0.0), (0.0, -7.5)][: min(n, 4)]
        out.append(p)
    return out


def test_ring_correlation_equals_einsum_bit_for_bit() -> None:
    """Random spectra of every shape class (and the descriptors' own: 20 rings, 31 frequencies, up to 700
    places) give the einsum's complex128 values bit for bit, including the first-n prefix of a larger store."""
    rng = np.random.default_rng(13)
    for _ in range(200):
        rings, nf, n = int(rng.integers(1, 30)), int(rng.integers(1, 40)), int(rng.integers(1, 60))
        q = rng.standard_normal((rings, nf)) + 1j * rng.standard_normal((rings, nf))
        cols = (rng.standard_normal((n + 3, rings, nf)) + 1j * rng.standard_normal((n + 3, rings, nf)))
        cols = cols.astype(np.complex64)
        got = _ring_correlation(q, cols, n)
        assert got.dtype == np.complex128 and got.shape == (n, nf)
        assert got.tobytes() == _reference(q, cols, n).tobytes()
    descs = polar_descriptors(_clouds(rng, 700), 20, 60, 15.0)
    cols, _occ, _count = _spectra_many(descs)
    stored = cols.astype(np.complex64)
    for i in (0, 5, 699):
        q = _spectra(descs[i])[0]
        for n in (1, 64, 700):
            assert _ring_correlation(q, stored, n).tobytes() == _reference(q, stored, n).tobytes()
    assert _ring_correlation(q, stored, 0).shape == (0, 31)


def test_batched_descriptors_and_spectra_equal_one_at_a_time() -> None:
    """polar_descriptors and _spectra_many give each place's polar_descriptor and _spectra bit for bit, and
    PlaceIndex.add_many the same index (spectra, counts, keys, distances) as add in turn."""
    rng = np.random.default_rng(4)
    clouds = _clouds(rng, 37)
    batch = polar_descriptors(clouds, 20, 60, 15.0)
    assert batch.dtype == np.float32 and batch.shape == (37, 20, 60)
    for p, d in zip(clouds, batch):
        assert d.tobytes() == polar_descriptor(p, 20, 60, 15.0).tobytes()
    cols, occ, count = _spectra_many(batch)
    for i, d in enumerate(batch):
        c1, o1, n1 = _spectra(d)
        assert cols[i].tobytes() == c1.tobytes() and occ[i].tobytes() == o1.tobytes() and int(count[i]) == n1
    one, many = PlaceIndex(20, 60, 15.0), PlaceIndex(20, 60, 15.0)
    keys = [3 * i + 1 for i in range(37)]
    for k, p in zip(keys, clouds):
        one.add(k, one.describe(p))
    many.add_many(keys[:16], many.describe_many(clouds[:16]))  # grows the 16-row store inside a batch
    many.add_many(keys[16:], many.describe_many(clouds[16:]))
    many.add_many([], many.describe_many([]))
    assert len(one) == len(many) == 37 and one.keys.tolist() == many.keys.tolist() == keys
    for name in ("_cols", "_occ", "_count"):
        assert getattr(one, name)[:37].tobytes() == getattr(many, name)[:37].tobytes(), name
    q = one.describe(clouds[8])
    for a, b in zip(one.distances(q), many.distances(q)):
        assert a.tobytes() == b.tobytes()
    assert 31 in many and many.distances_of(31)[1].tobytes() == one.distances_of(31)[1].tobytes()
