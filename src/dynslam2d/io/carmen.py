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

import gzip
import math
import os
import zlib
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

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


def _show(field: str, limit: int = 24) -> str:
    """A field for an error message: ASCII-escaped (binary junk never reaches the terminal), short."""
    text = ascii(field[:limit])
    return text + ("…" if len(field) > limit else "")


def _int_field(fields: list[str], i: int, what: str) -> int:
    if i >= len(fields):
        raise _BadLine(f"line ends before {what} (field {i + 1})")
    try:
        value = int(fields[i])
    except ValueError:
        raise _BadLine(f"{what} {_show(fields[i])} is not an integer") from None
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
                raise _BadLine(f"non-numeric {what} field {_show(f)}") from None
        raise _BadLine(f"non-numeric {what} field") from None


def _stamp(field: str, what: str) -> float:
    try:
        value = float(field)
    except ValueError:
        raise _BadLine(f"non-numeric {what} {_show(field)}") from None
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
    """Move every stamp not above its predecessor to ``previous + 1 µs``; count moves.

    Where 1 µs is below the float64 resolution of the stamp, the move is to the next
    representable number above the predecessor (``np.nextafter``): the smallest step
    that keeps the order strict.
    """
    out = stamps.copy()
    nudged = 0
    if out.size > 1 and np.any(np.diff(out) <= 0.0):
        for i in range(1, out.size):
            if out[i] <= out[i - 1]:
                out[i] = max(out[i - 1] + DUPLICATE_NUDGE_S, float(np.nextafter(out[i - 1], np.inf)))
                nudged += 1
    return out, nudged


def _open_lines(path: Path) -> Iterator[bytes]:
    """The lines of ``path`` (bytes, newline kept), gunzipping when it starts with the gzip magic."""
    with path.open("rb") as raw:
        gz = raw.read(2) == _GZIP_MAGIC
    fh = gzip.open(path, "rb") if gz else path.open("rb")
    with fh:
        yield from fh


class _FlaserStats:
    """What :func:`detect_no_return_threshold` needs from all FLASER readings, in O(1) memory.

    Pass 1 keeps the count, maximum and count of the maximum of the considered readings
    (finite, above :data:`DEFAULT_RANGE_MIN`); the median test of the rule needs a second
    look at the readings only when the maximum is a repeated candidate marker.
    """

    def __init__(self) -> None:
        self.n = 0
        self.top = -math.inf
        self.top_count = 0

    def add(self, ranges: np.ndarray) -> None:
        r = ranges[np.isfinite(ranges) & (ranges > DEFAULT_RANGE_MIN)]
        if r.size == 0:
            return
        self.n += r.size
        m = float(r.max())
        c = int(np.count_nonzero(r == m))
        if m > self.top:
            self.top, self.top_count = m, c
        elif m == self.top:
            self.top_count += c

    def needs_median(self) -> bool:
        return self.n > 0 and self.top < SICK_NO_RETURN and self.top_count >= max(10, 0.001 * self.n)


class _MedianBelow:
    """Decides ``median(readings) < h`` exactly from counts (numpy's median of an even count
    is the mean of the two middle values)."""

    def __init__(self, h: float) -> None:
        self.h = h
        self.n = 0
        self.below = 0
        self.max_below = -math.inf
        self.min_above = math.inf

    def add(self, ranges: np.ndarray) -> None:
        r = ranges[np.isfinite(ranges) & (ranges > DEFAULT_RANGE_MIN)]
        if r.size == 0:
            return
        lo = r < self.h
        self.n += r.size
        k = int(np.count_nonzero(lo))
        self.below += k
        if k:
            self.max_below = max(self.max_below, float(r[lo].max()))
        if k < r.size:
            self.min_above = min(self.min_above, float(r[~lo].min()))

    def result(self) -> bool:
        n, c = self.n, self.below
        if n % 2:
            return c > n // 2
        half = n // 2
        if c >= half + 1:
            return True
        if c <= half - 1:
            return False
        return self.max_below + self.min_above < 2.0 * self.h


