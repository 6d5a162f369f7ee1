"""What a scan source holds, measured by reading it once (for ``dynslam2d info``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from dynslam2d.types import ScanSource

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


def summarize_source(
    source: ScanSource, progress: Callable[[int], None] | None = None
) -> SourceSummary:
    """Read every scan of ``source`` and summarise it.

    ``progress`` (optional) is called with the number of scans read so far, every 100 scans.
    The range median is computed on the valid returns of the first 200 scans and of
    every 10th scan after that, at most :data:`MAX_MEDIAN_SAMPLES` scans, so memory
    stays bounded on long logs.
    """
    n = 0
    beams_min, beams_max = 1 << 30, 0
    fov = 0.0
    first = last = math.nan
    max_gap = 0.0
    rmin_sensor, rmax_sensor = math.inf, 0.0
    vmin, vmax = math.inf, -math.inf
    total_beams = 0
    valid_beams = 0
    frame_id: str | None = None
    samples: list[np.ndarray] = []
    for scan in source:
        if n == 0:
            first = scan.stamp
            frame_id = scan.frame_id
        else:
            max_gap = max(max_gap, scan.stamp - last)
        last = scan.stamp
        beams_min = min(beams_min, scan.n_beams)
        beams_max = max(beams_max, scan.n_beams)
        fov = max(fov, scan.fov)
        rmin_sensor = min(rmin_sensor, scan.range_min)
        rmax_sensor = max(rmax_sensor, scan.range_max)
        valid = scan.ranges[scan.valid_mask()]
        total_beams += scan.n_beams
        valid_beams += valid.size
        if valid.size:
            vmin = min(vmin, float(valid.min()))
            vmax = max(vmax, float(valid.max()))
            if len(samples) < 200 or (n % 10 == 0 and len(samples) < MAX_MEDIAN_SAMPLES):
                samples.append(valid)
        n += 1
        if progress is not None and n % 100 == 0:
            progress(n)
    if progress is not None:
        progress(n)
    duration = (last - first) if n > 1 else 0.0
    median = float(np.median(np.concatenate(samples))) if samples else None
    meta = source.meta
    return SourceSummary(
        format=meta.format,
        origin=meta.origin,
        topic=meta.topic,
        scans=n,
        beams_min=beams_min if n else 0,
        beams_max=beams_max,
        fov=fov,
        rate_hz=(n - 1) / duration if duration > 0 else meta.rate_hz,
        duration=duration,
        first_stamp=first,
        last_stamp=last,
        frame_id=frame_id,
        range_min=rmin_sensor if n else math.nan,
        range_max=rmax_sensor if n else math.nan,
        valid_range_min=vmin if valid_beams else None,
        valid_range_median=median,
        valid_range_max=vmax if valid_beams else None,
        no_return_share=1.0 - valid_beams / total_beams if total_beams else 1.0,
        max_gap=max_gap,
        extra=dict(meta.extra),
    )


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
