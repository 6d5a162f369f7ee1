"""Live view of a run in the Rerun viewer (issue 6, "Live viewer"; optional extra).

:class:`RerunViewer` is a :class:`~dynslam2d.pipeline.RunObserver` that streams a
run to Rerun (https://rerun.io, package ``rerun-sdk``), scan by scan, either to a
spawned viewer window or into an ``.rrd`` recording file. It needs the ``viewer``
extra (``pip install "dynslam2d[viewer]"``); ``rerun`` is imported only when a
viewer is made, and without it :class:`DynSlamError` says how to install it.

Entities (all in the map frame, metres, z = 0; the "world" view is z-up, REP 103):

==========================  =========================================================
``world/scan/kept``         endpoints of the beams the map update used (grey)
``world/scan/removed``      endpoints of the beams the filter removed (red)
``world/tracks``            each live track's box as a closed line strip, labelled with
                            its id; red = in the dynamic set M, blue = not in M
``world/tracks/velocity``   velocity arrows, ``velocity · arrow_time`` long
``world/laser``             the laser pose: an arrow 0.5 m long along its heading
``world/trajectory``        the path so far (logged with the map, and at the end)
``world/map``               occupied cells (p > 0.65) as points, every ``map_period`` s
``map``                     the finest map as a grey image (north up, 205 = unknown)
``stats/score``             match score per scan; ``stats/removed`` beams removed per scan
==========================  =========================================================

Timelines: ``scan`` (scan index) and ``time`` (scan stamp − first stamp, s).
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.io.atomic import atomic_path
from dynslam2d.types import Scan, Track

if TYPE_CHECKING:
    from dynslam2d.pipeline import Pipeline, RunResult, StepResult

__all__ = ["INSTALL_HINT", "RerunViewer", "map_image", "scan_layers", "track_strips"]

#: The message shown when the ``viewer`` extra is missing.
INSTALL_HINT = 'the live viewer needs the viewer extra: pip install "dynslam2d[viewer]"'

#: How long closing waits for a live viewer to take the rest of the stream, s.
_LIVE_FLUSH_S = 10.0

_KEPT = (150, 150, 150)
_REMOVED = (230, 40, 25)
_IN_M = (230, 40, 25)
_NOT_M = (30, 115, 230)
_PATH = (255, 150, 0)
_WALL = (20, 20, 20)


def _import_rerun() -> Any:
    """``import rerun``, or DynSlamError with :data:`INSTALL_HINT` when it is not installed."""
    try:
        import rerun
    except ImportError as err:  # also raised when sys.modules["rerun"] is None
        raise DynSlamError(INSTALL_HINT) from err
    return rerun


# --------------------------------------------------------------------------- pure helpers


def scan_layers(scan: Scan, step: StepResult) -> tuple[np.ndarray, np.ndarray]:
    """((k, 2) kept, (r, 2) removed) beam endpoints of ``scan`` in the map frame, m.

    Kept = valid beams (REP 117) not removed by the filter; removed = valid beams in
    ``step.removed``. Points are placed with ``step.pose`` (laser pose in the map frame).
    """
    valid = scan.valid_mask()
    removed = np.asarray(step.removed, dtype=bool)
    if removed.shape != valid.shape:
        removed = np.zeros_like(valid)
    kept_xy = step.pose.transform_points(scan.points(valid & ~removed))
    removed_xy = step.pose.transform_points(scan.points(valid & removed))
    return kept_xy, removed_xy


def track_strips(tracks: list[Track]) -> list[np.ndarray]:
    """One closed (5, 3) polyline per track box (map frame, z = 0), in the order of ``tracks``."""
    strips = []
    for t in tracks:
        c = t.box.corners()
        strips.append(np.column_stack((np.vstack([c, c[:1]]), np.zeros(5))))
    return strips


def map_image(grid: GridMap) -> np.ndarray:
    """(H, W) uint8 picture of ``grid``, row 0 at the TOP (north up), map_server shades:
    ``round(254 − 254·p)`` (254 free … 0 occupied), 205 unknown."""
    prob = np.asarray(grid.prob, dtype=np.float64)
    img = np.full(prob.shape, 205, dtype=np.uint8)
    known = np.isfinite(prob)
    img[known] = np.rint(254.0 * (1.0 - np.clip(prob[known], 0.0, 1.0))).astype(np.uint8)
    return np.ascontiguousarray(img[::-1])


def _xyz(xy: np.ndarray) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.column_stack((xy, np.zeros(len(xy))))


# --------------------------------------------------------------------------- the observer


class RerunViewer:
    """Streams a run to Rerun (a :class:`~dynslam2d.pipeline.RunObserver`).

    Args:
        save: write the stream into this ``.rrd`` file instead of a viewer window (it
            appears only once the run finished: :func:`atomic_path`). None = spawn the
            Rerun viewer (a separate process from the ``rerun-sdk`` package) and stream to it.
        map_period: log the map image, occupied cells and trajectory whenever this much scan
            time (s) passed since the last time (0 = every scan); always once at the end.
        arrow_time: velocity arrows are ``velocity · arrow_time`` long, s.
        application_id: the Rerun application id (names the recording in the viewer).
        env: environment used to check, on Linux, that the spawned viewer has a display
            (``DISPLAY`` or ``WAYLAND_DISPLAY``); None = ``os.environ``. Without one the
            viewer window cannot open and :class:`DynSlamError` says to use ``save``.

    Use it as a context manager around :func:`~dynslam2d.pipeline.run` so that a failed run
    closes the stream (and discards a half-written ``save`` file)::

        with RerunViewer() as viewer:
            run(source, config, observers=[viewer])

    Raises:
        DynSlamError: ``rerun-sdk`` is not installed (message: :data:`INSTALL_HINT`), or
            the viewer / file cannot be opened.
    """

    def __init__(self, *, save: str | os.PathLike[str] | None = None, map_period: float = 1.0,
                 arrow_time: float = 1.0, application_id: str = "dynslam2d",
                 env: Mapping[str, str] | None = None) -> None:
        rr = _import_rerun()
        if not (math.isfinite(map_period) and map_period >= 0):
            raise DynSlamError(f"live viewer: map period must be a number of seconds >= 0, got {map_period}")
        self._rr = rr
        self.map_period = float(map_period)
        self.arrow_time = float(arrow_time)
        self.save = Path(save) if save is not None else None
        self._stack = contextlib.ExitStack()
        self._closed = False
        try:
            self._rec = _new_recording(rr, application_id)
            if self.save is not None:
                tmp = self._stack.enter_context(atomic_path(self.save))
                rr.save(str(tmp), recording=self._rec)
            else:
                _check_display(env)
                rr.spawn(recording=self._rec)
        except DynSlamError as err:
            self._stack.__exit__(type(err), err, None)
            raise
        except Exception as err:
            self._stack.__exit__(type(err), err, None)
            where = str(self.save) if self.save is not None else "live viewer"
            raise DynSlamError(f"{where}: cannot start the Rerun stream ({type(err).__name__}: {err})") from err
        self._log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._t0: float | None = None
        self._path: list[tuple[float, float]] = []
        self._last_map_stamp: float | None = None
        self._last_map_index: int | None = None
        self._last_index = -1

    # ---- RunObserver
    def on_scan(self, scan: Scan, step: StepResult, pipeline: Pipeline) -> None:
        """Log the scan layers, tracks, pose and stats of one scan (and the map when due)."""
        rr = self._rr
        if self._t0 is None:
            self._t0 = scan.stamp
        self._set_time(step.index, scan.stamp - self._t0)
        kept, removed = scan_layers(scan, step)
        self._log("world/scan/kept", rr.Points3D(_xyz(kept), colors=[_KEPT], radii=[0.03]))
        self._log("world/scan/removed", rr.Points3D(_xyz(removed), colors=[_REMOVED], radii=[0.05]))
        tracks = step.tracks
        colors = [_IN_M if t.in_m else _NOT_M for t in tracks]
        self._log("world/tracks", rr.LineStrips3D(track_strips(tracks), colors=colors, radii=[0.02],
                                                  labels=[str(t.id) for t in tracks]))
        origins = _xyz([t.box.center for t in tracks])
        vectors = _xyz([np.asarray(t.velocity) * self.arrow_time for t in tracks])
        self._log("world/tracks/velocity", rr.Arrows3D(origins=origins, vectors=vectors, colors=colors))
        p = step.pose
        self._log("world/laser", rr.Arrows3D(origins=[[p.x, p.y, 0.0]],
                                             vectors=[[0.5 * math.cos(p.theta), 0.5 * math.sin(p.theta), 0.0]],
                                             colors=[_PATH]))
        self._path.append((p.x, p.y))
        self._scalar("stats/score", float(step.score))
        self._scalar("stats/removed", float(np.count_nonzero(step.removed)))
        self._last_index = step.index
        if self._last_map_stamp is None or scan.stamp - self._last_map_stamp >= self.map_period:
            self._log_map(pipeline.gridmap())
            self._last_map_stamp, self._last_map_index = scan.stamp, step.index

    def on_finish(self, result: RunResult, pipeline: Pipeline) -> None:
        """Log the final map and trajectory (unless just logged) and close the stream."""
        if self._last_map_index != self._last_index and self._t0 is not None:
            self._log_map(result.grid)
        self.close()

    # ---- lifetime
    def close(self) -> None:
        """Flush and close the stream (idempotent); a ``save`` file appears now."""
        if self._closed:
            return
        self._closed = True
        try:
            _finish(self._rr, self._rec, 120.0 if self.save is not None else _LIVE_FLUSH_S)
        except Exception as err:
            self._stack.__exit__(type(err), err, None)
            raise DynSlamError(f"{self.save or 'live viewer'}: cannot finish the Rerun stream ({err})") from err
        self._stack.close()

    def abort(self) -> None:
        """Close the stream and discard a ``save`` file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(Exception):
            _finish(self._rr, self._rec, _LIVE_FLUSH_S)
        err = RuntimeError("run aborted")
        with contextlib.suppress(RuntimeError):
            self._stack.__exit__(RuntimeError, err, None)

    def __enter__(self) -> RerunViewer:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # ---- helpers
    def _log(self, path: str, entity: Any, static: bool = False) -> None:
        self._rr.log(path, entity, static=static, recording=self._rec)

    def _scalar(self, path: str, value: float) -> None:
        rr = self._rr
        cls = getattr(rr, "Scalars", None)  # rerun >= 0.23
        self._log(path, cls([value]) if cls is not None else rr.Scalar(value))

    def _set_time(self, index: int, seconds: float) -> None:
        rr = self._rr
        if hasattr(rr, "set_time"):  # rerun >= 0.23
            rr.set_time("scan", sequence=int(index), recording=self._rec)
            rr.set_time("time", duration=float(seconds), recording=self._rec)
        else:
            rr.set_time_sequence("scan", int(index), recording=self._rec)
            rr.set_time_seconds("time", float(seconds), recording=self._rec)

    def _log_map(self, grid: GridMap) -> None:
        rr = self._rr
        if grid.prob.size:
            self._log("map", rr.Image(map_image(grid)))
            occ = grid.occupied()
            xs, ys = grid.cell_centers()
            self._log("world/map", rr.Points3D(_xyz(np.column_stack((xs[occ], ys[occ]))), colors=[_WALL],
                                               radii=[0.5 * grid.resolution]))
        if self._path:
            self._log("world/trajectory", rr.LineStrips3D([_xyz(np.array(self._path))], colors=[_PATH],
                                                          radii=[0.02]))


