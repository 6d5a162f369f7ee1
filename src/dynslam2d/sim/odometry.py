"""Simulated wheel odometry and IMU for a scenario: noisy, biased, seeded.

The scenario's robot script gives the LASER pose over time (world frame). The laser
sits on the robot base at ``mount`` (the static ``base_link → laser`` transform), so
the base pose is ``B(t) = L(t) ⊕ mount⁻¹``. The odometry frame is the base pose at
t = 0 (a wheel-odometry node starts at zero).

Odometry noise model (sampled at ``rate_hz``; the increments between consecutive
samples are corrupted, then integrated, so errors accumulate like real dead reckoning).
For a true base increment ``Δ = B_{k-1}⁻¹ ⊕ B_k`` (forward/left/yaw in the base frame)
with travelled distance ``d = |Δxy|`` and turned angle ``a = |Δθ|``:

* ``Δxy' = (1 + scale_error)·Δxy + n_xy``, ``n_xy ~ N(0, translation_noise²·d)`` per axis;
* ``Δθ' = (1 + yaw_scale_error)·Δθ + yaw_bias_per_metre·d + n_θ``,
  ``n_θ ~ N(0, rotation_noise²·a + rotation_per_metre²·d)``.

The variances grow linearly with distance and angle (a random walk), so the drift
does not depend on the sample rate: after ``D`` metres straight the along-track
error has σ = ``translation_noise·√D`` on top of the systematic ``scale_error·D``.
A robot standing still gets no odometry error.

IMU (sampled at ``imu_rate_hz``): ``ω' = (1 + gyro_scale_error)·ω + gyro_bias + n``,
``n ~ N(0, gyro_noise²)`` per sample, ω the exact yaw rate of the robot.

Both are seeded from the scenario seed (streams separate from the range noise, so
adding odometry never changes the scans).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.odometry import ImuTrack, OdometryTrack, compose_mount
from dynslam2d.types import Pose2D, Scan, wrap_angle

#: ``meta.odometry`` of simulated sources.
SIM_ODOMETRY = "sim"


@dataclass(frozen=True)
class OdometryModel:
    """Noise of the simulated odometry and IMU, and the laser's mount on the base.

    Attributes:
        rate_hz: odometry sample rate, Hz (also the /odom and /tf rate of a written bag).
        translation_noise: σ of the position random walk, m per √m driven, per axis.
        rotation_noise: σ of the heading random walk, rad per √rad turned.
        rotation_per_metre: σ of the heading random walk from driving, rad per √m.
        scale_error: relative error of the reported distance (0.02: 2 % too long).
        yaw_scale_error: relative error of the reported turn angle.
        yaw_bias_per_metre: systematic heading drift while driving, rad/m (unequal wheels).
        imu_rate_hz: IMU sample rate, Hz.
        gyro_noise: σ of the white yaw-rate noise per IMU sample, rad/s.
        gyro_bias: constant yaw-rate bias, rad/s.
        gyro_scale_error: relative yaw-rate scale error.
        mount: the laser's pose on the base (``base_link → laser``), m and rad.
        base_frame, odom_frame, imu_frame: frame names written into bags.
    """

    rate_hz: float = 50.0
    translation_noise: float = 0.01
    rotation_noise: float = 0.01
    rotation_per_metre: float = 0.002
    scale_error: float = 0.02
    yaw_scale_error: float = 0.01
    yaw_bias_per_metre: float = 0.005
    imu_rate_hz: float = 100.0
    gyro_noise: float = 0.005
    gyro_bias: float = 0.002
    gyro_scale_error: float = 0.0
    mount: Pose2D = field(default_factory=lambda: Pose2D(0.15, 0.0, 0.0))
    base_frame: str = "base_link"
    odom_frame: str = "odom"
    imu_frame: str = "imu_link"

    def __post_init__(self) -> None:
        for name in ("rate_hz", "imu_rate_hz"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise DynSlamError(f"odometry model: {name} must be positive, got {v}")
        for name in ("translation_noise", "rotation_noise", "rotation_per_metre", "gyro_noise"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise DynSlamError(f"odometry model: {name} must be >= 0, got {v}")
        for name in ("scale_error", "yaw_scale_error", "yaw_bias_per_metre", "gyro_bias", "gyro_scale_error"):
            if not math.isfinite(getattr(self, name)):
                raise DynSlamError(f"odometry model: {name} must be finite")

    def scaled(self, factor: float) -> OdometryModel:
        """This model with every noise, bias and scale-error term multiplied by ``factor``
        (0: perfect odometry and IMU; 2: twice as bad). Rates, mount and frames are kept."""
        import dataclasses

        if not (math.isfinite(factor) and factor >= 0):
            raise DynSlamError(f"odometry noise factor must be >= 0, got {factor}")
        names = ("translation_noise", "rotation_noise", "rotation_per_metre", "scale_error", "yaw_scale_error",
                 "yaw_bias_per_metre", "gyro_noise", "gyro_bias", "gyro_scale_error")
        return dataclasses.replace(self, **{n: getattr(self, n) * factor for n in names})

    @classmethod
    def perfect(cls, mount: Pose2D | None = None) -> OdometryModel:
        """No noise, no bias, no scale error (for tests of the plumbing)."""
        return cls(translation_noise=0.0, rotation_noise=0.0, rotation_per_metre=0.0, scale_error=0.0,
                   yaw_scale_error=0.0, yaw_bias_per_metre=0.0, gyro_noise=0.0, gyro_bias=0.0,
                   mount=Pose2D(0.15, 0.0, 0.0) if mount is None else mount)


@dataclass(frozen=True, eq=False)
class SimOdometry:
    """The simulated odometry and IMU of one run.

    Attributes:
        track: noisy base poses in the odometry frame at the odometry stamps.
        truth: the true base poses in the same frame and at the same stamps.
        twist: (n, 2) reported forward speed (m/s) and yaw rate (rad/s) per sample
            (the noisy increment over the preceding interval; 0 at the first sample).
        imu: noisy yaw rates.
        model: the noise model used.
    """

    track: OdometryTrack
    truth: OdometryTrack
    twist: np.ndarray
    imu: ImuTrack
    model: OdometryModel

    @property
    def mount(self) -> Pose2D:
        return self.model.mount

    def laser_poses(self, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Noisy LASER poses in the odometry frame at ``stamps``: ``(poses (m, 3), ok (m,))``."""
        base, ok = self.track.at(stamps)
        return compose_mount(base, self.mount), ok

    def attach(self, scan: Scan) -> Scan:
        """``scan`` with ``odom`` (laser pose in the odometry frame) and ``yaw_rate`` set."""
        poses, ok = self.laser_poses(np.array([scan.stamp]))
        odom = Pose2D.from_array(poses[0]) if ok[0] else None
        return scan.with_odometry(odom, self.imu.at(scan.stamp))


