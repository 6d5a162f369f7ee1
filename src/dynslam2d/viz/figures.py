"""Every figure of a run in one call: map.png, tracks.png and, with ground truth, errors.png."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from dynslam2d.gridmap import GridMap
from dynslam2d.memtrim import release_free_memory
from dynslam2d.pipeline import RunResult
from dynslam2d.records import TrackRows
from dynslam2d.slam.cleanup import CleanResult
from dynslam2d.slam.confidence import stretches
from dynslam2d.viz import style
from dynslam2d.viz.collect import RemovedPointsCollector
from dynslam2d.viz.mapplot import GreyMap, paint_grey, plot_map
from dynslam2d.viz.trackpaths import TrackPath, boxes_to_draw, track_paths, tracks_to_draw
from dynslam2d.viz.tracksplot import plot_tracks, tracks_background

if TYPE_CHECKING:
    from dynslam2d.eval.runeval import RunEvaluation


def _loop_segments(result: RunResult) -> np.ndarray | None:
    """(k, 2, 2) segments between the optimised positions of the two keyframes of every active loop."""
    loop = getattr(result, "loop", None)
    if loop is None or not loop.loops:
        return None
    ij = np.asarray(loop.loops, dtype=np.int64)
    # drawn where the map's poses put the keyframes: optimised, or the front end's when those were kept
    nodes = loop.node_poses if loop.corrected else loop.frontend[loop.keyframe_scans]
    return np.stack((nodes[ij[:, 0], :2], nodes[ij[:, 1], :2]), axis=1)


@dataclass(frozen=True, eq=False)
class FigureMaps:
    """The two maps the figures draw, already as grey indices (:func:`figure_maps`): map.png's (the cleaned map after
    a clean-up pass, else the online one) and tracks.png's faint online map."""

    drawn: GreyMap
    background: GreyMap


def figure_maps(result: RunResult, cleaned: CleanResult | None = None, drawn: GreyMap | None = None,
                background: GreyMap | None = None) -> FigureMaps:
    """The grey indices :func:`write_figures` draws with ``release=True``, made from ``result.grid`` and
    ``cleaned.grid``, which become None (2 bytes per cell each where the float64 maps take 8; issue 13 item 3). A
    caller that makes them before its other work (``write_outputs``: tracks.csv, kept_mask.npz, the summary) does
    that work without either float64 map. ``drawn``: map.png's grey indices made already (``GreyMap.of`` of the
    cleaned map, whose float64 map the caller let go; pass mem48), used as they are; ``background``: tracks.png's
    faint map (:func:`tracks_background` of the online map) made already, likewise."""
    if background is None:
        background = tracks_background(result.grid)
    if drawn is None:
        drawn = GreyMap.of(cleaned.grid if cleaned is not None else result.grid)
    result.grid = None  # type: ignore[assignment]
    if cleaned is not None:
        cleaned.grid = None  # type: ignore[assignment]
    return FigureMaps(drawn, background)


