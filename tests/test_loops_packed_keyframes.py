"""The loop closer's keyframes keep their ranges packed (issue 13 item 3, docs/speed.md pass mem44): every range
reads back bit for bit, in the narrowest codes that hold it; the closer's per-scan poses and nodes move into arrays."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.slam import loops
from dynslam2d.slam.loops import _PACK_BATCH, _PACK_SCALES, LoopCloser, _pack_codes
from dynslam2d.types import Pose2D, Scan


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype == np.float64 and a.shape == b.shape and np.array_equal(a.view(np.int64),
                                                                                      b.view(np.int64))


def _decoded(codes: np.ndarray, scale: float) -> np.ndarray:
    return codes.astype(np.float64) / scale if scale else codes.astype(np.float64)


def test_codes_read_back_bit_for_bit_in_the_narrowest_dtype() -> None:
    rng = np.random.default_rng(44)
    for decimals, top, dtype, scale in ((2, 81.91, np.uint16, 100.0), (3, 30.0, np.uint16, 1000.0),
                                        (3, 120.0, np.uint32, 1000.0), (0, 5000.0, np.uint16, 1.0),
                                        (1, 60.0, np.uint16, 10.0)):
        for _ in range(50):
            # ranges as a log's text gives them: decimals parsed to the nearest float64
            txt = [f"{v:.{decimals}f}" for v in rng.uniform(0.0, top, (3, 361)).ravel()]
            r = np.array([float(t) for t in txt]).reshape(3, 361)
            r[0, :4] = (0.0, top, float(f"{top:.{decimals}f}"), 0.05 if decimals >= 2 else 1.0)
            codes, s = _pack_codes(r, _PACK_SCALES)
            assert codes.dtype == dtype and s == scale, (decimals, top, codes.dtype, s)
            assert _same_bits(_decoded(codes, s), r)
    # float32 values (a ROS bag's ranges), also with no-return values: float32 codes
    f = rng.uniform(0.0, 30.0, (2, 720)).astype(np.float32)
    f[0, :3] = (np.nan, np.inf, -np.inf)
    codes, s = _pack_codes(f.astype(np.float64), _PACK_SCALES)
    assert codes.dtype == np.float32 and s == 0.0 and _same_bits(_decoded(codes, s), f.astype(np.float64))
    # neither a decimal nor a float32 value: nothing packs it (the closer then keeps the float64 values)
    g = rng.uniform(0.0, 30.0, (1, 100))
    assert _pack_codes(g, _PACK_SCALES) is None
    # a negative range and NaN leave the decimal codes out (NaN, −0.0 and negatives are float32 values)
    h = np.array([[1.25, -0.5, np.nan, -0.0]])
    codes, s = _pack_codes(h, _PACK_SCALES)
    assert s == 0.0 and _same_bits(_decoded(codes, s), h)


def _scan(k: int, rng: np.random.Generator, kind: str) -> Scan:
    n = 181
    if kind == "cm":
        r = np.array([float(f"{v:.2f}") for v in rng.uniform(0.5, 20.0, n)])
    elif kind == "float32":
        r = rng.uniform(0.5, 20.0, n).astype(np.float32).astype(np.float64)
        r[::17] = np.nan
    else:
        r = rng.uniform(0.5, 20.0, n)
    r[::29] = float(np.float32(81.91)) if kind == "float32" else 81.91  # beyond range_max: no return
    return Scan(float(k), -math.pi / 2, math.pi / (n - 1), r, 0.1, 30.0)


def test_closer_packs_its_keyframes_and_gives_the_same_scans_and_points() -> None:
    rng = np.random.default_rng(7)
    for kind in ("cm", "float32", "plain"):
        closer = LoopCloser()
        scans, removed = [], []
        n_kf = 2 * _PACK_BATCH + 5
        for k in range(n_kf + 3):
            sc = _scan(k, rng, kind)
            rm = np.zeros(sc.n_beams, dtype=bool)
            if k % 5 == 0:
                rm[rng.integers(0, sc.n_beams, 7)] = True
            scans.append(sc)
            removed.append(rm)
            # the front end's pose, and a keyframe on every scan but three (0.5 m apart: a new keyframe each time)
            closer.add(sc.stamp, Pose2D(0.5 * k, 0.1 * math.sin(k), 0.02 * k), sc, rm, keyframe=k % 23 != 22)
        kfs = closer.keyframes
        assert len(kfs) == n_kf
        packed = [kf for kf in kfs if kf._codes is not None]
        assert len(packed) == 2 * _PACK_BATCH  # the batches so far; the last keyframes wait for the next one
        want = {"cm": (np.uint16, 2), "float32": (np.float32, 4), "plain": (np.float64, 8)}[kind]
        for kf in kfs:
            sc, rm = scans[kf.scan_index], removed[kf.scan_index]
            got = kf.scan
            assert _same_bits(got.ranges, sc.ranges)
            assert np.array_equal(got.valid_mask(), sc.valid_mask())
            assert (got.stamp, got.angle_min, got.angle_increment, got.range_min, got.range_max) == (
                sc.stamp, sc.angle_min, sc.angle_increment, sc.range_min, sc.range_max)
            if kf._codes is not None:
                assert kf._codes.dtype == want[0] and kf._codes.nbytes == want[1] * sc.n_beams
                assert kf._scan.ranges.size == 0 and kf._scan._valid is None  # the shell holds no beams
                assert kf.removed.size == (sc.n_beams if rm.any() else 0)
            # the points every submap and query is built from, and the kept scan of the re-render
            ref = closer._scan_points(sc, rm)
            pts = closer._points(kf)
            assert all(np.array_equal(a, b) for a, b in zip(ref, pts))
            assert _same_bits(kf.kept().ranges, sc.without(rm).ranges)
        res = closer.finish()
        assert all(kf._codes is not None for kf in kfs)  # finish packs the rest
        # the per-scan poses moved into arrays give the front end's poses back
        want_poses = np.array([[0.5 * k, 0.1 * math.sin(k), 0.02 * k] for k in range(n_kf + 3)])
        assert np.array_equal(res.frontend, want_poses) and closer.next_index == n_kf + 3
        assert res.keyframe_scans.tolist() == [k for k in range(n_kf + 3) if k % 23 != 22]


def test_drop_beams_after_packing_marks_the_beams() -> None:
    rng = np.random.default_rng(3)
    closer = LoopCloser()
    for k in range(_PACK_BATCH + 1):
        sc = _scan(k, rng, "cm")
        closer.add(sc.stamp, Pose2D(0.5 * k, 0.0, 0.0), sc, np.zeros(sc.n_beams, dtype=bool), keyframe=True)
    kf = closer.keyframes[3]
    assert kf._codes is not None and kf.removed.size == 0
    assert closer.drop_beams([(3, np.array([1, 2, 500]))]) == 2
    assert kf.removed.shape == (181,) and kf.removed.sum() == 2 and kf.removed[1] and kf.removed[2]


def test_poses_moved_into_arrays_give_the_scans_poses_and_nodes(monkeypatch) -> None:
    rng = np.random.default_rng(5)
    monkeypatch.setattr(loops, "_POSE_CHUNK", 7)  # several chunks and a rest in the lists
    closer, ref = LoopCloser(), LoopCloser()
    monkeypatch.setattr(loops, "_POSE_CHUNK", 10**9)  # (ref: every pose in the lists, as before the chunks)
    ref._chunk_poses = lambda: None
    poses = []
    for k in range(40):
        sc = _scan(k, rng, "cm")
        p = (float(rng.normal(0.0, 9.0)), float(rng.normal(0.0, 9.0)), float(rng.uniform(-3.0, 3.0)))
        poses.append(p)
        for c, chunk in ((closer, 7), (ref, 10**9)):
            monkeypatch.setattr(loops, "_POSE_CHUNK", chunk)
            c.add(sc.stamp, Pose2D(*p), sc, np.zeros(sc.n_beams, dtype=bool), keyframe=k % 3 == 0)
    assert closer._n_chunked == 35 and len(closer._scan_node) == 5 and closer.next_index == 40
    assert [kf.scan_index for kf in closer.keyframes] == list(range(0, 40, 3))
    got = closer.finish()
    assert np.array_equal(got.frontend, np.array(poses)) and got.frontend.flags.c_contiguous
    # the optimised scan poses come from each scan's node: force a correction to compare them
    for c in (closer, ref):
        c.graph.set_poses(c.graph.poses + np.array([0.3, -0.2, 0.05]))
    a = loops.scan_poses(got.frontend, np.concatenate(closer._pose_chunks)[:, 0].astype(np.int64),
                         np.array([kf.frontend for kf in closer.keyframes]), closer.graph.poses)
    nodes = np.asarray(ref._scan_node, dtype=np.int64)
    b = loops.scan_poses(np.asarray(ref._frontend), nodes, np.array([kf.frontend for kf in ref.keyframes]),
                         ref.graph.poses)
    assert nodes.tolist() == [k // 3 for k in range(40)]
    assert np.array_equal(a.view(np.int64), b.view(np.int64))
