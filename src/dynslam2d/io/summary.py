"""What a scan source holds, measured by reading it once (for ``dynslam2d info``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from dynslam2d.types import Scan, ScanSource, SourceMeta

#: Most scans whose returns feed the range median of :func:`summarize_source`.
MAX_MEDIAN_SAMPLES = 5000


@dataclass(slots=True)
class SourceSummary:
    """Counts and statistics of a whole source. Times in s, angles in rad, ranges in m."""

    format: str
    origin: str
    topic: str | None
    scans: int
    beams_min: int
    beams_max: int
    fov: float
    rate_hz: float | None
    duration: float
    first_stamp: float
    last_stamp: float
    frame_id: str | None
    range_min: float
    range_max: float
    valid_range_min: float | None
    valid_range_median: float | None
    valid_range_max: float | None
    no_return_share: float
    max_gap: float
    extra: dict[str, object] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


class SummaryAccumulator:
    """The running counts behind :class:`SourceSummary`, fed one scan at a time.

    :func:`summarize_source` feeds it a whole source; the bag overview
    (:mod:`dynslam2d.io.baginfo`) keeps one per LaserScan topic while it reads the bag once.
    The range median is computed on the valid returns of the first 200 scans and of
    every 10th scan after that, at most :data:`MAX_MEDIAN_SAMPLES` scans, so memory
    stays bounded on long logs.
    """

    def __init__(self) -> None:
        self.n = 0
        self.beams_min, self.beams_max = 1 << 30, 0
        self.fov = 0.0
        self.first = self.last = math.nan
        self.max_gap = 0.0
        self.rmin_sensor, self.rmax_sensor = math.inf, 0.0
        self.vmin, self.vmax = math.inf, -math.inf
        self.total_beams = 0
        self.valid_beams = 0
        self.frame_id: str | None = None
        self.samples: list[np.ndarray] = []

    def add(self, scan: Scan) -> None:
        """Count one scan (stamps are taken as they come; the caller checks their order)."""
        if self.n == 0:
            self.first = scan.stamp
            self.frame_id = scan.frame_id
        else:
            self.max_gap = max(self.max_gap, scan.stamp - self.last)
        self.last = scan.stamp
        self.beams_min = min(self.beams_min, scan.n_beams)
        self.beams_max = max(self.beams_max, scan.n_beams)
        self.fov = max(self.fov, scan.fov)
        self.rmin_sensor = min(self.rmin_sensor, scan.range_min)
        self.rmax_sensor = max(self.rmax_sensor, scan.range_max)
        valid = scan.ranges[scan.valid_mask()]
        self.total_beams += scan.n_beams
        self.valid_beams += valid.size
        if valid.size:
            self.vmin = min(self.vmin, float(valid.min()))
            self.vmax = max(self.vmax, float(valid.max()))
            if len(self.samples) < 200 or (self.n % 10 == 0 and len(self.samples) < MAX_MEDIAN_SAMPLES):
                self.samples.append(valid)
        self.n += 1

    def result(self, meta: SourceMeta) -> SourceSummary:
        """The summary of the scans added so far; format, origin, topic and extra from ``meta``, and its
        ``rate_hz`` when fewer than two scans give no rate of their own."""
        n = self.n
        duration = (self.last - self.first) if n > 1 else 0.0
        median = float(np.median(np.concatenate(self.samples))) if self.samples else None
        return SourceSummary(
            format=meta.format,
            origin=meta.origin,
            topic=meta.topic,
            scans=n,
            beams_min=self.beams_min if n else 0,
            beams_max=self.beams_max,
            fov=self.fov,
            rate_hz=(n - 1) / duration if duration > 0 else meta.rate_hz,
            duration=duration,
            first_stamp=self.first,
            last_stamp=self.last,
            frame_id=self.frame_id,
            range_min=self.rmin_sensor if n else math.nan,
            range_max=self.rmax_sensor if n else math.nan,
            valid_range_min=self.vmin if self.valid_beams else None,
            valid_range_median=median,
            valid_range_max=self.vmax if self.valid_beams else None,
            no_return_share=1.0 - self.valid_beams / self.total_beams if self.total_beams else 1.0,
            max_gap=self.max_gap,
            extra=dict(meta.extra),
        )


def summarize_source(
    source: ScanSource, progress: Callable[[int], None] | None = None
) -> SourceSummary:
    """Read every scan of ``source`` and summarise it (:class:`SummaryAccumulator`).

    ``progress`` (optional) is called with the number of scans read so far, every 100 scans.
    """
    acc = SummaryAccumulator()
    for scan in source:
        acc.add(scan)
        if progress is not None and acc.n % 100 == 0:
            progress(acc.n)
    if progress is not None:
        progress(acc.n)
    return acc.result(source.meta)


#: Keys of ``SourceMeta.extra`` that count input records dropped by ``--skip-bad``.
SKIP_KEYS = ("skipped_lines", "skipped_messages", "skipped_scans")
#: Their names in summary.json's ``input_skipped``.
SKIP_NAMES = ("malformed_lines", "malformed_messages", "non_increasing_stamps")
#: Keys of ``SourceMeta.extra`` that count stamp repairs of a CARMEN log.
REPAIR_KEYS = ("backward_steps", "nudged_stamps", "largest_nudge_s", "time_source")


def input_report(meta: object) -> dict[str, object]:
    """What the reader dropped or repaired, for summary.json and the terminal.

    ``input_skipped``: ``malformed_lines`` (CARMEN), ``malformed_messages`` (bags) and
    ``non_increasing_stamps`` (scans dropped), each counted (0 when none); ``input_skipped_total`` their sum;
    ``stamp_repairs``: CARMEN stamp sorting / nudging / synthesis; ``input_warnings``.
    """
    extra = dict(getattr(meta, "extra", {}) or {})
    skipped = {name: int(extra.get(k, 0) or 0) for k, name in zip(SKIP_KEYS, SKIP_NAMES)}
    out: dict[str, object] = {"input_skipped": skipped, "input_skipped_total": sum(skipped.values())}
    repairs = {k: extra[k] for k in REPAIR_KEYS if k in extra}
    if repairs:
        out["stamp_repairs"] = repairs
    warnings = extra.get("warnings")
    if warnings:
        out["input_warnings"] = list(warnings)  # type: ignore[arg-type]
    return out
