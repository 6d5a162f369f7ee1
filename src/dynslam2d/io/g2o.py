"""g2o text format for 2D pose graphs (``graph.g2o``; docs/slam.md, "Loop closure").

The format g2o (Kümmerle et al., ICRA 2011) and gtsam's ``readG2o`` load:

    VERTEX_SE2 id x y theta
    EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33
    FIX id

``(dx, dy, dtheta)`` is the pose of vertex j in the frame of vertex i (m, rad); ``I..`` the upper
triangle of the 3×3 information matrix, row by row (order x, y, θ). Loop edges are the same
records; a ``# LOOP i j`` comment before each marks them for readers of this project (g2o and gtsam
skip comment lines).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dynslam2d.errors import DynSlamError
from dynslam2d.io.atomic import write_text_atomic
from dynslam2d.slam.posegraph import PoseGraph

_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


@dataclass(slots=True)
class G2oGraph:
    """A graph read back from a g2o file.

    Attributes:
        ids: (n,) vertex ids in file order; poses: (n, 3) their poses (m, rad).
        edges: (m, 2) int64 vertex ids (i, j); z: (m, 3) measurements; info: (m, 3, 3).
        loop: (m,) bool, edges marked ``# LOOP``; fixed: ids of ``FIX`` records.
    """

    ids: np.ndarray
    poses: np.ndarray
    edges: np.ndarray
    z: np.ndarray
    info: np.ndarray
    loop: np.ndarray
    fixed: list[int]

    def to_posegraph(self) -> PoseGraph:
        """The graph as a :class:`PoseGraph` (vertex ids mapped to 0 … n−1 in file order)."""
        g = PoseGraph()
        index = {int(v): k for k, v in enumerate(self.ids)}
        for p in self.poses:
            g.add_node(p)
        for (i, j), z, info, lp in zip(self.edges, self.z, self.info, self.loop):
            g.add_edge(index[int(i)], index[int(j)], z, info, loop=bool(lp))
        return g


def format_g2o(graph: PoseGraph, active_only: bool = True) -> str:
    """The text of ``graph`` in g2o format (vertex 0 fixed); inactive edges (switched-off loops)
    are left out unless ``active_only`` is False."""
    lines = []
    for k, p in enumerate(graph.poses):
        lines.append(f"VERTEX_SE2 {k} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}")
    if graph.n_nodes:
        lines.append("FIX 0")
    for e in graph.edges:
        if active_only and not e.active:
            continue
        if e.loop:
            lines.append(f"# LOOP {e.i} {e.j}")
        info = " ".join(f"{e.info[a, b]:.6g}" for a, b in _UPPER)
        lines.append(f"EDGE_SE2 {e.i} {e.j} {e.z[0]:.6f} {e.z[1]:.6f} {e.z[2]:.6f} {info}")
    return "\n".join(lines) + "\n"


def write_g2o(path: str | os.PathLike[str], graph: PoseGraph, active_only: bool = True) -> Path:
    """Write ``graph`` to ``path`` (atomically); return the path."""
    return write_text_atomic(Path(path), format_g2o(graph, active_only))


def read_g2o(path: str | os.PathLike[str]) -> G2oGraph:
    """Read VERTEX_SE2 / EDGE_SE2 / FIX records (other record types are refused).

    Raises:
        DynSlamError: naming the file and line of a malformed record, an edge to an unknown
            vertex, or a file without vertices.
    """
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise DynSlamError(f"{p}: cannot read the g2o file ({exc.strerror or exc})") from None
    ids: list[int] = []
    poses: list[list[float]] = []
    edges: list[tuple[int, int]] = []
    zs: list[list[float]] = []
    infos: list[np.ndarray] = []
    loops: list[bool] = []
    fixed: list[int] = []
    pending_loop: tuple[int, int] | None = None
    for n, raw in enumerate(text.splitlines(), start=1):
        f = raw.split()
        if not f:
            continue
        try:
            if f[0] == "#":
                if len(f) == 4 and f[1] == "LOOP":
                    pending_loop = (int(f[2]), int(f[3]))
                continue
            if f[0].startswith("#"):
                continue
            if f[0] == "VERTEX_SE2" and len(f) == 5:
                ids.append(int(f[1]))
                poses.append([float(v) for v in f[2:5]])
            elif f[0] == "EDGE_SE2" and len(f) == 12:
                i, j = int(f[1]), int(f[2])
                vals = [float(v) for v in f[3:]]
                info = np.zeros((3, 3))
                for (a, b), v in zip(_UPPER, vals[3:]):
                    info[a, b] = info[b, a] = v
                edges.append((i, j))
                zs.append(vals[:3])
                infos.append(info)
                loops.append(pending_loop == (i, j))
                pending_loop = None
            elif f[0] == "FIX" and len(f) >= 2:
                fixed.extend(int(v) for v in f[1:])
            else:
                raise DynSlamError(f"{p}:{n}: not a VERTEX_SE2 (5 fields), EDGE_SE2 (12 fields) or FIX record: "
                                   f"{raw[:60]!r}")
        except ValueError:
            raise DynSlamError(f"{p}:{n}: non-numeric field in {f[0]} record") from None
    if not ids:
        raise DynSlamError(f"{p}: no VERTEX_SE2 records")
    known = set(ids)
    for (i, j) in edges:
        if i not in known or j not in known:
            raise DynSlamError(f"{p}: EDGE_SE2 {i} {j} refers to a vertex that is not in the file")
    a = np.asarray(poses, dtype=np.float64)
    if not np.all(np.isfinite(a)) or any(not math.isfinite(v) for z in zs for v in z):
        raise DynSlamError(f"{p}: non-finite pose or measurement")
    return G2oGraph(np.asarray(ids, dtype=np.int64), a, np.asarray(edges, dtype=np.int64).reshape(-1, 2),
                    np.asarray(zs, dtype=np.float64).reshape(-1, 3), np.asarray(infos).reshape(-1, 3, 3),
                    np.asarray(loops, dtype=bool), fixed)
