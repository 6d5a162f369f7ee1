"""Core types: pose algebra, scan validation (including random and corrupted metadata)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Pose2D, Scan, wrap_angle

finite = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-10, 10, allow_nan=False)


@given(finite, finite, angle, finite, finite, angle)
def test_compose_inverse_is_identity(x, y, t, u, v, w):
    a, b = Pose2D(x, y, t), Pose2D(u, v, w)
    ident = a.compose(a.inverse())
    assert abs(ident.x) < 1e-9 and abs(ident.y) < 1e-9 and abs(ident.theta) < 1e-9
    back = a.compose(a.between(b))
    assert math.isclose(back.x, b.x, abs_tol=1e-9) and math.isclose(back.y, b.y, abs_tol=1e-9)
    assert abs(wrap_angle(back.theta - b.theta)) < 1e-9


def test_compose_matches_matrix_product_and_transform_points():
    a, b = Pose2D(1.0, -2.0, 0.3), Pose2D(0.5, 0.25, -1.2)
    m = a.as_matrix() @ b.as_matrix()
    c = a.compose(b)
    np.testing.assert_allclose(c.as_matrix(), m, atol=1e-12)
    pts = np.array([[1.0, 0.0], [0.0, 2.0]])
    np.testing.assert_allclose(a.transform_points(pts), (a.as_matrix() @ np.c_[pts, np.ones(2)].T).T[:, :2])
    # rotation of (1, 0) by 90° about the origin then shift
    np.testing.assert_allclose(Pose2D(1, 1, math.pi / 2).transform_points(np.array([[1.0, 0.0]])), [[1.0, 2.0]])


def test_wrap_angle_range():
    a = np.linspace(-20, 20, 1001)
    w = wrap_angle(a)
    assert (w >= -math.pi).all() and (w < math.pi).all()
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)
    assert wrap_angle(3 * math.pi) == pytest.approx(-math.pi)


def _scan(ranges, **kw) -> Scan:
    base = dict(stamp=1.0, angle_min=-math.pi / 2, angle_increment=math.pi / 180, range_min=0.1, range_max=10.0)
    base.update(kw)
    return Scan(ranges=np.asarray(ranges, dtype=float), **base)


def test_no_return_values_are_masked_rep117():
    s = _scan([1.0, np.nan, np.inf, -np.inf, -1.0, 0.05, 10.0, 10.5, 0.1])
    np.testing.assert_array_equal(s.valid_mask(), [1, 0, 0, 0, 0, 0, 1, 0, 1])
    np.testing.assert_array_equal(s.valid_mask(min_range=0.5, max_range=5.0), [1, 0, 0, 0, 0, 0, 0, 0, 0])
    pts = s.points()
    assert pts.shape == (3, 2)
    np.testing.assert_allclose(pts[0], [0.0, -1.0], atol=1e-12)  # beam 0 at -90°


def test_angles_and_default_angle_max():
    s = _scan(np.ones(181))
    assert s.angles[0] == -math.pi / 2
    assert s.angles[-1] == pytest.approx(math.pi / 2)
    assert s.angle_max == pytest.approx(math.pi / 2)
    assert s.fov == pytest.approx(math.radians(181))


def test_angle_metadata_disagreeing_with_range_count_is_rejected():
    with pytest.raises(DynSlamError, match="implies 181.0 beams .* 90 ranges"):
        _scan(np.ones(90), angle_max=math.pi / 2)
    # one beam of slack (drivers disagree on whether angle_max is inclusive)
    assert _scan(np.ones(180), angle_max=math.pi / 2).n_beams == 180


def test_other_bad_metadata_is_rejected():
    with pytest.raises(DynSlamError, match="intensities"):
        _scan(np.ones(5), intensities=np.ones(4))
    with pytest.raises(DynSlamError, match="angle_increment is 0"):
        _scan(np.ones(5), angle_increment=0.0)
    with pytest.raises(DynSlamError, match="range limits"):
        _scan(np.ones(5), range_min=5.0, range_max=1.0)
    with pytest.raises(DynSlamError, match="not finite"):
        _scan(np.ones(5), stamp=math.nan)
    with pytest.raises(DynSlamError, match="1-D"):
        _scan(np.ones((2, 2)))


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(0, 50),
    amin=st.floats(allow_nan=True, allow_infinity=True),
    inc=st.floats(allow_nan=True, allow_infinity=True),
    amax=st.none() | st.floats(allow_nan=True, allow_infinity=True),
    rmin=st.floats(allow_nan=True, allow_infinity=True),
    rmax=st.floats(allow_nan=True, allow_infinity=True),
    data=st.data(),
)
def test_random_metadata_either_validates_or_raises_project_error(n, amin, inc, amax, rmin, rmax, data):
    ranges = data.draw(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=n, max_size=n))
    try:
        s = Scan(stamp=0.0, angle_min=amin, angle_increment=inc, angle_max=amax, ranges=np.array(ranges),
                 range_min=rmin, range_max=rmax)
    except DynSlamError:
        return
    mask = s.valid_mask()
    assert mask.shape == (n,)
    assert np.isfinite(s.points()).all()
    assert (s.ranges[mask] >= s.range_min).all() and (s.ranges[mask] <= s.range_max).all()


def test_absurd_angles_are_rejected():
    with pytest.raises(DynSlamError, match="outside"):
        _scan(np.ones(3), angle_min=1e300)
    with pytest.raises(DynSlamError, match="outside"):
        _scan(np.ones(3), angle_increment=1e300)


def test_copy_scan_writes_every_slot_and_without_matches_with_ranges():
    """_copy_scan's one statement per slot: the setters' order is Scan.__slots__', every slot is copied (distinct
    values in each), and ``without`` gives what ``with_ranges(np.where(mask, nan, ranges))`` gives, with the valid
    mask of those ranges (computed or not yet computed on the source scan)."""
    from dynslam2d.types import _SCAN_SLOTS, _copy_scan

    assert Scan.__slots__ == _SCAN_SLOTS
    rng = np.random.default_rng(3)
    r = rng.uniform(0.05, 40.0, 200)
    r[rng.random(200) < 0.2] = np.nan
    s = Scan(stamp=12.5, angle_min=-1.5, angle_increment=0.015, ranges=r, range_min=0.1, range_max=30.0,
             frame_id="front", intensities=rng.uniform(0, 1, 200), time_increment=1e-5, scan_time=0.05,
             odom=Pose2D(1.0, 2.0, 0.3), yaw_rate=0.25)
    _ = s.angles
    for computed in (False, True):
        if computed:
            s.valid_view()
        c = _copy_scan(s)
        for name in Scan.__slots__:
            assert getattr(c, name) is getattr(s, name), name
        mask = rng.random(200) < 0.3
        w = s.without(mask)
        ref = s.with_ranges(np.where(mask, np.nan, s.ranges))
        assert w.same_as(ref)
        for name in Scan.__slots__:
            if name not in ("ranges", "_valid"):
                assert getattr(w, name) is getattr(s, name), name
        assert (w._valid is None) == (not computed)
        np.testing.assert_array_equal(w.valid_mask(), ref.valid_mask())
        np.testing.assert_array_equal(s.ranges, r)  # the source is untouched


def test_dataclasses_replace_does_not_carry_another_scans_caches():
    """``dataclasses.replace`` builds a new scan from the constructor's fields: the cached angles, (cos, sin)
    and valid mask of the old scan are caches, not fields, so the new scan computes its own."""
    import dataclasses

    old = Scan(stamp=0.0, angle_min=-1.0, angle_increment=0.5, ranges=np.array([1.0, 2.0, 3.0, 4.0, 5.0]),
               range_min=0.1, range_max=10.0)
    old.angles, old.trig(), old.valid_view()  # fill the caches
    new = dataclasses.replace(old, angle_min=-0.5, ranges=np.array([1.0, np.nan, 3.0, 20.0, 5.0]))
    np.testing.assert_array_equal(new.angles, [-0.5, 0.0, 0.5, 1.0, 1.5])
    np.testing.assert_array_equal(new.trig()[0], np.cos(new.angles))
    np.testing.assert_array_equal(new.valid_view(), [True, False, True, False, True])
