"""CARMEN log files (``.clf``, ``.log``, optionally gzipped) as a :class:`ScanSource`.

Record layouts (see ``shared/data/README.md``; whitespace-separated fields):

``FLASER n r_1 … r_n x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp``
    n + 11 fields. ``x y theta`` is the laser pose, ``odom_*`` the robot's
    odometry pose (both in the odometry/world frame, m and rad).

``ROBOTLASER1 laser_type start_angle fov ang_res max_range accuracy remission_mode n r_1 … r_n
m rem_1 … rem_m laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv forward_safety
side_safety turn_axis ipc_timestamp ipc_hostname logger_timestamp``
    n + m + 24 fields.

``ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp``
    10 fields; exposed by :meth:`CarmenSource.odometry`.

Everything else (``NEFF``, ``PARAM``, ``VERTEX2``, ``EDGE2``, ``RLASER`` and other
record types, ``#`` comments, blank lines) is ignored and counted in
``meta.extra``.

Beam geometry (angles in the laser frame, rad, counter-clockwise, beam 0 right-most):

* ``ROBOTLASER1``: ``angle_min = start_angle``, ``angle_increment = ang_res``.
* ``FLASER`` has no angle fields; they follow from n (the layouts the ROBOTLASER1
  headers of the same datasets give): n = 180 → −90°…+89° in 1° steps; n = 360 →
  −90°…+89.5° in 0.5° steps; n = 361 → −90°…+90° in 0.5° steps. Any other n is
  assumed to be a 180° field of view centred straight ahead with beams at both
  ends: −90°…+90° in steps of 180°/(n − 1) (so 181 → 1° steps); n = 1 is one beam
  straight ahead.

No return: a CARMEN log writes the sensor's maximum for "no return". A reading
``r >= t`` is no return, where ``t`` is, in priority order:

1. the ``max_range`` argument, if given (all record types);
2. for ``ROBOTLASER1``, the record's own ``max_range`` field;
3. for ``FLASER``, a per-file threshold detected from the readings
   (:func:`detect_no_return_threshold`): 81.83 m when any reading reaches the SICK
   long-range no-return values (81.83 / 81.91 m; real returns up to 81.82 m occur
   in the Freiburg campus log); otherwise the file's largest reading if it is a
   saturation marker (repeated ≥ 10 times and ≥ 0.1 % of readings, and more than
   twice the median reading and 0.1 m; ACES writes 50.0 m); otherwise 81.83 m.

Each :class:`Scan` gets ``range_max`` = the largest float below ``t`` so that its
``valid_mask()`` drops exactly the readings ``r >= t``, and ``range_min`` =
:data:`DEFAULT_RANGE_MIN` (1 cm: CARMEN stores no minimum range; a reading of 0
is some drivers' error code). NaN or negative readings are kept as written and
are invalid under ``valid_mask()``.

Time: a scan's stamp is the record's ``ipc_timestamp`` (s; Unix time in raw
logs, logger-relative in GMapping ``.gfs`` output). If the ipc stamps of all laser
records are equal (the Freiburg campus log has all zeros), the logger
timestamps are used; if those are equal too, stamps are synthesized at
``nominal_rate_hz`` (default :data:`DEFAULT_NOMINAL_RATE_HZ`) in file order,
starting at 0. Scans are then stably sorted by stamp (the flirtlib logs are not
in time order), and any stamp that does not exceed its predecessor is moved to
``previous + 1 µs`` (:data:`DUPLICATE_NUDGE_S`) so the output strictly
increases. Each such fallback or repair adds a string to
``meta.extra["warnings"]``.
"""

from __future__ import annotations

import dataclasses
import gzip
import math
import os
import zlib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.types import Pose2D, Scan, SourceMeta

#: Readings below this (m) are no return; CARMEN records carry no minimum range.
DEFAULT_RANGE_MIN = 0.01
#: SICK LMS long-range mode writes 81.83 or 81.91 m for "no return".
SICK_NO_RETURN = 81.83
#: Scan rate assumed when a log has no usable timestamps at all, Hz.
DEFAULT_NOMINAL_RATE_HZ = 5.0
#: Step used to make repeated stamps strictly increasing, s.
DUPLICATE_NUDGE_S = 1e-6
#: How many skipped line numbers ``meta.extra["skipped_line_numbers"]`` keeps.
MAX_REPORTED_LINES = 10