class CarmenSource:
    """Laser scans of a CARMEN log, in strictly increasing stamp order, read as a stream.

    The constructor reads the file once (every format error surfaces there as a
    DynSlamError ``"<file>:<line>: <what>"``) but keeps only a compact index per laser
    record (line number, stamps: ~40 bytes), the ``ODOM`` rows and counters; iterating
    reads the file again and yields one scan at a time, so memory does not grow with
    the length of the log. A log whose records are not in time order is the exception:
    its scans are parsed into memory on each iteration to be yielded sorted (such logs
    are the small flirtlib exports).

    Args:
        path: a ``.clf``/``.log`` file, plain or gzipped (detected by magic bytes).
        skip_bad: skip malformed lines instead of raising; they are counted in
            ``meta.extra["skipped_lines"]`` (first line numbers in
            ``meta.extra["skipped_line_numbers"]``).
        max_range: no-return threshold, m (``r >= max_range`` is no return) for all
            records; None = ROBOTLASER1's own field, auto-detected for FLASER.
        nominal_rate_hz: rate used to synthesize stamps when the log has none, Hz.
        origin: the name used in messages and ``meta.origin`` (default: ``path``).

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
        origin: str | None = None,
    ) -> None:
        if max_range is not None and not (math.isfinite(max_range) and max_range > DEFAULT_RANGE_MIN):
            raise DynSlamError(f"max_range must be a finite number above {DEFAULT_RANGE_MIN} m, got {max_range}")
        if not (math.isfinite(nominal_rate_hz) and nominal_rate_hz > 0.0):
            raise DynSlamError(f"nominal_rate_hz must be positive, got {nominal_rate_hz}")
        p = Path(path)
        if not p.exists():
            raise DynSlamError(f"{p}: no such file")
        if p.is_dir():
            raise DynSlamError(f"{p}: is a folder, expected a file")
        self.path = p
        self.name = origin or str(p)
        self.skip_bad = skip_bad
        self._max_range = max_range
        self._odometry: CarmenOdometry
        self.meta: SourceMeta = SourceMeta(format="carmen", origin=self.name)
        self._index(max_range, nominal_rate_hz)

    # -- reading -----------------------------------------------------------------

    def _lines(self) -> Iterator[tuple[int, str, bool]]:
        """``(line number, text, has newline)`` of every line; read errors become DynSlamError."""
        try:
            for lineno, raw in enumerate(_open_lines(self.path), start=1):
                yield lineno, raw.decode("latin-1"), raw.endswith(b"\n")
        except (OSError, EOFError, zlib.error) as exc:
            if isinstance(exc, OSError) and not isinstance(exc, gzip.BadGzipFile) and exc.errno is not None:
                raise DynSlamError(f"{self.name}: cannot read ({exc.strerror or exc})") from None
            raise DynSlamError(f"{self.name}: corrupt or truncated gzip data ({exc})") from None

    def _parse(self, kind: str, fields: list[str], lineno: int) -> _RawLaser:
        return _parse_flaser(fields, lineno) if kind == "FLASER" else _parse_robotlaser1(fields, lineno)

    def _threshold(self, raw: _RawLaser) -> float:
        if self._max_range is not None:
            return self._max_range
        if raw.max_range is not None:
            return raw.max_range
        return self._flaser_t if self._flaser_t is not None else SICK_NO_RETURN

    def _scan(self, raw: _RawLaser, stamp: float) -> Scan:
        return Scan(
            stamp=stamp,
            angle_min=raw.angle_min,
            angle_increment=raw.angle_increment,
            ranges=raw.ranges,
            range_min=DEFAULT_RANGE_MIN,
            range_max=float(np.nextafter(self._threshold(raw), 0.0)),  # r >= t is no return
            frame_id="laser",
            intensities=raw.intensities,
        )

    def _bad(self, kind: str, lineno: int, reason: str) -> None:
        if not self.skip_bad:
            raise DynSlamError(f"{self.name}:{lineno}: malformed {kind} record: {reason}") from None

    def _index(self, max_range: float | None, nominal_rate_hz: float) -> None:
        """Pass 1: validate every line, keep a compact index of the good laser records.

        Then, from that index: the FLASER no-return threshold, the scans' stamps and
        order, the ODOM records on the scans' clock, and ``meta``.
        """
        self._flaser_t: float | None = None
        found = self._read_index(max_range)
        warnings: list[str] = []
        rule = self._choose_flaser_threshold(found, max_range)
        clock = self._order_stamps(found.lines, nominal_rate_hz, warnings)
        self._odometry = _odometry_on_clock(found.odom, found.odom_lines, clock.time_source)
        self.meta = self._describe(found, clock, rule, max_range, warnings)

    def _read_index(self, max_range: float | None) -> _Pass1:
        """Read every line once: count record kinds, parse (and check) the laser and ODOM
        records, and index the good laser records; a file without any is an error."""
        found = _Pass1()
        any_text = False
        for lineno, line, newline in self._lines():
            fields = line.split()
            if not fields:
                continue
            any_text = True
            kind = fields[0]
            if kind.startswith("#"):
                found.kinds["#"] += 1
                continue
            found.kinds[kind] += 1
            if kind not in ("FLASER", "ROBOTLASER1", "ODOM"):
                continue
            try:
                if kind == "ODOM":
                    found.odom.append(_parse_odom(fields))
                    found.odom_lines.append(lineno)
                    continue
                raw = self._parse(kind, fields, lineno)
            except _BadLine as exc:
                reason = str(exc)
                if not newline:
                    reason += " (last line has no newline: file truncated?)"
                self._bad(kind, lineno, reason)
                found.skip(lineno)
                continue
            try:  # geometry the Scan type rejects is a bad line too (range limit provisional here)
                self._scan(raw, raw.ipc)
            except DynSlamError as exc:
                self._bad(raw.kind, lineno, str(exc))
                found.skip(lineno)
                continue
            if raw.kind == "FLASER" and max_range is None:
                found.stats.add(raw.ranges)
            found.lines.append(lineno, raw.ipc, raw.logger, raw.kind == "FLASER")
            found.beam_counts.add(int(raw.ranges.shape[0]))
        if not any_text:
            raise DynSlamError(f"{self.name}: file is empty")
        if len(found.lines) == 0:
            kinds, n_skipped = found.kinds, found.n_skipped
            listed = ", ".join(f"{k}×{v}" for k, v in sorted(kinds.items())) or "nothing"
            extra = f"; {n_skipped} malformed laser/odometry lines skipped" if n_skipped else ""
            if not any(kinds.get(k) for k in _LASER_KINDS):
                raise DynSlamError(f"{self.name}: no FLASER or ROBOTLASER1 laser records (found {listed}){extra}")
            raise DynSlamError(f"{self.name}: no valid laser records ({n_skipped} malformed lines skipped)")
        return found

    def _choose_flaser_threshold(self, found: _Pass1, max_range: float | None) -> str:
        """Set the no-return threshold of FLASER records (detect_no_return_threshold, streamed);
        return the rule that chose it ("" when no FLASER record needs one)."""
        rule = "max_range argument" if max_range is not None else ""
        stats = found.stats
        if max_range is None and found.lines.any_flaser():
            if stats.n == 0:
                self._flaser_t, rule = SICK_NO_RETURN, "default (no finite readings)"
            elif stats.top >= SICK_NO_RETURN:
                self._flaser_t, rule = SICK_NO_RETURN, "SICK no-return values (>= 81.83 m) present"
            elif stats.needs_median() and stats.top > 0.1 and self._median_below(stats.top / 2.0):
                self._flaser_t = stats.top
                rule = f"saturation marker {stats.top:g} m repeated {stats.top_count} times"
            else:
                self._flaser_t, rule = SICK_NO_RETURN, "default (no saturation marker found)"
        return rule

    def _order_stamps(self, lines: GrowLines, nominal_rate_hz: float, warnings: list[str]) -> _Clock:
        """Stamps: ipc, else logger, else synthesized; sorted stably and made strictly increasing.

        Sets the scans' order and stamps; appends a string to ``warnings`` for each fallback
        or repair.
        """
        n = len(lines)
        line_no, ipc, logger, is_flaser = lines.arrays()
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
        largest_nudge = 0.0
        if nudged:
            step = sorted_stamps - stamps[order]
            largest_nudge = float(step.max())
            warnings.append(
                f"{nudged} stamps did not increase after sorting; each moved to previous + "
                f"{DUPLICATE_NUDGE_S * 1e6:g} µs (largest move {largest_nudge:.3g} s)"
            )
        self._order = order
        self._stamps = sorted_stamps
        self._lines_sorted = line_no[order]
        self._identity = bool(np.all(order == np.arange(n)))
        return _Clock(time_source, backward, nudged, largest_nudge, is_flaser)

    def _describe(
        self, found: _Pass1, clock: _Clock, rule: str, max_range: float | None, warnings: list[str]
    ) -> SourceMeta:
        """The source's metadata (geometry from the first scan in stamp order)."""
        first = next(self.records()).scan
        is_flaser = clock.is_flaser
        used = [k for k, present in (("FLASER", bool(is_flaser.any())), ("ROBOTLASER1", bool((~is_flaser).any())))
                if present]
        diffs = np.diff(self._stamps)
        median_dt = float(np.median(diffs)) if diffs.size else 0.0
        kinds = found.kinds
        ignored = {k: v for k, v in kinds.items() if k not in ("FLASER", "ROBOTLASER1", "ODOM", "#")}
        if found.n_skipped:
            warnings.append(f"{found.n_skipped} malformed lines skipped")
        return SourceMeta(
            format="carmen",
            origin=self.name,
            topic="+".join(used),
            count=len(found.lines),
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
                "odometry_records": len(found.odom),
                "skipped_lines": found.n_skipped,
                "skipped_line_numbers": found.skipped,
                "time_source": clock.time_source,
                "backward_steps": clock.backward,
                "nudged_stamps": clock.nudged,
                "largest_nudge_s": clock.largest_nudge,
                "beam_counts": sorted(found.beam_counts),
                "no_return_threshold": (max_range if max_range is not None else self._flaser_t),
                "no_return_rule": rule or "ROBOTLASER1 max_range field",
                "warnings": warnings,
            },
        )

    def _median_below(self, h: float) -> bool:
        """Pass over the FLASER readings again: is their median below ``h``?"""
        med = _MedianBelow(h)
        for lineno, line, _ in self._lines():
            fields = line.split()
            if not fields or fields[0] != "FLASER":
                continue
            try:
                raw = _parse_flaser(fields, lineno)
                self._scan(raw, raw.ipc)
            except (_BadLine, DynSlamError):
                continue
            med.add(raw.ranges)
        return med.result()

    def _file_order_records(self) -> Iterator[tuple[int, _RawLaser]]:
        """``(file-order index, parsed record)`` of every indexed laser record, streaming."""
        wanted = np.sort(self._lines_sorted)
        k = 0
        total = wanted.shape[0]
        for lineno, line, _ in self._lines():
            if k >= total:
                return
            if lineno != wanted[k]:
                continue
            fields = line.split()
            yield k, self._parse(fields[0], fields, lineno)
            k += 1

    def _record(self, raw: _RawLaser, stamp: float) -> CarmenRecord:
        scan = self._scan(raw, float(stamp))
        odom, laser_pose = _pose_or_none(raw.odom), _pose_or_none(raw.laser_pose)
        return CarmenRecord(scan, raw.kind, raw.line, odom, laser_pose, raw.ipc, raw.logger)

    # -- ScanSource --------------------------------------------------------------

    def __iter__(self) -> Iterator[Scan]:
        for record in self.records():
            yield record.scan

    def __len__(self) -> int:
        return int(self._stamps.shape[0])

    def records(self) -> Iterator[CarmenRecord]:
        """The laser records, in the same (strictly increasing stamp) order as the scans."""
        if self._identity:
            for k, raw in self._file_order_records():
                yield self._record(raw, self._stamps[k])
            return
        # Out of time order: parse all, then yield sorted (file index -> sorted position).
        raws = dict(self._file_order_records())
        for pos, k in enumerate(self._order):
            yield self._record(raws[int(k)], self._stamps[pos])

    def odometry(self) -> CarmenOdometry:
        """The ``ODOM`` records (empty arrays when the log has none), sorted by stamp."""
        return self._odometry


