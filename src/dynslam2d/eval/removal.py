"""Dynamic-point removal metrics: the filter's removed beams against per-beam labels.

Labels follow the ground-truth folders (``labels.npz``, :mod:`dynslam2d.io.groundtruth`):
−1 no return, 0 static structure, k ≥ 1 mover k. A beam counts as *dynamic* when its
label is ≥ 1 and *static* when it is 0; no-return beams are in neither class and are
left out of every ratio (their count is reported, and removing one is reported too).

* precision = removed dynamic / removed (labelled with a return),
* recall = removed dynamic / dynamic,
* static_removed_share = removed static / static (the "wrongly removed" share).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.stamps import match_nearest


def _ratio(num: int, den: int) -> float:
    return num / den if den > 0 else float("nan")


@dataclass(frozen=True)
class RemovalMetrics:
    """Result of :func:`removal_metrics` (counts are beams summed over all scans).

    Attributes:
        precision: removed dynamic / removed beams with a return (NaN if none removed).
        recall: removed dynamic / dynamic beams (NaN if no dynamic beam).
        f1: harmonic mean of precision and recall (NaN if either is NaN).
        static_removed_share: removed static / static beams (NaN if no static beam).
        n_dynamic, n_static, n_no_return: beams per label class.
        n_removed: removed beams with a return; n_removed_dynamic, n_removed_static its split.
        n_removed_no_return: removed beams labelled "no return" (not in any ratio).
        per_mover_recall: mover id → share of that mover's beams removed.
        n_scans: scans compared.
    """

    precision: float
    recall: float
    f1: float
    static_removed_share: float
    n_dynamic: int
    n_static: int
    n_no_return: int
    n_removed: int
    n_removed_dynamic: int
    n_removed_static: int
    n_removed_no_return: int
    n_scans: int
    per_mover_recall: dict[int, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python mapping (mover ids become string keys, for JSON)."""
        d = asdict(self)
        d["per_mover_recall"] = {str(k): float(v) for k, v in self.per_mover_recall.items()}
        return d


def removal_metrics(removed: np.ndarray, labels: np.ndarray) -> RemovalMetrics:
    """Score removed beams against per-beam labels.

    Args:
        removed: (n_scans, beams) bool, True where the filter removed the beam.
        labels: (n_scans, beams) int labels (−1 no return, 0 static, k ≥ 1 mover k), the
            same scans in the same order (associate by stamp first if needed).

    Raises:
        DynSlamError: if the shapes differ.
    """
    rem = np.asarray(removed, dtype=bool)
    lab = np.asarray(labels)
    if rem.shape != lab.shape:
        raise DynSlamError(f"removal metrics: removed mask has shape {rem.shape} but labels have {lab.shape}")
    dyn = lab >= 1
    sta = lab == 0
    nor = lab < 0
    n_dyn, n_sta = int(dyn.sum()), int(sta.sum())
    rd, rs = int((rem & dyn).sum()), int((rem & sta).sum())
    n_rem = rd + rs
    precision = _ratio(rd, n_rem)
    recall = _ratio(rd, n_dyn)
    if np.isnan(precision) or np.isnan(recall):
        f1 = float("nan")
    elif precision + recall == 0:
        f1 = 0.0
    else:
        f1 = 2 * precision * recall / (precision + recall)
    per_mover: dict[int, float] = {}
    if n_dyn:
        ids, counts = np.unique(lab[dyn], return_counts=True)
        ids_r, counts_r = np.unique(lab[dyn & rem], return_counts=True)
        got = dict(zip(ids_r.tolist(), counts_r.tolist()))
        per_mover = {int(i): got.get(int(i), 0) / int(c) for i, c in zip(ids.tolist(), counts.tolist())}
    return RemovalMetrics(
        precision=precision,
        recall=recall,
        f1=f1,
        static_removed_share=_ratio(rs, n_sta),
        n_dynamic=n_dyn,
        n_static=n_sta,
        n_no_return=int(nor.sum()),
        n_removed=n_rem,
        n_removed_dynamic=rd,
        n_removed_static=rs,
        n_removed_no_return=int((rem & nor).sum()),
        n_scans=int(lab.shape[0]) if lab.ndim else 0,
        per_mover_recall=per_mover,
    )


def match_scans(
    removed_stamps: np.ndarray, label_stamps: np.ndarray, max_dt: float = 1e-3
) -> tuple[np.ndarray, np.ndarray]:
    """Pair the rows of a removed mask and of a label array by stamp.

    For every row of the removed mask, the label row with the nearest stamp is taken and
    kept when ``|Δt| <= max_dt`` (s). Returns ``(i_removed, i_labels)`` index arrays.

    Raises:
        DynSlamError: if no row pairs up.
    """
    a = np.asarray(removed_stamps, dtype=np.float64).reshape(-1)
    b = np.asarray(label_stamps, dtype=np.float64).reshape(-1)
    if a.size == 0 or b.size == 0:
        raise DynSlamError(f"removal metrics: {a.size} removed-mask stamps and {b.size} label stamps")
    i_a, i_b = match_nearest(a, b, max_dt)
    if i_a.size == 0:
        raise DynSlamError(f"removal metrics: no removed-mask stamp within {max_dt} s of a label stamp")
    return i_a, i_b


__all__ = ["RemovalMetrics", "match_scans", "removal_metrics"]
