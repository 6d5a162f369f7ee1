"""Pass map36: the processor's and the map's per-scan Python written inline give the values of the forms they replace.

``degeneracy_values`` against ``degeneracy`` (every field, as bits), the processor's inlined prediction, motion
model and map-update test against ``_predict`` / ``_model_rates`` / ``_wrap``, ``update_map`` (the match's points
reused) against ``_integrate`` of the match result's, and ``MultiResMap.integrate``'s fast path (ndarray points, the
default three levels in one call) against its general path (points as lists, which take the conversion and
``_integrate_fused``).
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from dynslam2d.slam import HectorSlam, SlamConfig
from dynslam2d.slam.grid import MultiResMap, grazing_stop
from dynslam2d.slam.matcher import degeneracy, degeneracy_values
from dynslam2d.slam.processor import _wrap
from dynslam2d.types import Pose2D, Scan


def _bits(v: float) -> bytes:
    return struct.pack("<d", float(v))


def _hessians(rng: np.random.Generator) -> list[np.ndarray]:
    """Random symmetric positive (semi)definite Hessians and the edge cases degeneracy guards."""
    out = []
    for _ in range(300):
        J = rng.normal(size=(rng.integers(1, 8), 3)) * rng.choice([1e-6, 1.0, 1e3], size=3)
        out.append(J.T @ J)
    corridor = np.diag([100.0, 1e-9, 30.0])
    out += [np.zeros((3, 3)), np.full((3, 3), np.nan), corridor, np.diag([1.0, 1.0, 0.0]),
            np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]]), -np.eye(3)]
    return out


def _degeneracy_reference(hessian_cells: np.ndarray, resolution: float, pts_m: np.ndarray, threshold: float,
                          sumsq: float | None = None) -> tuple:
    """``degeneracy`` as it was before pass map36 (its closed form, returning the record's fields)."""
    n = pts_m.shape[0]
    if sumsq is None:
        sumsq = float(np.einsum("ij,ij->", pts_m, pts_m))
    rho = math.sqrt(sumsq / n) if n else 1.0
    rho = 1e-3 if 1e-3 > rho else rho
    (h00, h01, h02), (h10, h11, h12), (h20, h21, h22) = hessian_cells.tolist()
    k = 1.0 / resolution
    a = h00 * k * k
    b = 0.5 * (h01 + h10) * k * k
    d = h11 * k * k
    u = 0.5 * (h02 + h20) * k
    v = 0.5 * (h12 + h21) * k
    r = h22
    isfinite = math.isfinite
    if not (isfinite(a) and isfinite(b) and isfinite(d) and isfinite(u) and isfinite(v) and isfinite(r)) \
            or not a + d > 0.0:
        return 0.0, 0.0, 0.0, np.array([1.0, 0.0]), rho, 0.0, True, True
    if r > 1e-12 * (a + d):
        a2, b2, d2 = a - u * u / r, b - u * v / r, d - v * v / r
    else:
        a2, b2, d2 = a, b, d
    half_tr = 0.5 * (a2 + d2)
    disc = 0.25 * (a2 - d2) ** 2 + b2 * b2
    disc = math.sqrt(0.0 if 0.0 > disc else disc)
    lam_max, lam_min = half_tr + disc, half_tr - disc
    if not lam_max > 0.0:
        return 0.0, 0.0, 0.0, np.array([1.0, 0.0]), rho, 0.0, True, True
    if abs(b2) > 1e-300:
        ax, ay = lam_min - d2, b2
    elif a2 <= d2:
        ax, ay = 1.0, 0.0
    else:
        ax, ay = 0.0, 1.0
    nrm = math.hypot(ax, ay)
    axis = np.array([ax / nrm, ay / nrm]) if nrm > 0.0 else np.array([1.0, 0.0])
    t_ratio = (0.0 if 0.0 > lam_min else lam_min) / lam_max
    det = a * d - b * b
    s_rot = r - (u * (d * u - b * v) + v * (a * v - b * u)) / det if det > 1e-300 * (a * d + 1e-300) else 0.0
    r_ratio = (0.0 if 0.0 > s_rot else s_rot) / (rho * rho * lam_max)
    return (r_ratio if r_ratio < t_ratio else t_ratio, t_ratio, r_ratio, axis, rho, lam_max,
            t_ratio < threshold, r_ratio < threshold)


def test_degeneracy_values_are_degeneracys_fields() -> None:
    rng = np.random.default_rng(36)
    pts = rng.normal(size=(50, 2)) * 4.0
    for H in _hessians(rng):
        for sumsq in (None, float((pts * pts).sum())):
            ref = _degeneracy_reference(H, 0.05, pts, 0.05, sumsq)
            d = degeneracy(H, 0.05, pts, 0.05, sumsq)
            v = degeneracy_values(H, 0.05, pts, 0.05, sumsq)
            want = (ref[0], ref[1], ref[2], ref[3][0], ref[3][1], ref[4], ref[5])
            assert [_bits(a) for a in v[:7]] == [_bits(a) for a in want]
            assert v[7:] == ref[6:] and type(v[7]) is bool and type(v[8]) is bool
            got = (d.ratio, d.translation_ratio, d.rotation_ratio, d.axis[0], d.axis[1], d.scale, d.lam_max)
            assert [_bits(a) for a in got] == [_bits(a) for a in want]
            assert (d.translation_degenerate, d.rotation_degenerate) == ref[6:]
            assert d.axis.dtype == np.float64 and d.axis.shape == (2,)


def test_inline_map_update_angle_is_wrap_of_wrap() -> None:
    rng = np.random.default_rng(1)
    slam = HectorSlam(SlamConfig())
    slam.map.levels[0].logodds = np.zeros((4, 4), dtype=np.float32)  # (not empty: the thresholds decide)
    c = slam.config
    thetas = list(rng.uniform(-7.0, 7.0, 400)) + [0.0, -0.0, math.pi, -math.pi, 1e-300]
    for i, t0 in enumerate(thetas):
        t1 = thetas[-1 - i] + rng.normal() * 0.05
        last = Pose2D(float(rng.normal()), float(rng.normal()), float(t0))
        pose = Pose2D(last.x + float(rng.normal()) * 0.3, last.y, float(t1))
        slam._last_map_pose = last
        dth = _wrap(_wrap(-last.theta) + pose.theta)
        want = math.hypot(pose.x - last.x, pose.y - last.y) > c.map_update_distance_thresh \
            or abs(dth) > c.map_update_angle_thresh
        assert slam.needs_map_update(pose) is want
        # the angle alone, with the threshold at the reference's |Δθ| and one float below it: any other bits of the
        # inlined Δθ answer one of the two differently
        far = SlamConfig(map_update_distance_thresh=1e9, map_update_angle_thresh=abs(dth))
        slam.config = far
        assert slam.needs_map_update(pose) is False
        slam.config = SlamConfig(map_update_distance_thresh=1e9,
                                 map_update_angle_thresh=math.nextafter(abs(dth), -math.inf))
        assert slam.needs_map_update(pose) is (abs(dth) > slam.config.map_update_angle_thresh)
        slam.config = c


def _scans(n: int, beams: int = 181, seed: int = 3) -> list[Scan]:
    """A robot moving along a box room (ranges to its walls), with a pause, a stamp gap and a backward stamp."""
    rng = np.random.default_rng(seed)
    angles = np.linspace(-math.pi / 2, math.pi / 2, beams)
    stamps = np.arange(n) * 0.1
    stamps[n // 2:] += 2.0  # a time gap
    stamps[n // 3] = stamps[n // 3 - 1] - 0.05  # a backward stamp
    out = []
    for k in range(n):
        x = 0.02 * k if not (n // 4 <= k < n // 4 + 5) else 0.02 * (n // 4)
        th = 0.01 * k
        a = angles + th
        c, s = np.cos(a), np.sin(a)
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.where(c > 0, (6.0 - x) / c, np.where(c < 0, (-3.0 - x) / c, np.inf))
            ty = np.where(s > 0, 4.0 / s, np.where(s < 0, 4.0 / -s, np.inf))
        r = np.minimum(tx, ty) + rng.normal(size=beams) * 0.005
        out.append(Scan(stamp=float(stamps[k]), ranges=r, angle_min=float(angles[0]),
                        angle_increment=float(angles[1] - angles[0]), range_min=0.05, range_max=20.0))
    return out


@pytest.mark.parametrize("constant_velocity", [False, True])
def test_inline_prediction_and_motion_model(constant_velocity: bool) -> None:
    """``match``'s start is ``_predict``'s, and ``_prior``'s constant-velocity pose is ``_model_rates``' applied
    by ``Pose2D.compose``'s operations, on every scan of a run (bits)."""
    slam = HectorSlam(SlamConfig(constant_velocity=constant_velocity, motion_prior=True))
    n_moving = 0
    for scan in _scans(60):
        want_start, want_gap = slam._predict(scan.stamp)
        v = slam._model_rates() if slam.state == "tracking" else None
        last = slam._last_pose
        res = slam.match(scan, commit=False)
        assert res.time_gap is want_gap
        if res.prior != "odometry":
            assert (_bits(res.start.x), _bits(res.start.y), _bits(res.start.theta)) == \
                (_bits(want_start.x), _bits(want_start.y), _bits(want_start.theta))
        prior = slam._prior(scan, want_start, want_gap)
        if last is not None and not want_gap:
            assert prior.gate is (v is not None)
            if v is not None:
                n_moving += 1
                dt = scan.stamp - slam._last_stamp
                c_, s_ = math.cos(last.theta), math.sin(last.theta)
                vx, vy, vth = v[0] * dt, v[1] * dt, v[2] * dt
                want = (last.x + c_ * vx - s_ * vy, last.y + s_ * vx + c_ * vy, _wrap(last.theta + vth))
                assert tuple(_bits(a) for a in (prior.pose.x, prior.pose.y, prior.pose.theta)) == \
                    tuple(_bits(a) for a in want)
        slam.process(scan)  # (commit and map update: the next scan's prediction)
    assert n_moving > 20 and slam.n_map_updates > 3


def test_update_map_is_integrate() -> None:
    """``update_map`` (the match's gated points reused, then ``_integrate``) leaves the map, counters and last map
    pose of ``_integrate`` on the match result's points."""
    a, b = HectorSlam(SlamConfig()), HectorSlam(SlamConfig())
    for scan in _scans(40):
        ra, rb = a.match(scan), b.match(scan)
        assert ra.pose == rb.pose
        if not ra.rejected and a.needs_map_update(ra.pose):
            ua = a.update_map(scan, ra.pose)
            ub = b._integrate(rb.points, rb.clear_points, rb.pose)
            assert ua == ub
    assert a.n_map_updates == b.n_map_updates > 3 and a._last_map_pose == b._last_map_pose
    for la, lb in zip(a.map.levels, b.map.levels):
        assert la.logodds.tobytes() == lb.logodds.tobytes() and la.uidx.tobytes() == lb.uidx.tobytes()
        assert la.prob.tobytes() == lb.prob.tobytes() and (la.i0, la.j0) == (lb.i0, lb.j0)
    nan = Pose2D(math.nan, 0.0, 0.0)
    assert a.update_map(_scans(1)[0], nan) is False and a.counts["update_refused_non_finite"] == 1


def _integrate_reference(m: MultiResMap, pose: Pose2D, hits: list, clear: list | None) -> int:
    """``MultiResMap.integrate`` as before pass map36: the points converted, ``_integrate_fused`` tried first (the
    grazing stops as ``integrate`` makes them), the general path (growth, then ``_integrate_fused``) when it refuses."""
    h = np.asarray(hits, dtype=np.float64).reshape(-1, 2)
    cl = np.zeros((0, 2)) if clear is None else np.asarray(clear, dtype=np.float64).reshape(-1, 2)
    stop = None
    if m.grazing_cells > 0.0:
        stop = np.zeros(h.shape[0] + cl.shape[0])
        stop[:h.shape[0]] = grazing_stop(h, m.grazing_cells, m.min_sin)
    if len(m.levels) <= 4:
        n0 = m._integrate_fused(h, cl, math.cos(pose.theta), math.sin(pose.theta), float(pose.x), float(pose.y),
                                stop)
        if n0 >= 0:
            return n0
    return m.integrate(pose, hits, clear)


@pytest.mark.parametrize("levels,grazing", [(3, 0.0), (3, 1.0), (4, 0.0), (2, 0.0)])
def test_integrate_fast_path_is_general_path(levels: int, grazing: float) -> None:
    """``MultiResMap.integrate`` with (n, 2) float64 arrays (the fast path) against the same scans as lists taken
    the way before (``_integrate_reference``), through growths, clearing rays and a map limit: the same levels,
    counters and return values."""
    rng = np.random.default_rng(levels)
    kw = dict(resolution=0.05, levels=levels, l_free=-0.4, l_occ=0.9, grazing_cells=grazing,
              max_bytes=None if levels == 2 else 10**9)
    fast, slow = MultiResMap(**kw), MultiResMap(**kw)
    for k in range(30):
        pose = Pose2D(0.3 * k, 0.1 * math.sin(k), 0.05 * k)
        ang = np.linspace(-2.0, 2.0, 90)
        r = rng.uniform(0.5, 4.0 + 0.2 * k, ang.size)
        hits = np.column_stack((r * np.cos(ang), r * np.sin(ang)))
        clear = hits[::7] * 1.5 if k % 3 == 0 else None
        nf = fast.integrate(pose, hits, clear)
        ns = _integrate_reference(slow, pose, hits.tolist(), None if clear is None else clear.tolist())
        assert nf == ns and type(nf) is int
    assert fast.version == slow.version == 30
    for a, b in zip(fast.levels, slow.levels):
        assert a.logodds.tobytes() == b.logodds.tobytes() and a.prob.tobytes() == b.prob.tobytes()
        assert a.uidx.tobytes() == b.uidx.tobytes()
        assert (a.i0, a.j0, a.update_counter, a.n_grows) == (b.i0, b.j0, b.update_counter, b.n_grows)
    assert fast.levels[0].n_grows > 1


def test_inline_gate_tracking_and_commit_motion() -> None:
    """``match``'s gate is ``_gate``'s (points and clearing ends as bytes, with and without dropped beams), a matched
    scan goes through ``_apply_prior_and_gate`` (its degeneracy and support set), and ``_commit``'s motion and velocity
    are ``_between``'s (bits)."""
    from dynslam2d.slam.processor import _between

    slam = HectorSlam(SlamConfig(clear_no_return_dist=3.0))
    n_checked = 0
    for k, scan in enumerate(_scans(50)):
        drop = None
        if k % 5 == 4:
            drop = np.zeros(scan.ranges.shape[0], dtype=bool)
            drop[10:20] = True
        want = slam._gate(scan, True, drop)
        prev, prev_stamp = slam._last_pose, slam._last_stamp
        res = slam.match(scan, drop=drop)
        assert res.points.tobytes() == want[0].tobytes() and res.clear_points.tobytes() == want[1].tobytes()
        assert res.n_points == want[0].shape[0]
        if not res.first and res.reason is None:
            assert math.isfinite(res.degeneracy) and res.support_points > 0
        if prev is not None and not res.skipped:
            dx, dy, dth = _between(prev, res.pose)
            assert [_bits(a) for a in slam._last_motion] == [_bits(math.hypot(dx, dy)), _bits(abs(dth))]
            dt = scan.stamp - prev_stamp
            if 0.0 < dt <= slam.config.max_time_gap and not res.rejected:
                assert [_bits(a) for a in slam._velocity] == [_bits(dx / dt), _bits(dy / dt), _bits(dth / dt)]
                n_checked += 1
        if not res.rejected and slam.needs_map_update(res.pose):
            slam.update_map(scan, res.pose, drop=drop)
    assert n_checked > 20