class GrowLines:
    """Index rows of pass 1: line number, ipc stamp, logger stamp, FLASER flag (compact arrays)."""

    def __init__(self) -> None:
        from dynslam2d.records import GrowArray

        self._line = GrowArray(np.int64)
        self._ipc = GrowArray(np.float64)
        self._logger = GrowArray(np.float64)
        self._flaser = GrowArray(np.bool_)

    def append(self, line: int, ipc: float = 0.0, logger: float = 0.0, flaser: bool = False) -> None:
        self._line.append(line)
        self._ipc.append(ipc)
        self._logger.append(logger)
        self._flaser.append(flaser)

    def __len__(self) -> int:
        return len(self._line)

    def any_flaser(self) -> bool:
        return bool(self._flaser.view().any())

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return (self._line.view().copy(), self._ipc.view().copy(), self._logger.view().copy(),
                self._flaser.view().copy())


class GrowArrayF:
    """Rows of ``width`` float64 values (the ODOM records)."""

    def __init__(self, width: int) -> None:
        from dynslam2d.records import GrowArray

        self._a = GrowArray(np.float64, (width,))

    def append(self, row: np.ndarray) -> None:
        self._a.append(row)

    def __len__(self) -> int:
        return len(self._a)

    def array(self) -> np.ndarray:
        return self._a.view().copy()


