"""Pose confidence of a whole run (issue 9 item 5, issue 10 items 2–4): how much of the run was
matched with low support, degenerate, or lost, and the longest such stretches.

A stretch is a run of consecutive scans with the flag set; its length is measured from the stamp
of its first scan to the stamp of the first scan after it (or its last scan), in seconds.
"""

from __future__ import annotations

import numpy as np

#: Keys of the per-scan arrays :func:`summarize` reads.
FLAGS = ("low_support", "degenerate", "lost")


def longest_stretch(stamps: np.ndarray, flag: np.ndarray) -> tuple[float, int]:
    """(duration s, scans) of the longest run of consecutive True in ``flag`` (n,) at ``stamps`` (n,) s."""
    flag = np.asarray(flag, dtype=bool)
    n = flag.shape[0]
    if n == 0 or not flag.any():
        return 0.0, 0
    d = np.diff(np.concatenate(([0], flag.astype(np.int8), [0])))
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1)  # exclusive
    best_t, best_n = 0.0, 0
    for a, b in zip(starts, ends):
        t_end = stamps[b] if b < n else stamps[b - 1]
        dur = float(t_end - stamps[a])
        if dur > best_t or (dur == best_t and b - a > best_n):
            best_t, best_n = dur, int(b - a)
    return best_t, best_n


def stretches(stamps: np.ndarray, flag: np.ndarray) -> list[tuple[float, float]]:
    """(start s, end s) of every run of consecutive True in ``flag`` (for figures)."""
    flag = np.asarray(flag, dtype=bool)
    n = flag.shape[0]
    d = np.diff(np.concatenate(([0], flag.astype(np.int8), [0])))
    out = []
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        out.append((float(stamps[a]), float(stamps[b] if b < n else stamps[b - 1])))
    return out


def jump_text(pc: dict[str, object]) -> str:
    """The largest jump of a ``pose_confidence`` block in words, as the warning and the run table give it:
    "0.98 m / 4.0° beyond the motion before it, at 729.5 s"."""
    return (f"{float(pc['largest_jump_m']):.2f} m / {float(pc['largest_jump_deg']):.1f}° beyond the motion before it"
            + (f", at {float(pc['largest_jump_s']):.1f} s" if pc.get("largest_jump_s") is not None else ""))


def summarize(stamps: np.ndarray, flags: dict[str, np.ndarray], degeneracy: np.ndarray,
              lost_events: int, relocalisations: int, max_share: float, max_stretch: float,
              jumps: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> dict[str, object]:
    """The ``pose_confidence`` block of summary.json.

    ``flags``: (n,) bool arrays "low_support", "degenerate", "lost"; ``degeneracy`` (n,) smallest /
    largest normalized Hessian eigenvalue (NaN where not matched). The run is flagged
    ``trustworthy = False`` when the share of low-support scans exceeds ``max_share`` or a
    low-support stretch lasts longer than ``max_stretch`` s, or the front end jumped; ``warning`` then says why
    in one line. ``jumps``: (flag, shift m, turn rad), each (n,), of :func:`dynslam2d.slam.jumps.jump_flags` on
    the front end's trajectory (None = not checked): a jump is the front end snapping back after drifting, so the
    poses before it were off by about its size even though every match looked well supported.
    ``largest_jump_m`` / ``largest_jump_deg`` / ``largest_jump_s`` describe one jump, the one with the largest shift:
    by how much its step exceeds the motion before it (m, °) and when (s after the first scan).
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    n = stamps.shape[0]
    out: dict[str, object] = {"scans": n}
    for key in FLAGS:
        f = np.asarray(flags.get(key, np.zeros(n, dtype=bool)), dtype=bool)
        t, k = longest_stretch(stamps, f)
        out[f"{key}_scans"] = int(f.sum())
        out[f"{key}_share"] = round(float(f.mean()), 4) if n else 0.0
        out[f"longest_{key}_s"] = round(t, 3)
        out[f"longest_{key}_scans"] = k
    lost = np.asarray(flags.get("lost", np.zeros(n, dtype=bool)), dtype=bool)
    if n > 1:
        dt = np.diff(stamps)
        out["lost_time_s"] = round(float(np.sum(dt[lost[:-1]])), 3)
        out["tracking_time_s"] = round(float(np.sum(dt[~lost[:-1]])), 3)
    else:
        out["lost_time_s"] = 0.0
        out["tracking_time_s"] = 0.0
    out["lost_events"] = int(lost_events)
    out["relocalisations"] = int(relocalisations)
    deg = np.asarray(degeneracy, dtype=np.float64)
    fin = deg[np.isfinite(deg)]
    out["degeneracy_median"] = round(float(np.median(fin)), 4) if fin.size else None
    out["degeneracy_min"] = round(float(fin.min()), 4) if fin.size else None
    share = float(out["low_support_share"])  # type: ignore[arg-type]
    longest = float(out["longest_low_support_s"])  # type: ignore[arg-type]
    reasons = []
    if share > max_share or longest > max_stretch:
        reasons.append(f"{100 * share:.0f} % of scans matched with low support (longest stretch {longest:.1f} s)")
    if lost_events:
        reasons.append(f"lost {lost_events}× ({float(out['lost_time_s']):.1f} s), relocalised {relocalisations}×")
    if jumps is not None:
        jf, jshift, jturn = (np.asarray(a) for a in jumps)
        out["jumps"] = int(jf.sum())
        out["jump_stamps_s"] = [round(float(t - stamps[0]), 3) for t in stamps[jf]] if n else []
        # the largest jump (largest shift) and that same jump's rotation excess and time: one jump, not the largest
        # shift of one and the largest rotation of another
        k = int(np.flatnonzero(jf)[np.argmax(jshift[jf])]) if jf.any() else -1
        out["largest_jump_m"] = round(float(jshift[k]), 3) if k >= 0 else 0.0
        out["largest_jump_deg"] = round(float(np.degrees(jturn[k])), 2) if k >= 0 else 0.0
        out["largest_jump_s"] = round(float(stamps[k] - stamps[0]), 3) if k >= 0 else None
        if k >= 0:
            reasons.append(f"the front end jumped {int(jf.sum())}× (largest {jump_text(out)}): the poses around it "
                           "were off by up to that much")
    out["trustworthy"] = not reasons
    out["warning"] = ("pose not trustworthy: " + "; ".join(reasons)) if reasons else None
    return out