def _robot_yaw_rate(robot: object, t: np.ndarray) -> np.ndarray:
    fn = getattr(robot, "yaw_rate", None)
    if fn is not None:
        return np.asarray(fn(t), dtype=np.float64)
    h = 1e-4
    a = robot.sample(t - h)[..., 2]  # type: ignore[attr-defined]
    b = robot.sample(t + h)[..., 2]  # type: ignore[attr-defined]
    return wrap_angle(b - a) / (2 * h)


def simulate_odometry(robot: object, last_stamp: float, seed: int,
                      model: OdometryModel | None = None) -> SimOdometry:
    """Odometry and IMU for ``robot`` (anything with ``sample(t) -> (..., 3+)`` laser poses,
    world frame) over ``[0, last_stamp]`` s, seeded by ``seed`` (see the module docstring)."""
    m = model or OdometryModel()
    n = int(math.ceil(last_stamp * m.rate_hz)) + 2
    stamps = np.arange(n, dtype=np.float64) / m.rate_hz
    laser = np.asarray(robot.sample(stamps), dtype=np.float64)[:, :3]  # type: ignore[attr-defined]
    base = compose_mount(laser, m.mount.inverse())
    origin = Pose2D.from_array(base[0]).inverse()
    # true base poses in the odometry frame: origin ⊕ B_k
    base_odom = np.empty((n, 3))
    c, s = math.cos(origin.theta), math.sin(origin.theta)
    base_odom[:, 0] = origin.x + c * base[:, 0] - s * base[:, 1]
    base_odom[:, 1] = origin.y + s * base[:, 0] + c * base[:, 1]
    base_odom[:, 2] = wrap_angle(base[:, 2] + origin.theta)

    # true increments in the previous base frame
    d = np.diff(base_odom, axis=0)
    th0 = base_odom[:-1, 2]
    ct, st = np.cos(th0), np.sin(th0)
    dx = ct * d[:, 0] + st * d[:, 1]
    dy = -st * d[:, 0] + ct * d[:, 1]
    dth = wrap_angle(d[:, 2])
    dist = np.hypot(dx, dy)
    turn = np.abs(dth)

    rng = np.random.default_rng([int(seed), 1])
    sig_t = m.translation_noise * np.sqrt(dist)
    sig_r = np.sqrt(m.rotation_noise ** 2 * turn + m.rotation_per_metre ** 2 * dist)
    ndx = (1.0 + m.scale_error) * dx + sig_t * rng.standard_normal(dist.shape)
    ndy = (1.0 + m.scale_error) * dy + sig_t * rng.standard_normal(dist.shape)
    ndth = (1.0 + m.yaw_scale_error) * dth + m.yaw_bias_per_metre * dist + sig_r * rng.standard_normal(dist.shape)

    # integrate: O_k = O_{k-1} ⊕ Δ'_k, O_0 = identity
    theta = np.concatenate(([0.0], np.cumsum(ndth)))
    c0, s0 = np.cos(theta[:-1]), np.sin(theta[:-1])
    x = np.concatenate(([0.0], np.cumsum(c0 * ndx - s0 * ndy)))
    y = np.concatenate(([0.0], np.cumsum(s0 * ndx + c0 * ndy)))
    noisy = np.column_stack((x, y, wrap_angle(theta)))
    dt = 1.0 / m.rate_hz
    twist = np.zeros((n, 2))
    twist[1:, 0] = ndx / dt
    twist[1:, 1] = ndth / dt

    ni = int(math.ceil(last_stamp * m.imu_rate_hz)) + 2
    istamps = np.arange(ni, dtype=np.float64) / m.imu_rate_hz
    irng = np.random.default_rng([int(seed), 2])
    omega = _robot_yaw_rate(robot, istamps)
    measured = (1.0 + m.gyro_scale_error) * omega + m.gyro_bias + m.gyro_noise * irng.standard_normal(ni)

    track = OdometryTrack(stamps, noisy, m.odom_frame, m.base_frame, source="sim")
    truth = OdometryTrack(stamps, base_odom, m.odom_frame, m.base_frame, source="sim (true)")
    imu = ImuTrack(istamps, measured, m.imu_frame, source="sim")
    return SimOdometry(track, truth, twist, imu, m)
