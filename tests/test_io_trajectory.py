"""TUM trajectory files: exact round trip, strict parsing, atomic writes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dynslam2d.errors import DynSlamError
from dynslam2d.io.trajectory import Trajectory, read_tum, write_tum
from dynslam2d.types import Pose2D


def _traj() -> Trajectory:
    stamps = np.array([1134864629.895123, 1134864630.1, 1134864630.300001, 1134864631.0])
    poses = np.array(
        [
            [0.0, 0.0, 0.0],
            [1.234567, -0.000001, 0.5],
            [-12.3456789, 4.2, math.pi - 1e-9],
            [3.0, -7.5, -2.9],
        ]
    )
    return Trajectory(stamps, poses)


def test_round_trip_is_exact_to_1e9(tmp_path: Path) -> None:
    traj = _traj()
    path = write_tum(tmp_path / "traj.txt", traj)
    back = read_tum(path)
    assert len(back) == 4
    assert back.frame == "map"
    # stamps and positions come back bit-for-bit (shortest round-trip repr)
    assert np.array_equal(back.stamps, traj.stamps)
    assert back.stamps[0] == 1134864629.895123
    assert np.array_equal(back.xy, traj.xy)
    # yaw goes through the quaternion: equal to well below 1e-9 rad
    assert np.max(np.abs(back.yaw - traj.yaw)) < 1e-9
    assert back.same_as(traj, atol=1e-9)


def test_written_line_is_tum_with_yaw_quaternion(tmp_path: Path) -> None:
    traj = Trajectory(np.array([1134864629.895123]), np.array([[1.5, -2.25, math.pi / 2]]))
    path = write_tum(tmp_path / "t.txt", traj, comment="dynslam2d run\nsecond line")
    lines = path.read_text().splitlines()
    assert lines[0] == "# dynslam2d run" and lines[1] == "# second line"
    f = lines[2].split()
    assert len(f) == 8
    assert f[0] == "1134864629.895123"  # µs preserved as written, no %.4f truncation
    assert float(f[1]) == 1.5 and float(f[2]) == -2.25 and float(f[3]) == 0.0
    qx, qy, qz, qw = map(float, f[4:])
    assert qx == 0.0 and qy == 0.0
    assert qz == pytest.approx(math.sin(math.pi / 4), abs=1e-15)
    assert qw == pytest.approx(math.cos(math.pi / 4), abs=1e-15)


def test_read_accepts_comments_blank_lines_and_wraps_yaw(tmp_path: Path) -> None:
    p = tmp_path / "t.txt"
    # yaw of 3π/2 written as a quaternion → read back as -π/2
    s, c = math.sin(3 * math.pi / 4), math.cos(3 * math.pi / 4)
    p.write_text(f"# header\n\n  1.0 2 3 0 0 0 {s!r} {c!r}  \n# tail\n\t\n2.5 0 0 0.0005 0 0 0 1\n")
    t = read_tum(p)
    assert t.stamps.tolist() == [1.0, 2.5]
    assert t.pose(0) == Pose2D(2.0, 3.0, t.yaw[0])
    assert t.yaw[0] == pytest.approx(-math.pi / 2, abs=1e-12)
    assert t.yaw[1] == 0.0


def test_read_normalises_a_slightly_off_quaternion(tmp_path: Path) -> None:
    p = tmp_path / "t.txt"
    # %.4f-style quaternion for yaw = 1 rad: norm ≈ 1 − 2e-5
    p.write_text("0 0 0 0 0 0 0.4794 0.8776\n")
    assert read_tum(p).yaw[0] == pytest.approx(1.0, abs=2e-4)


@pytest.mark.parametrize(
    ("content", "lineno", "needle"),
    [
        ("# c\n1 2 3 0 0 0 0 1\n1 2 3 0 0 0 1\n", 3, "expected 8 fields"),
        ("1 2 3 0 0 0 0 1 9\n", 1, "got 9"),
        ("1 2 3 0 0 0 0 1\n\n2 x 3 0 0 0 0 1\n", 3, "'x' is not a number"),
        ("1 2 3 0 0 0 0 1\n2 nan 3 0 0 0 0 1\n", 2, "non-finite"),
        ("1 2 3 0.5 0 0 0 1\n", 1, "not planar: z"),
        # 10° roll
        (f"1 2 3 0 {math.sin(math.radians(5))!r} 0 0 {math.cos(math.radians(5))!r}\n", 1, "tilt"),
        ("1 2 3 0 0 0 0 0\n", 1, "norm"),
        ("1 2 3 0 0 0 0 2\n", 1, "norm"),
        ("1,2,3,0,0,0,0,1\n", 1, "expected 8 fields"),
    ],
)
def test_malformed_lines_name_file_and_line(tmp_path: Path, content: str, lineno: int, needle: str) -> None:
    p = tmp_path / "bad.txt"
    p.write_text(content)
    with pytest.raises(DynSlamError) as ei:
        read_tum(p)
    msg = str(ei.value)
    assert f"bad.txt:{lineno}:" in msg
    assert needle in msg


def test_planarity_tolerances_are_adjustable(tmp_path: Path) -> None:
    p = tmp_path / "t.txt"
    p.write_text("1 2 3 0.5 0 0 0 1\n")
    with pytest.raises(DynSlamError):
        read_tum(p)
    assert read_tum(p, max_z=1.0).xy.tolist() == [[2.0, 3.0]]


@pytest.mark.parametrize("content", ["", "# only a comment\n\n"])
def test_empty_file_is_an_error(tmp_path: Path, content: str) -> None:
    p = tmp_path / "empty.txt"
    p.write_text(content)
    with pytest.raises(DynSlamError, match="empty.txt: no poses"):
        read_tum(p)


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(DynSlamError, match="not found"):
        read_tum(tmp_path / "nope.txt")
    with pytest.raises(DynSlamError, match="directory"):
        read_tum(tmp_path)


def test_atomic_write_leaves_nothing_on_failure(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    final = tmp_path / "out.txt"

    def boom(self: Path, *a: object, **k: object) -> int:
        # write part of the content, then fail as a full disk would
        with open(self, "w") as fh:
            fh.write("1.0 0 0 0 0 0 0 1\n")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "write_text", boom)
    with pytest.raises(DynSlamError, match="No space left"):
        write_tum(final, _traj())
    assert not final.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary left behind either


def test_atomic_write_keeps_previous_file_on_failure(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    final = tmp_path / "out.txt"
    write_tum(final, _traj())
    before = final.read_text()

    def boom(self: Path, *a: object, **k: object) -> int:
        raise KeyboardInterrupt

    monkeypatch.setattr(Path, "write_text", boom)
    with pytest.raises(KeyboardInterrupt):
        write_tum(final, Trajectory(np.array([5.0]), np.array([[9.0, 9.0, 0.0]])))
    assert final.read_text() == before


def test_trajectory_validation_and_helpers() -> None:
    t = Trajectory.from_poses([0.0, 0.1], [Pose2D(1, 2, 0.3), Pose2D(4, 5, -0.6)])
    assert len(t) == 2
    assert t.poses.dtype == np.float64 and t.poses.shape == (2, 3)
    assert t.pose(1) == Pose2D(4.0, 5.0, -0.6)
    assert t.subset([1]).stamps.tolist() == [0.1]
    with pytest.raises(DynSlamError, match="2 stamps for 1 poses"):
        Trajectory(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 0.0]]))
    with pytest.raises(DynSlamError, match="shape"):
        Trajectory(np.array([0.0]), np.array([[0.0, 0.0]]))
    with pytest.raises(DynSlamError, match="pose 1 is not finite"):
        Trajectory(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 0.0], [np.inf, 0.0, 0.0]]))
