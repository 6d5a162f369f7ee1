"""Ground-truth folders: what ``dynslam2d simulate`` writes and ``--gt DIR`` reads.

A folder holds, all in the **first-scan frame** (the laser pose at the first scan,
which is the map frame SLAM output uses, so a perfect run overlays directly):

- ``gt_map.pgm`` + ``gt_map.yaml``: the static structure (map_server, trinary);
- ``gt_trajectory.tum``: the true laser pose at every scan stamp;
- ``labels.npz``: ``stamps`` (n,) s and ``labels`` (n, beams) int16 per-beam labels
  (−1 no return, 0 static structure, k ≥ 1 mover k);
- ``movers.csv``: one row per scan and mover: stamp, id, kind, x, y, heading,
  length, width, vx, vy, hits (m, rad, m/s; hits = beams on the mover);
- ``simulation.yaml``: scenario, seed, duration, sensor, frame, map resolution.

This module only reads and writes files; it does not import the simulator.
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.io.atomic import atomic_path, write_text_atomic
from dynslam2d.io.mapfile import read_map, write_map
from dynslam2d.io.trajectory import Trajectory, read_tum, write_tum

GT_MAP = "gt_map.yaml"
GT_TRAJECTORY = "gt_trajectory.tum"
GT_LABELS = "labels.npz"
GT_MOVERS = "movers.csv"
GT_INFO = "simulation.yaml"


@dataclass(eq=False)
class GroundTruthFiles:
    """The contents of a ground-truth folder (first-scan frame).

    Attributes:
        trajectory: true laser poses at the scan stamps.
        static_map: the static structure (1 occupied, 0 free, NaN unknown).
        stamps: (n,) scan stamps of ``labels``, s.
        labels: (n, beams) int16 per-beam labels.
        movers: structured array of mover rows (see module docstring), or None.
        info: the simulation.yaml mapping (empty when absent).
    """

    trajectory: Trajectory
    static_map: GridMap
    stamps: np.ndarray
    labels: np.ndarray
    movers: np.ndarray | None
    info: dict[str, Any]


def write_ground_truth_folder(
    out_dir: str | os.PathLike[str],
    *,
    trajectory: Trajectory,
    static_map: GridMap,
    labels: np.ndarray,
    mover_rows: np.ndarray,
    info: dict[str, Any],
) -> list[Path]:
    """Write the ground-truth files into ``out_dir`` (each atomically); return their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    written += list(write_map(out / GT_MAP, static_map))
    written.append(write_tum(out / GT_TRAJECTORY, trajectory, comment="ground-truth laser pose, first-scan frame"))
    with atomic_path(out / GT_LABELS) as tmp:
        with tmp.open("wb") as fh:
            np.savez_compressed(fh, stamps=trajectory.stamps, labels=np.asarray(labels, dtype=np.int16))
    written.append(out / GT_LABELS)
    buf = io.StringIO()
    names = list(mover_rows.dtype.names or ())
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(names)
    for row in mover_rows:
        writer.writerow([repr(float(v)) if isinstance(v, (float, np.floating)) else str(v) for v in row])
    written.append(write_text_atomic(out / GT_MOVERS, buf.getvalue()))
    written.append(write_text_atomic(out / GT_INFO, yaml.safe_dump(info, sort_keys=False, allow_unicode=True)))
    return written


def _read_movers(path: Path) -> np.ndarray | None:
    if not path.exists():
        return None
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise DynSlamError(f"{path}: empty movers file (expected a header line)")
    header, body = rows[0], rows[1:]
    dtypes = {"id": "i4", "hits": "i4", "kind": "U8"}
    dtype = np.dtype([(h, dtypes.get(h, "f8")) for h in header])
    out = np.zeros(len(body), dtype=dtype)
    for i, row in enumerate(body):
        if len(row) != len(header):
            raise DynSlamError(f"{path}:{i + 2}: {len(row)} fields, header has {len(header)}")
        try:
            out[i] = tuple(row)
        except ValueError as exc:
            raise DynSlamError(f"{path}:{i + 2}: malformed value ({exc})") from exc
    return out


def read_ground_truth_folder(gt_dir: str | os.PathLike[str]) -> GroundTruthFiles:
    """Read a folder written by :func:`write_ground_truth_folder` (``dynslam2d simulate``)."""
    d = Path(gt_dir)
    if not d.is_dir():
        raise DynSlamError(f"{d}: ground-truth folder not found")
    for name in (GT_MAP, GT_TRAJECTORY, GT_LABELS):
        if not (d / name).exists():
            raise DynSlamError(f"{d}: not a ground-truth folder ({name} is missing; write one with 'dynslam2d "
                               f"simulate')")
    try:
        with np.load(d / GT_LABELS) as npz:
            stamps = np.asarray(npz["stamps"], dtype=np.float64)
            labels = np.asarray(npz["labels"], dtype=np.int16)
    except (OSError, ValueError, KeyError) as exc:
        raise DynSlamError(f"{d / GT_LABELS}: cannot read labels ({exc})") from exc
    if labels.ndim != 2 or labels.shape[0] != stamps.shape[0]:
        raise DynSlamError(f"{d / GT_LABELS}: labels shape {labels.shape} does not match {stamps.shape[0]} stamps")
    info: dict[str, Any] = {}
    if (d / GT_INFO).exists():
        info = yaml.safe_load((d / GT_INFO).read_text(encoding="utf-8")) or {}
    return GroundTruthFiles(
        trajectory=read_tum(d / GT_TRAJECTORY),
        static_map=read_map(d / GT_MAP),
        stamps=stamps,
        labels=labels,
        movers=_read_movers(d / GT_MOVERS),
        info=info,
    )