class _Pass1:
    """What pass 1 over a CARMEN file keeps: the laser-record index, the ODOM rows, counters."""

    def __init__(self) -> None:
        self.lines = GrowLines()
        self.odom = GrowArrayF(8)
        self.odom_lines = GrowLines()
        self.kinds: Counter[str] = Counter()
        self.skipped: list[int] = []  # the first MAX_REPORTED_LINES skipped line numbers
        self.n_skipped = 0
        self.stats = _FlaserStats()
        self.beam_counts: set[int] = set()

    def skip(self, lineno: int) -> None:
        """Count a malformed line (skip_bad)."""
        self.n_skipped += 1
        if len(self.skipped) < MAX_REPORTED_LINES:
            self.skipped.append(lineno)


@dataclass(frozen=True)
class _Clock:
    """How the scans' stamps were made: source, repairs, and which records are FLASER (file order)."""

    time_source: str
    backward: int
    nudged: int
    largest_nudge: float
    is_flaser: np.ndarray


def _odometry_on_clock(odom: GrowArrayF, odom_lines: GrowLines, time_source: str) -> CarmenOdometry:
    """The ODOM records stamped on the scans' clock (``time_source``) and sorted by stamp
    (file order when the scans' stamps are synthesized: ODOM stamps are then NaN)."""
    if len(odom):
        arr = odom.array()
        if time_source == "ipc":
            ost = arr[:, 6].copy()
        elif time_source == "logger":
            ost = arr[:, 7].copy()
        else:
            ost = np.full(arr.shape[0], np.nan)
        oorder = np.argsort(ost, kind="stable") if time_source != "synthesized" else np.arange(arr.shape[0])
        arr = arr[oorder]
        return CarmenOdometry(
            ost[oorder], arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3], arr[:, 4], arr[:, 5],
            odom_lines.arrays()[0][oorder],
        )
    empty = np.empty(0)
    no_lines = np.empty(0, dtype=np.int64)
    return CarmenOdometry(empty, empty, empty, empty, empty, empty, empty, no_lines)