def _new_recording(rr: Any, application_id: str) -> Any:
    """A recording stream of its own (no global default), across rerun-sdk versions."""
    if hasattr(rr, "new_recording"):  # rerun < 0.24
        return rr.new_recording(application_id=application_id)
    return rr.RecordingStream(application_id)


def _check_display(env: Mapping[str, str] | None) -> None:
    """On Linux, refuse to spawn the viewer window when there is no display to show it on."""
    if not sys.platform.startswith("linux"):
        return
    env = os.environ if env is None else env
    if not (env.get("DISPLAY") or env.get("WAYLAND_DISPLAY")):
        raise DynSlamError(
            "live viewer: no display (DISPLAY / WAYLAND_DISPLAY unset), the Rerun viewer cannot open; "
            "record to an .rrd file instead and open it with `rerun FILE.rrd` elsewhere"
        )


def _finish(rr: Any, rec: Any, timeout_s: float) -> None:
    """Flush everything logged (waiting at most ``timeout_s`` where the SDK allows it) and
    close the sinks: an .rrd file is complete afterwards. A viewer that went away makes
    the flush raise instead of blocking forever."""
    flush = getattr(rec, "flush", None)
    try:
        if flush is not None:
            try:
                flush(timeout_sec=timeout_s)  # rerun >= 0.24
            except TypeError:
                flush()
    finally:
        rr.disconnect(recording=rec)