_GZIP_MAGIC = b"\x1f\x8b"
_LASER_KINDS = ("FLASER", "ROBOTLASER1")


def read_text(path: str | os.PathLike[str]) -> tuple[Path, str]:
    """Read a text file, gunzipping it when its first bytes are the gzip magic.

    Returns ``(path, text)``. The text is decoded as Latin-1 (never fails; junk
    bytes then fail as non-numeric fields with a line number). Raises
    DynSlamError for a missing, unreadable or corrupt file.
    """
    p = Path(path)
    if not p.exists():
        raise DynSlamError(f"{p}: no such file")
    if p.is_dir():
        raise DynSlamError(f"{p}: is a folder, expected a file")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise DynSlamError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    if data.startswith(_GZIP_MAGIC):
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError, zlib.error) as exc:
            raise DynSlamError(f"{p}: corrupt or truncated gzip data ({exc})") from exc
    return p, data.decode("latin-1")


def flaser_geometry(n: int) -> tuple[float, float]:
    """``(angle_min, angle_increment)`` in rad for a FLASER record of ``n`` beams.

    180 → −90°…+89° (1°), 360 → −90°…+89.5° (0.5°), 361 → −90°…+90° (0.5°);
    any other n: 180° centred ahead, −90°…+90°, step 180°/(n − 1); n = 1: 0 rad.
    """
    if n == 180:
        return -math.pi / 2.0, math.pi / 180.0
    if n == 360 or n == 361:
        return -math.pi / 2.0, math.pi / 360.0
    if n == 1:
        return 0.0, math.pi  # one beam straight ahead; the increment is never used
    return -math.pi / 2.0, math.pi / (n - 1)


def detect_no_return_threshold(ranges: np.ndarray) -> tuple[float, str]:
    """No-return threshold ``t`` (m) for FLASER readings: ``r >= t`` is no return.

    Rule (module docstring): 81.83 m if any reading is ≥ 81.83 m (SICK); else the
    largest reading if it is a repeated saturation marker; else 81.83 m.
    Returns ``(t, rule)`` where ``rule`` names the branch taken.
    """
    r = np.asarray(ranges, dtype=np.float64)
    r = r[np.isfinite(r) & (r > DEFAULT_RANGE_MIN)]
    if r.size == 0:
        return SICK_NO_RETURN, "default (no finite readings)"
    top = float(r.max())
    if top >= SICK_NO_RETURN:
        return SICK_NO_RETURN, "SICK no-return values (>= 81.83 m) present"
    repeats = int(np.count_nonzero(r == top))
    if repeats >= max(10, 0.001 * r.size) and top > max(2.0 * float(np.median(r)), 0.1):
        return top, f"saturation marker {top:g} m repeated {repeats} times"
    return SICK_NO_RETURN, "default (no saturation marker found)"


@dataclass(frozen=True, slots=True)
class CarmenRecord:
    """One laser record of a CARMEN log.

    Attributes:
        scan: the scan; ``scan.stamp`` is the final (sorted, repaired) stamp, s.
        kind: "FLASER" or "ROBOTLASER1".
        line: 1-based line number in the (decompressed) file.
        odom: robot pose from odometry in the odometry frame (FLASER ``odom_x/y/theta``,
            ROBOTLASER1 ``robot_x/y/theta``), or None if a field is not finite.
        laser_pose: laser pose in the same frame (FLASER ``x y theta``, ROBOTLASER1
            ``laser_x/y/theta``), or None if not finite. In GMapping ``.gfs`` output both
            poses are the SLAM-corrected pose, not raw odometry.
        ipc_stamp, logger_stamp: the two timestamps as written, s.
    """

    scan: Scan
    kind: str
    line: int
    odom: Pose2D | None
    laser_pose: Pose2D | None
    ipc_stamp: float
    logger_stamp: float