def write_figures(
    result: RunResult,
    out_dir: str | os.PathLike[str],
    evaluation: RunEvaluation | None = None,
    collector: RemovedPointsCollector | None = None,
    *,
    dpi: int = 120,
    cleaned: CleanResult | None = None,
    release: bool = False,
    drawn: FigureMaps | None = None,
) -> dict[str, Path]:
    """Write the figures of ``result`` into ``out_dir`` (each atomically); return paths by name.

    - ``map.png``: occupancy map, estimated trajectory (and the ground truth one, mapped
      into the run's map frame with the inverse ATE alignment), paths of the tracks that
      were ever in M or are confirmed at the end, the final confirmed boxes, the removed
      points (from ``collector``, if it watched the run), scale bar, axes in m;
    - ``tracks.png``: every track that was ever confirmed, coloured by speed (m/s), in-M
      segments solid, the rest dashed, ids labelled;
    - ``errors.png`` (only with ``evaluation``): ATE over time and the map difference (ghost
      cells, missed structure) over the ground-truth structure.

    ``evaluation``: the run scored against ground truth (:func:`dynslam2d.eval.runeval.evaluate_run`,
    the scores metrics.json holds); its ATE, alignment and cell sets are drawn as they are, never
    computed again here.

    With ``cleaned`` (the clean-up pass, docs/maps.md) map.png shows the cleaned map with
    the erased cells in :data:`style.ERASED`, and errors.png draws the cleaned map and
    names the ghost area and F1 of both maps (the evaluation's ``map`` and ``map_online``).

    ``release``: the caller does not use ``result`` and ``cleaned`` afterwards (the command line): their maps are
    let go before matplotlib draws: tracks.png's faint copy of the online map and map.png's map are made first as
    grey indices (2 bytes per cell; ``result.grid`` and ``cleaned.grid`` become None; issue 13 item 3), or taken from
    ``drawn`` (:func:`figure_maps`, made by the caller); the track rows go once the paths are built, the erased and
    restored cells once map.png is drawn (``result.track_rows`` empty, ``result.erased`` None, ``cleaned.erased``
    and ``cleaned.restored`` 0 × 0; the restored cells, never drawn, before map.png), so tracks.png is drawn without
    them.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    traj = result.trajectory
    last_stamp = float(traj.stamps[-1]) if len(traj) else None
    all_paths = track_paths(result.track_rows)
    if release:  # (the paths hold what the figures draw of them)
        result.track_rows = type(result.track_rows)() if isinstance(result.track_rows, TrackRows) else []
    # the paths each figure draws and tracks.png's count line; the other paths (tentative tracks never in M) go before
    # matplotlib's import (MIT CSAIL: 1 208 of 2 674 tracks; pass mem61)
    drawn_paths, boxes = tracks_to_draw(all_paths, last_stamp), boxes_to_draw(all_paths, last_stamp)
    confirmed = sorted((p for p in all_paths.values() if p.ever_confirmed), key=lambda p: p.id)
    counts = tracks_title(all_paths)
    del all_paths
    ate_res = None
    ref_xy = None
    if evaluation is not None and len(evaluation.reference) and len(traj):
        ate_res = evaluation.ate
        ref_xy = ate_res.alignment.inverse().transform_points(evaluation.reference.xy)
    name = result.source.origin.replace("\\", "/").split(":")[-1].rstrip("/").split("/")[-1] or result.source.origin
    if result.source.origin.startswith("sim:"):
        name = result.source.origin
    title = f"{name} — {result.n_scans} scans, filter {result.config.filter.mode}"
    if ate_res is not None:
        title += f", ATE RMSE {ate_res.rmse:.3f} m"
    removed_xy = collector.points() if collector is not None else None
    grid: GridMap | GreyMap
    background: GridMap | GreyMap
    if release:  # both maps as the grey indices the figures draw (2 bytes per cell), before matplotlib's work
        maps = drawn if drawn is not None else figure_maps(result, cleaned)
        grid, background = maps.drawn, maps.background
        del maps, drawn
        if cleaned is not None:  # (the restored cells are never drawn: they go before matplotlib's import; pass mem48)
            cleaned.restored = np.zeros((0, 0), dtype=bool)
        # the erased cells painted into map.png's indices now, as plot_map paints them (retroactive erasure's, then
        # the clean-up's over them), and both masks let go before matplotlib's import (MIT CSAIL: 3.6 MiB; pass mem49)
        if isinstance(grid, GreyMap):
            grid = paint_grey(grid, [(_memory_erased(result, grid), style.MEMORY_ERASED),
                                     (cleaned.erased if cleaned is not None else None, style.ERASED)])
            result.erased = None  # type: ignore[attr-defined]
            if cleaned is not None:
                cleaned.erased = np.zeros((0, 0), dtype=bool)
        # the masks (1 byte a cell, below the allocator's mmap threshold) lie under later blocks of the heap, which
        # keeps their pages when they are freed: back to the OS before matplotlib's import and map.png (memtrim.py;
        # MIT CSAIL: ≈ 2 MiB off map.png's peak once the clean-up pass no longer leaves its windows below them)
        release_free_memory()
    else:
        grid = cleaned.grid if cleaned is not None else result.grid
        background = result.grid
    conf = result.confidence
    pc = result.pose_confidence() if conf else {}
    paths["map.png"] = plot_map(
        out / "map.png", grid, traj.xy, reference_xy=ref_xy, title=title, dpi=dpi,
        tracks=drawn_paths, boxes=boxes,
        removed_xy=removed_xy, removed_count=removed_beams(result) if removed_xy is not None else None,
        erased=cleaned.erased if cleaned is not None and cleaned.erased.size else None,
        low_support=conf.get("low_support"), lost=conf.get("lost"),
        jumps=result.front_end_jumps()[0] if conf else None,
        warning=pc.get("warning"),  # type: ignore[arg-type]
        loop_edges=_loop_segments(result),
        memory_erased=_memory_erased(result, grid),
    )
    if release:
        del grid
        result.erased = None  # type: ignore[attr-defined]
        if cleaned is not None:
            cleaned.erased = cleaned.restored = np.zeros((0, 0), dtype=bool)
    del drawn_paths, boxes
    paths["tracks.png"] = plot_tracks(out / "tracks.png", confirmed, background, dpi=dpi, title=f"{name}\n{counts}")
    if evaluation is not None and ate_res is not None:
        from dynslam2d.viz.errorsplot import map_difference_of, plot_errors  # ground truth only

        diff = map_difference_of(evaluation.map.sets)  # the map drawn: the cleaned one after a clean-up pass
        spans = {k: stretches(traj.stamps, conf[k]) for k in ("degenerate", "low_support", "lost") if k in conf}
        note = ""
        if cleaned is not None and evaluation.map_online is not None:
            mc, mo = evaluation.map.metrics, evaluation.map_online.metrics
            note = (f"cleaned map (shown): ghost {mc.ghost_area_m2:.2f} m², F1 {mc.f1:.3f}; "
                    f"online map: ghost {mo.ghost_area_m2:.2f} m², F1 {mo.f1:.3f}")
        paths["errors.png"] = plot_errors(out / "errors.png", ate_res, diff, dpi=dpi,
                                          title=f"{name} — filter {result.config.filter.mode}",
                                          intervals=spans, map_note=note)
    return paths


def removed_beams(result: RunResult) -> int:
    """The run's removed beams: summary.json's ``removed_beam_share`` × its beams (all the removed
    beams, where the removed points drawn in map.png may be a subsample)."""
    from dynslam2d.records import BitRows

    rows = result.removed_rows
    if isinstance(rows, BitRows):
        return int(rows.total_set)
    return int(sum(int(np.count_nonzero(r)) for r in rows))


def tracks_title(paths: dict[int, TrackPath]) -> str:
    """The count line of tracks.png: the confirmed tracks it draws, named against summary.json's
    ``tracks`` (every track id, tentative ones included) and ``tracks_in_M``."""
    n_conf = sum(p.ever_confirmed for p in paths.values())
    n_conf_m = sum(p.ever_confirmed and p.ever_in_m for p in paths.values())
    n_m = sum(p.ever_in_m for p in paths.values())
    return (f"{n_conf} confirmed tracks drawn ({n_conf_m} ever in M), coloured by speed\n"
            f"(summary.json: {len(paths)} tracks with the tentative ones, {n_m} in M)")


def _memory_erased(result: RunResult, grid: GridMap | GreyMap) -> np.ndarray | None:
    """The run's retroactively erased cells (docs/maps.md) on ``grid``'s cells (the online and the cleaned
    map share cells, resolution and origin), or None."""
    erased = getattr(result, "erased", None)
    if erased is None or erased.shape != grid.shape:
        return None
    return erased


__all__ = ["FigureMaps", "figure_maps", "removed_beams", "tracks_title", "write_figures"]
