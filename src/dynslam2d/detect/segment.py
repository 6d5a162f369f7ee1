"""Breakpoint segmentation of a 2D scan into clusters of consecutive beams.

Two consecutive valid beams i, j (at most ``max_skip_beams`` no-return beams between them)
belong to the same cluster when the Euclidean gap between their points is below a threshold
(paper Eq. 1):

- adaptive (Borges & Aldon 2004; the ABD that Konstantinidis et al. 2020 describe):
  ``D = clip(r_i·sin Δφ / sin(λ − Δφ) + 3σ_r, d_min, d_max)`` with Δφ the real angle between
  the two beams (so dropped beams widen the threshold);
- fixed (datmo's actual code, ``Datmo::Clustering`` in kostaskonkk/datmo): ``D = fixed_gap``.

On a 360° scan the last and first valid beams are compared too (wrap-around), and a cluster
may run across the end of the scan. Clusters with fewer than ``min_points`` points are dropped;
clusters with more than ``max_points`` points are marked as static structure (the fit marks
clusters that are too long). Everything is in the sensor frame; the kernel is one O(n) pass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from dynslam2d.detect.config import SegmentConfig
from dynslam2d.types import Scan


@dataclass(frozen=True, slots=True, eq=False)
class Segmentation:
    """Clusters of one scan.

    Attributes:
        labels: (n_beams,) int32 cluster index of every beam, −1 for beams in no cluster
            (no return, or a dropped small cluster).
        beams: concatenated beam indices of all clusters, each cluster in scan order starting at
            its first beam (a wrapped cluster runs …, n−1, 0, 1, …).
        offsets: (k+1,) cluster c owns ``beams[offsets[c]:offsets[c+1]]``.
        structure: (k,) bool, True for clusters too large to be a moving object.
        wrapped: True if the scan was treated as a closed 360° ring.
        n_dropped: number of clusters dropped for having fewer than min_points points.
    """

    labels: np.ndarray
    beams: np.ndarray
    offsets: np.ndarray
    structure: np.ndarray
    wrapped: bool
    n_dropped: int

    @property
    def n_clusters(self) -> int:
        return int(self.offsets.shape[0] - 1)

    def cluster(self, c: int) -> np.ndarray:
        """Beam indices of cluster ``c``, in scan order."""
        return self.beams[self.offsets[c]:self.offsets[c + 1]]

    def sizes(self) -> np.ndarray:
        """(k,) number of points per cluster."""
        return np.diff(self.offsets)


@njit(cache=True)
def _link_kernel(ranges: np.ndarray, angles: np.ndarray, valid_idx: np.ndarray, fixed: bool, fixed_gap: float,
                 lam: float, three_sigma: float, d_min: float, d_max: float, max_skip: int,
                 wrap: bool) -> np.ndarray:
    """links[j] = 1 if valid beam j links to valid beam j+1 (the last one to the first when wrap)."""
    m = valid_idx.shape[0]
    links = np.zeros(m, dtype=np.uint8)
    n = ranges.shape[0]
    for j in range(m):
        if j == m - 1 and not wrap:
            break
        a = valid_idx[j]
        b = valid_idx[(j + 1) % m]
        skipped = b - a - 1 if b > a else b + n - a - 1
        if skipped > max_skip or (m == 1):
            continue
        ra = ranges[a]
        rb = ranges[b]
        dphi = abs(angles[b] - angles[a])
        if dphi > math.pi:
            dphi = 2.0 * math.pi - dphi
        gap2 = ra * ra + rb * rb - 2.0 * ra * rb * math.cos(dphi)  # law of cosines (as Datmo::Clustering)
        if gap2 < 0.0:
            gap2 = 0.0
        if fixed:
            thr = fixed_gap
        else:
            # paper Eq. 1 / Borges & Aldon 2004 ABD, clamped to [d_min, d_max]
            if dphi >= lam:
                thr = d_max
            else:
                thr = ra * math.sin(dphi) / math.sin(lam - dphi) + three_sigma
                if thr < d_min:
                    thr = d_min
                elif thr > d_max:
                    thr = d_max
        if gap2 < thr * thr:
            links[j] = 1
    return links


@njit(cache=True)
def _clusters_kernel(valid_idx: np.ndarray, links: np.ndarray, wrap: bool, n_beams: int,
                     min_points: int) -> tuple:
    """Runs of linked valid beams → (labels, beams, offsets, n_dropped)."""
    m = valid_idx.shape[0]
    labels = -np.ones(n_beams, dtype=np.int32)
    beams = np.empty(m, dtype=np.int64)
    offsets = np.zeros(m + 1, dtype=np.int64)
    if m == 0:
        return labels, beams[:0], offsets[:1], 0
    # start right after the last break so that no run is cut by the array end and clusters
    # come in scan order (a cluster wrapping past the end comes first)
    start = 0
    if wrap:
        start = -1
        for j in range(m - 1, -1, -1):
            if links[j] == 0:
                start = (j + 1) % m
                break
        if start == -1:  # one closed ring: a single cluster
            start = 0
    k = 0
    nb = 0
    dropped = 0
    count = 0
    for t in range(m):
        j = (start + t) % m
        beams[nb + count] = valid_idx[j]
        count += 1
        last = t == m - 1
        if last or links[j] == 0:
            if count >= min_points:
                for q in range(count):
                    labels[beams[nb + q]] = k
                nb += count
                k += 1
                offsets[k] = nb
            else:
                dropped += 1
            count = 0
    return labels, beams[:nb], offsets[:k + 1], dropped


def is_full_circle(scan: Scan) -> bool:
    """True when the scan's beams cover 360° (n·|Δφ| ≥ 2π − 1.5|Δφ|)."""
    inc = abs(scan.angle_increment)
    return scan.n_beams * inc >= 2.0 * math.pi - 1.5 * inc


def segment_scan(scan: Scan, config: SegmentConfig | None = None, valid: np.ndarray | None = None) -> Segmentation:
    """Split ``scan`` into clusters of consecutive beams (paper Eq. 1).

    Args:
        scan: the scan (sensor frame).
        config: segmentation parameters (defaults if None).
        valid: optional (n,) bool mask of beams to use (default ``scan.valid_mask()``; zero
            ranges are always excluded).

    Returns:
        A :class:`Segmentation`; a scan with no valid return gives zero clusters.
    """
    cfg = config or SegmentConfig()
    mask = scan.valid_mask() if valid is None else np.asarray(valid, dtype=bool) & scan.valid_mask()
    mask &= scan.ranges > 0.0
    valid_idx = np.flatnonzero(mask).astype(np.int64)
    wrap = {"auto": is_full_circle(scan), "always": True, "never": False}[cfg.wrap_around]
    wrap = wrap and valid_idx.shape[0] > 2
    links = _link_kernel(scan.ranges, scan.angles, valid_idx, cfg.mode == "fixed", float(cfg.fixed_gap),
                         math.radians(cfg.lambda_deg), 3.0 * float(cfg.sigma_r), float(cfg.d_min),
                         float(cfg.d_max), int(cfg.max_skip_beams), wrap)
    labels, beams, offsets, dropped = _clusters_kernel(valid_idx, links, wrap, scan.n_beams, int(cfg.min_points))
    structure = np.diff(offsets) > cfg.max_points
    return Segmentation(labels=labels, beams=beams, offsets=offsets, structure=structure, wrapped=bool(wrap),
                        n_dropped=int(dropped))