@dataclass(frozen=True, slots=True)
class CarmenOdometry:
    """The ``ODOM`` records of a log, as (k,) arrays sorted by ``stamp``.

    ``stamp`` (s) is on the same clock as the scans (ipc or logger time, whichever the
    scans use); it is NaN when the scans' stamps had to be synthesized. ``x, y`` m,
    ``theta`` rad (odometry frame), ``tv`` m/s, ``rv`` rad/s, ``accel`` m/s²,
    ``line`` 1-based line numbers.
    """

    stamp: np.ndarray
    x: np.ndarray
    y: np.ndarray
    theta: np.ndarray
    tv: np.ndarray
    rv: np.ndarray
    accel: np.ndarray
    line: np.ndarray

    def __len__(self) -> int:
        return int(self.stamp.shape[0])


class _BadLine(Exception):
    """Internal: a malformed line; carries the reason."""


@dataclass(slots=True)
class _RawLaser:
    kind: str
    line: int
    ranges: np.ndarray
    intensities: np.ndarray | None
    angle_min: float
    angle_increment: float
    max_range: float | None  # ROBOTLASER1 field; None for FLASER
    laser_pose: np.ndarray
    odom: np.ndarray
    ipc: float
    logger: float


def _int_field(fields: list[str], i: int, what: str) -> int:
    if i >= len(fields):
        raise _BadLine(f"line ends before {what} (field {i + 1})")
    try:
        value = int(fields[i])
    except ValueError:
        raise _BadLine(f"{what} {fields[i]!r} is not an integer") from None
    if value < 0:
        raise _BadLine(f"{what} is negative ({value})")
    return value


def _floats(fields: list[str], what: str) -> np.ndarray:
    try:
        return np.array(fields, dtype=np.float64)
    except ValueError:
        for f in fields:
            try:
                float(f)
            except ValueError:
                raise _BadLine(f"non-numeric {what} field {f!r}") from None
        raise _BadLine(f"non-numeric {what} field") from None


def _stamp(field: str, what: str) -> float:
    try:
        value = float(field)
    except ValueError:
        raise _BadLine(f"non-numeric {what} {field!r}") from None
    if not math.isfinite(value):
        raise _BadLine(f"{what} is not finite ({field})")
    return value


def _parse_flaser(fields: list[str], line: int) -> _RawLaser:
    n = _int_field(fields, 1, "beam count n")
    if n == 0:
        raise _BadLine("FLASER with 0 beams")
    need = n + 11
    if len(fields) != need:
        raise _BadLine(f"FLASER with n={n} needs {need} fields, found {len(fields)}")
    values = _floats(fields[2 : n + 8], "range/pose")
    ipc = _stamp(fields[n + 8], "ipc_timestamp")
    logger = _stamp(fields[n + 10], "logger_timestamp")
    a0, inc = flaser_geometry(n)
    return _RawLaser(
        "FLASER", line, values[:n], None, a0, inc, None, values[n : n + 3], values[n + 3 : n + 6], ipc, logger
    )


def _parse_robotlaser1(fields: list[str], line: int) -> _RawLaser:
    if len(fields) < 9:
        raise _BadLine(f"ROBOTLASER1 needs at least 9 header fields, found {len(fields)}")
    header = _floats(fields[2:6], "header")
    start, fov, res, max_range = (float(v) for v in header)
    n = _int_field(fields, 8, "beam count n")
    if n == 0:
        raise _BadLine("ROBOTLASER1 with 0 beams")
    m = _int_field(fields, 9 + n, "remission count")
    need = n + m + 24
    if len(fields) != need:
        raise _BadLine(f"ROBOTLASER1 with n={n}, {m} remissions needs {need} fields, found {len(fields)}")
    if not (math.isfinite(start) and math.isfinite(res) and res != 0.0):
        raise _BadLine(f"bad angle header start_angle={fields[2]} ang_res={fields[4]}")
    if not (math.isfinite(max_range) and max_range > DEFAULT_RANGE_MIN):
        raise _BadLine(f"bad max_range {fields[5]}")
    ranges = _floats(fields[9 : 9 + n], "range")
    remissions = _floats(fields[10 + n : 10 + n + m], "remission") if m else None
    base = 10 + n + m
    poses = _floats(fields[base : base + 6], "pose")
    _floats(fields[base + 6 : base + 11], "velocity/safety")
    ipc = _stamp(fields[base + 11], "ipc_timestamp")
    logger = _stamp(fields[base + 13], "logger_timestamp")
    inten = remissions if remissions is not None and m == n else None
    return _RawLaser("ROBOTLASER1", line, ranges, inten, start, res, max_range, poses[:3], poses[3:6], ipc, logger)


def _parse_odom(fields: list[str]) -> np.ndarray:
    if len(fields) != 10:
        raise _BadLine(f"ODOM needs 10 fields, found {len(fields)}")
    values = _floats(fields[1:7], "odometry")
    ipc = _stamp(fields[7], "ipc_timestamp")
    logger = _stamp(fields[9], "logger_timestamp")
    return np.concatenate((values, [ipc, logger]))


def _pose_or_none(v: np.ndarray) -> Pose2D | None:
    return Pose2D.from_array(v) if bool(np.all(np.isfinite(v))) else None


def _strictly_increasing(stamps: np.ndarray) -> tuple[np.ndarray, int]:
    """Move every stamp not above its predecessor to ``previous + 1 µs``; count moves."""
    out = stamps.copy()
    nudged = 0
    if out.size > 1 and np.any(np.diff(out) <= 0.0):
        for i in range(1, out.size):
            if out[i] <= out[i - 1]:
                out[i] = max(out[i - 1] + DUPLICATE_NUDGE_S, float(np.nextafter(out[i - 1], np.inf)))
                nudged += 1
    return out, nudged


class CarmenSource:
    """Laser scans of a CARMEN log, in strictly increasing stamp order.

    The whole file is parsed when the source is created (logs are small), so every
    format error surfaces here as a DynSlamError ``"<file>:<line>: <what>"``.

    Args:
        path: a ``.clf``/``.log`` file, plain or gzipped (detected by magic bytes).
        skip_bad: skip malformed lines instead of raising; they are counted in
            ``meta.extra["skipped_lines"]`` (first line numbers in
            ``meta.extra["skipped_line_numbers"]``).
        max_range: no-return threshold, m (``r >= max_range`` is no return) for all
            records; None = ROBOTLASER1's own field, auto-detected for FLASER.
        nominal_rate_hz: rate used to synthesize stamps when the log has none, Hz.

    Iterating yields :class:`Scan` objects; :meth:`records` yields
    :class:`CarmenRecord` (scan + poses + line) in the same order.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        skip_bad: bool = False,
        *,
        max_range: float | None = None,
        nominal_rate_hz: float = DEFAULT_NOMINAL_RATE_HZ,
    ) -> None:
        if max_range is not None and not (math.isfinite(max_range) and max_range > DEFAULT_RANGE_MIN):
            raise DynSlamError(f"max_range must be a finite number above {DEFAULT_RANGE_MIN} m, got {max_range}")
        if not (math.isfinite(nominal_rate_hz) and nominal_rate_hz > 0.0):
            raise DynSlamError(f"nominal_rate_hz must be positive, got {nominal_rate_hz}")
        self.path, text = read_text(path)
        self.skip_bad = skip_bad
        self._records: list[CarmenRecord] = []
        self._odometry: CarmenOdometry
        self.meta: SourceMeta = SourceMeta(format="carmen", origin=str(self.path))
        self._load(text, max_range, nominal_rate_hz)

    # -- parsing ---------------------------------------------------------------

    def _load(self, text: str, max_range: float | None, nominal_rate_hz: float) -> None:
        """Parse every line; malformed ones raise (or are skipped with ``skip_bad``)."""
        name = str(self.path)
        if not text.strip():
            raise DynSlamError(f"{name}: file is empty")
        lines = text.split("\n")
        ends_with_newline = lines[-1] == ""
        if ends_with_newline:
            lines.pop()
        lasers: list[_RawLaser] = []
        odom_rows: list[np.ndarray] = []
        odom_lines: list[int] = []
        kinds: Counter[str] = Counter()
        skipped: list[int] = []
        n_lines = len(lines)
        for index, line in enumerate(lines):
            fields = line.split()
            if not fields:
                continue
            kind = fields[0]
            if kind.startswith("#"):
                kinds["#"] += 1
                continue
            kinds[kind] += 1
            if kind not in ("FLASER", "ROBOTLASER1", "ODOM"):
                continue
            lineno = index + 1
            try:
                if kind == "FLASER":
                    lasers.append(_parse_flaser(fields, lineno))
                elif kind == "ROBOTLASER1":
                    lasers.append(_parse_robotlaser1(fields, lineno))
                else:
                    odom_rows.append(_parse_odom(fields))
                    odom_lines.append(lineno)
            except _BadLine as exc:
                reason = str(exc)
                if index == n_lines - 1 and not ends_with_newline:
                    reason += " (last line has no newline: file truncated?)"
                if not self.skip_bad:
                    raise DynSlamError(f"{name}:{lineno}: malformed {kind} record: {reason}") from None
                skipped.append(lineno)
        if not lasers:
            found = ", ".join(f"{k}×{v}" for k, v in sorted(kinds.items())) or "nothing"
            extra = f"; {len(skipped)} malformed laser/odometry lines skipped" if skipped else ""
            raise DynSlamError(f"{name}: no FLASER or ROBOTLASER1 laser records (found {found}){extra}")
        self._build(lasers, odom_rows, odom_lines, kinds, skipped, max_range, nominal_rate_hz)

    def _build(
        self,
        lasers: list[_RawLaser],
        odom_rows: list[np.ndarray],
        odom_lines: list[int],
        kinds: Counter[str],
        skipped: list[int],
        max_range: float | None,
        nominal_rate_hz: float,
    ) -> None:
        warnings: list[str] = []
        # -- no-return thresholds
        flaser_t: float | None = None
        rule = "max_range argument" if max_range is not None else ""
        if max_range is None and any(r.kind == "FLASER" for r in lasers):
            flaser_ranges = np.concatenate([r.ranges for r in lasers if r.kind == "FLASER"])
            flaser_t, rule = detect_no_return_threshold(flaser_ranges)

        # -- one scan per record (stamps provisional); geometry the Scan type rejects is a bad line
        name = str(self.path)
        kept: list[tuple[_RawLaser, Scan]] = []
        for raw in lasers:
            if max_range is not None:
                t = max_range
            elif raw.max_range is not None:
                t = raw.max_range
            else:
                assert flaser_t is not None
                t = flaser_t
            try:
                scan = Scan(
                    stamp=raw.ipc,
                    angle_min=raw.angle_min,
                    angle_increment=raw.angle_increment,
                    ranges=raw.ranges,
                    range_min=DEFAULT_RANGE_MIN,
                    range_max=float(np.nextafter(t, 0.0)),  # r >= t is no return
                    frame_id="laser",
                    intensities=raw.intensities,
                )
            except DynSlamError as exc:
                if not self.skip_bad:
                    raise DynSlamError(f"{name}:{raw.line}: malformed {raw.kind} record: {exc}") from None
                skipped.append(raw.line)
                continue
            kept.append((raw, scan))
        if not kept:
            raise DynSlamError(f"{name}: no valid laser records ({len(skipped)} malformed lines skipped)")
        skipped.sort()

        # -- stamps: ipc, else logger, else synthesized
        ipc = np.array([raw.ipc for raw, _ in kept])
        logger = np.array([raw.logger for raw, _ in kept])
        n = len(kept)
        if n == 1 or np.ptp(ipc) > 0.0:
            time_source, stamps = "ipc", ipc
        elif np.ptp(logger) > 0.0:
            time_source, stamps = "logger", logger
            warnings.append("all ipc timestamps are equal; using logger timestamps")
        else:
            time_source = "synthesized"
            stamps = np.arange(n, dtype=np.float64) / nominal_rate_hz
            warnings.append(
                f"all ipc and logger timestamps are equal ({ipc[0]:g}); stamps synthesized at "
                f"{nominal_rate_hz:g} Hz in file order"
            )
        backward = int(np.count_nonzero(np.diff(stamps) < 0.0))
        order = np.argsort(stamps, kind="stable")
        if backward:
            warnings.append(f"{backward} backward steps in file order; scans sorted by stamp")
        sorted_stamps, nudged = _strictly_increasing(stamps[order])
        if nudged:
            warnings.append(
                f"{nudged} stamps did not increase after sorting; each moved to previous + "
                f"{DUPLICATE_NUDGE_S * 1e6:g} µs"
            )

        records: list[CarmenRecord] = []
        for k, stamp in zip(order, sorted_stamps):
            raw, scan = kept[int(k)]
            scan = dataclasses.replace(scan, stamp=float(stamp))
            odom, laser_pose = _pose_or_none(raw.odom), _pose_or_none(raw.laser_pose)
            records.append(CarmenRecord(scan, raw.kind, raw.line, odom, laser_pose, raw.ipc, raw.logger))
        self._records = records

        # -- odometry on the scans' clock
        if odom_rows:
            arr = np.vstack(odom_rows)
            if time_source == "ipc":
                ost = arr[:, 6].copy()
            elif time_source == "logger":
                ost = arr[:, 7].copy()
            else:
                ost = np.full(arr.shape[0], np.nan)
            oorder = np.argsort(ost, kind="stable") if time_source != "synthesized" else np.arange(arr.shape[0])
            arr = arr[oorder]
            self._odometry = CarmenOdometry(
                ost[oorder], arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3], arr[:, 4], arr[:, 5],
                np.asarray(odom_lines, dtype=np.int64)[oorder],
            )
        else:
            empty = np.empty(0)
            no_lines = np.empty(0, dtype=np.int64)
            self._odometry = CarmenOdometry(empty, empty, empty, empty, empty, empty, empty, no_lines)

        # -- metadata
        first = records[0].scan
        used = [k for k in _LASER_KINDS if any(r.kind == k for r in records)]
        diffs = np.diff(sorted_stamps)
        median_dt = float(np.median(diffs)) if diffs.size else 0.0
        ignored = {k: v for k, v in kinds.items() if k not in ("FLASER", "ROBOTLASER1", "ODOM", "#")}
        if skipped:
            warnings.append(f"{len(skipped)} malformed lines skipped")
        self.meta = SourceMeta(
            format="carmen",
            origin=str(self.path),
            topic="+".join(used),
            count=len(records),
            beams=first.n_beams,
            fov=first.fov,
            rate_hz=(1.0 / median_dt) if median_dt > 0.0 else None,
            frame_id=first.frame_id,
            range_min=first.range_min,
            range_max=first.range_max,
            extra={
                "records": dict(kinds),
                "ignored_records": ignored,
                "comments": kinds.get("#", 0),
                "odometry_records": len(odom_rows),
                "skipped_lines": len(skipped),
                "skipped_line_numbers": skipped[:MAX_REPORTED_LINES],
                "time_source": time_source,
                "backward_steps": backward,
                "nudged_stamps": nudged,
                "beam_counts": sorted({r.scan.n_beams for r in records}),
                "no_return_threshold": (max_range if max_range is not None else flaser_t),
                "no_return_rule": rule or "ROBOTLASER1 max_range field",
                "warnings": warnings,
            },
        )

    # -- ScanSource --------------------------------------------------------------

    def __iter__(self) -> Iterator[Scan]:
        for record in self._records:
            yield record.scan

    def __len__(self) -> int:
        return len(self._records)

    def records(self) -> Iterator[CarmenRecord]:
        """The laser records, in the same (strictly increasing stamp) order as the scans."""
        return iter(self._records)

    def odometry(self) -> CarmenOdometry:
        """The ``ODOM`` records (empty arrays when the log has none), sorted by stamp."""
        return self._odometry
