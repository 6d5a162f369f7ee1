"""Sparse 2D pose-graph optimisation (docs/slam.md, "Loop closure").

Nodes are laser poses x_i = (x, y, θ) in the map frame (m, rad). An edge (i, j, z, Ω) says
that x_j seen from x_i is z = x_i⁻¹ ⊕ x_j, with information Ω (3×3, inverse covariance in
m⁻², m⁻¹rad⁻¹, rad⁻²). The error of an edge is the one of sparse pose adjustment
(Konolige et al., "Efficient Sparse Pose Adjustment for 2D Mapping", IROS 2010, Eq. 3):

    e_t = R_zᵀ (R_iᵀ (t_j − t_i) − t_z),   e_θ = wrap(θ_j − θ_i − θ_z)

and the cost Σ eᵀΩe is minimised by Gauss–Newton with Levenberg–Marquardt damping on the
sparse normal equations (scipy.sparse, SuperLU). Node 0 is held fixed (gauge).

Loop edges can be made robust: each iteration re-weights them (iteratively re-weighted
least squares) with

* ``dcs`` — dynamic covariance scaling, Agarwal et al., "Robust Map Optimization using
  Dynamic Covariance Scaling", ICRA 2013: Ω ← s²Ω with s = min(1, 2Φ/(Φ + χ²)), the
  closed form of switchable constraints (Sünderhauf & Protzel, IROS 2012);
* ``cauchy`` — ρ(χ²) = c² log(1 + χ²/c²), weight 1/(1 + χ²/c²);
* ``none`` — plain least squares.

After convergence, loop edges whose χ² = eᵀΩe exceeds ``outlier_chi2`` are switched off and
the graph is optimised again: a wrong loop that the kernel only weakened is removed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dynslam2d.types import wrap_angle

KERNELS = ("dcs", "cauchy", "none")


@dataclass(slots=True)
class Edge:
    """One relative-pose constraint: x_j = x_i ⊕ z (m, rad), information ``info`` (3×3).

    ``loop``: a loop closure (robust kernel applies); ``robust``: the robust kernel applies although it is no
    loop (an odometry-like edge across a weak match, which may be a break of the front end); ``active``: taken
    into account.
    ``weight``: the robust weight of the last optimisation (1 for odometry-like edges).
    """

    i: int
    j: int
    z: np.ndarray
    info: np.ndarray
    loop: bool = False
    active: bool = True
    weight: float = 1.0
    robust: bool = False


@dataclass(slots=True)
class OptimiseReport:
    """What :meth:`PoseGraph.optimise` did: iterations, costs before/after, loops switched off."""

    iterations: int = 0
    cost_start: float = 0.0
    cost_end: float = 0.0
    rejected_loops: list[int] = field(default_factory=list)


def _edge_errors(poses: np.ndarray, ii: np.ndarray, jj: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, ...]:
    """Errors (m, 3) and the pieces of their Jacobians for edges ii → jj (SPA, Konolige 2010)."""
    pi = poses[ii]
    pj = poses[jj]
    ci, si = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    cz, sz = np.cos(z[:, 2]), np.sin(z[:, 2])
    dx = pj[:, 0] - pi[:, 0]
    dy = pj[:, 1] - pi[:, 1]
    # R_iᵀ Δt
    lx = ci * dx + si * dy
    ly = -si * dx + ci * dy
    ux, uy = lx - z[:, 0], ly - z[:, 1]
    e = np.empty((ii.shape[0], 3))
    e[:, 0] = cz * ux + sz * uy
    e[:, 1] = -sz * ux + cz * uy
    e[:, 2] = wrap_angle(pj[:, 2] - pi[:, 2] - z[:, 2])
    # A = R_zᵀ R_iᵀ (2×2 per edge) = rotation by −(θ_i + θ_z)
    ca, sa = np.cos(pi[:, 2] + z[:, 2]), np.sin(pi[:, 2] + z[:, 2])
    # ∂(R_iᵀΔt)/∂θ_i = (ly, −lx); rotated by R_zᵀ
    dth_x = cz * ly + sz * (-lx)
    dth_y = -sz * ly + cz * (-lx)
    return e, ca, sa, dth_x, dth_y


def _edge(i: int, j: int, z: object, info: np.ndarray, loop: bool, robust: bool) -> Edge:
    """The :class:`Edge` x_j = x_i ⊕ z: ``z`` copied as (3,) float64, ``info`` (3×3) symmetrised."""
    info = np.asarray(info, dtype=np.float64).reshape(3, 3)
    return Edge(i, j, np.array(z, dtype=np.float64).reshape(3), 0.5 * (info + info.T), loop, robust=robust)


class PoseGraph:
    """Nodes (poses) and edges; :meth:`optimise` moves the nodes.

    >>> g = PoseGraph(); a = g.add_node((0, 0, 0)); b = g.add_node((1, 0, 0))
    >>> g.add_edge(a, b, (1.0, 0.0, 0.0), np.eye(3))
    0
    """

    def __init__(self) -> None:
        self._p = np.zeros((16, 3))  # capacity grows by doubling; rows [:_n] are the nodes
        self._n = 0
        self._edges: list[Edge] = []
        #: edges given by :meth:`add_diag_edge` and not built yet, after those of ``_edges``
        self._pending: list[tuple[int, int, object, float, float, bool]] = []
        #: during :meth:`optimise`: every edge's (i, j, z, info) arrays (the edges do not change inside it)
        self._all: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    # ---- building -----------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        return self._n

    @property
    def edges(self) -> list[Edge]:
        """The edges in the order they were added (those of :meth:`add_diag_edge` built at the first read)."""
        if self._pending:
            self._build_pending()
        return self._edges

    def _build_pending(self) -> None:
        for i, j, z, sxy, sth, robust in self._pending:
            self._edges.append(_edge(i, j, z, diag_info(sxy, sth), False, robust))
        self._pending = []

    @property
    def poses(self) -> np.ndarray:
        """(n, 3) current node poses (x m, y m, θ rad); a view, do not write into it."""
        return self._p[: self._n]

    def pose(self, node: int) -> np.ndarray:
        """(3,) copy of one node's pose (x m, y m, θ rad)."""
        return self._p[node].copy()

    def set_poses(self, poses: np.ndarray) -> None:
        """Replace every node pose ((n, 3), m / rad)."""
        p = np.asarray(poses, dtype=np.float64)
        if p.shape != (self.n_nodes, 3):
            raise ValueError(f"set_poses: expected shape {(self.n_nodes, 3)}, got {p.shape}")
        self._p[: self._n] = p

    def add_node(self, pose: tuple[float, float, float] | np.ndarray) -> int:
        """Append a node at ``pose`` (x m, y m, θ rad); returns its id."""
        if self._n == self._p.shape[0]:
            self._p = np.vstack((self._p, np.zeros_like(self._p)))
        self._p[self._n] = np.asarray(pose, dtype=np.float64).reshape(3)
        self._n += 1
        return self._n - 1

    def add_edge(self, i: int, j: int, z: tuple[float, float, float] | np.ndarray, info: np.ndarray,
                 loop: bool = False, robust: bool = False) -> int:
        """Append the constraint x_j = x_i ⊕ z with information ``info`` (3×3); returns its index."""
        n = self._n
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise ValueError(f"add_edge: bad node ids {i}, {j} (graph has {n} nodes)")
        edges = self.edges
        edges.append(_edge(int(i), int(j), z, info, bool(loop), bool(robust)))
        return len(edges) - 1

    def add_diag_edge(self, i: int, j: int, z: tuple[float, float, float] | list[float] | np.ndarray,
                      sigma_xy: float, sigma_theta: float, robust: bool = False) -> int:
        """``add_edge(i, j, z, diag_info(sigma_xy, sigma_theta), robust=robust)`` (no loop edge), its :class:`Edge`
        built when :attr:`edges` is next read (the same edge, at the same index; ``z`` must not change until then):
        the loop closer adds one per keyframe and reads the edges only to optimise. Returns its index."""
        n = self._n
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise ValueError(f"add_diag_edge: bad node ids {i}, {j} (graph has {n} nodes)")
        self._pending.append((int(i), int(j), z, sigma_xy, sigma_theta, bool(robust)))
        return len(self._edges) + len(self._pending) - 1

    # ---- evaluation ---------------------------------------------------------------------
    def chi2(self, poses: np.ndarray | None = None) -> np.ndarray:
        """(m,) eᵀΩe of every edge at ``poses`` (default: the current ones), inactive edges included."""
        p = self.poses if poses is None else poses
        if not self.edges:
            return np.zeros(0)
        ii, jj, z, info = self._all if self._all is not None else self._arrays(list(range(len(self.edges))))
        e = _edge_errors(p, ii, jj, z)[0]
        return np.einsum("ni,nij,nj->n", e, info, e)

    def _arrays(self, idx: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        edges = self.edges
        ed = [edges[k] for k in idx]
        ii = np.array([e.i for e in ed], dtype=np.int64)
        jj = np.array([e.j for e in ed], dtype=np.int64)
        z = np.array([e.z for e in ed], dtype=np.float64).reshape(-1, 3)
        info = np.array([e.info for e in ed], dtype=np.float64).reshape(-1, 3, 3)
        return ii, jj, z, info

    # ---- optimisation -------------------------------------------------------------------
    def optimise(self, kernel: str = "dcs", kernel_scale: float = 1.0, iterations: int = 30,
                 outlier_chi2: float | None = None, tol: float = 1e-6) -> OptimiseReport:
        """Minimise the (robust) cost over every node but node 0; switch off loop edges whose χ²
        after convergence exceeds ``outlier_chi2`` and optimise again (until none does).

        ``kernel``: "dcs", "cauchy" or "none" (module docstring); ``kernel_scale``: Φ for dcs,
        c for cauchy (χ units). ``tol``: stop when the relative cost decrease is below it.
        """
        if kernel not in KERNELS:
            raise ValueError(f"optimise: kernel must be one of {KERNELS}, got {kernel!r}")
        rep = OptimiseReport()
        if self.n_nodes < 2 or not self.edges:
            return rep
        # every edge's arrays once for the whole call (chi2 and each solve select rows of them: the same values as
        # building them from the edges each time)
        self._all = self._arrays(list(range(len(self.edges))))
        try:
            self._optimise(rep, kernel, kernel_scale, iterations, outlier_chi2, tol)
        finally:
            self._all = None
        return rep

    def _optimise(self, rep: OptimiseReport, kernel: str, kernel_scale: float, iterations: int,
                  outlier_chi2: float | None, tol: float) -> None:
        """:meth:`optimise`'s rounds (``rep`` filled in)."""
        for _round in range(10):
            # graduated non-convexity (Yang et al., RA-L 2020): start with a kernel so wide that every loop
            # counts, then narrow it; a kernel at its final width from the start would ignore the true loops
            # too while the drift they correct is still in the poses
            chi = self.chi2()
            edges = self.edges
            loop_chi = [chi[k] for k, e in enumerate(edges) if e.loop and e.active]
            # after pruning, the poses are already near the solution: no need to widen again
            wide = max(loop_chi) if loop_chi and kernel != "none" and _round == 0 else kernel_scale
            scale = max(wide if kernel == "dcs" else float(np.sqrt(wide)), kernel_scale)
            first = True
            while True:
                last = scale <= kernel_scale
                # intermediate widths only need to move the poses into the next width's basin
                it, c0, c1 = self._solve(kernel, scale, iterations if last else max(iterations // 3, 1),
                                         tol if last else max(tol, 1e-3))
                if _round == 0 and first:
                    rep.cost_start = c0
                first = False
                rep.iterations += it
                rep.cost_end = c1
                if scale <= kernel_scale:
                    break
                scale = max(scale / 8.0, kernel_scale)
            if outlier_chi2 is None:
                break
            chi = self.chi2()
            edges = self.edges
            bad = [k for k, e in enumerate(edges) if e.loop and e.active and chi[k] > outlier_chi2]
            if not bad:
                break
            for k in bad:
                self.edges[k].active = False
                self.edges[k].weight = 0.0
                rep.rejected_loops.append(k)

    def _weights(self, chi: np.ndarray, loop: np.ndarray, kernel: str, scale: float) -> np.ndarray:
        w = np.ones_like(chi)
        if kernel == "dcs":
            s = np.minimum(1.0, 2.0 * scale / (scale + chi))
            w = np.where(loop, s * s, 1.0)
        elif kernel == "cauchy":
            w = np.where(loop, 1.0 / (1.0 + chi / (scale * scale)), 1.0)
        return w

    def _cost(self, chi: np.ndarray, loop: np.ndarray, kernel: str, scale: float) -> float:
        if kernel == "cauchy":
            c2 = scale * scale
            return float(np.sum(np.where(loop, c2 * np.log1p(chi / c2), chi)))
        if kernel == "dcs":
            # DCS is the IRLS form of switchable constraints; its cost: s²χ² + Φ(1 − s)²
            s = np.minimum(1.0, 2.0 * scale / (scale + chi))
            return float(np.sum(np.where(loop, s * s * chi + scale * (1.0 - s) ** 2, chi)))
        return float(np.sum(chi))

    def _solve(self, kernel: str, scale: float, iterations: int, tol: float) -> tuple[int, float, float]:
        edges = self.edges
        idx = [k for k, e in enumerate(edges) if e.active]
        if not idx:
            return 0, 0.0, 0.0
        # imported here, not with the module: scipy.sparse(.linalg) costs ~1 s and tens of MiB at start-up,
        # and only a run that optimises a graph needs it (docs/speed.md)
        import scipy.sparse as sp

        from dynslam2d.lazyscipy import splu

        if self._all is not None:
            sel = np.array(idx, dtype=np.int64)
            ii, jj, z, info = (a[sel] for a in self._all)
        else:
            ii, jj, z, info = self._arrays(idx)
        # the edges under the robust kernel: loops, and edges marked robust
        loop = np.array([edges[k].loop or edges[k].robust for k in idx], dtype=bool)
        poses = self.poses.copy()
        n = self.n_nodes

        def evaluate(p: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
            parts = _edge_errors(p, ii, jj, z)
            e = parts[0]
            return np.einsum("ni,nij,nj->n", e, info, e), parts

        chi, parts = evaluate(poses)
        cost = self._cost(chi, loop, kernel, scale)
        cost0 = cost
        lam = 1e-4
        it = 0
        m = ii.shape[0]
        # the sparsity pattern of H and b: the same every iteration (the edges do not change inside a solve)
        r3 = np.arange(3)
        rows_blk = np.concatenate([(3 * ii)[:, None, None] + r3[None, :, None] + 0 * r3[None, None, :],
                                   (3 * jj)[:, None, None] + r3[None, :, None] + 0 * r3[None, None, :],
                                   (3 * ii)[:, None, None] + r3[None, :, None] + 0 * r3[None, None, :],
                                   (3 * jj)[:, None, None] + r3[None, :, None] + 0 * r3[None, None, :]]).ravel()
        cols_blk = np.concatenate([(3 * ii)[:, None, None] + 0 * r3[None, :, None] + r3[None, None, :],
                                   (3 * jj)[:, None, None] + 0 * r3[None, :, None] + r3[None, None, :],
                                   (3 * jj)[:, None, None] + 0 * r3[None, :, None] + r3[None, None, :],
                                   (3 * ii)[:, None, None] + 0 * r3[None, :, None] + r3[None, None, :]]).ravel()
        b_i = (3 * ii)[:, None] + r3[None, :]
        b_j = (3 * jj)[:, None] + r3[None, :]
        for it in range(1, iterations + 1):  # noqa: B007 (the count is returned after the loop)
            e, ca, sa, dth_x, dth_y = parts
            w = self._weights(chi, loop, kernel, scale)
            # Jacobian blocks: J_i (3×3), J_j (3×3) per edge
            Ji = np.zeros((m, 3, 3))
            Jj = np.zeros((m, 3, 3))
            # A = R_zᵀR_iᵀ: [[ca, sa], [−sa, ca]]
            Ji[:, 0, 0], Ji[:, 0, 1] = -ca, -sa
            Ji[:, 1, 0], Ji[:, 1, 1] = sa, -ca
            Ji[:, 0, 2], Ji[:, 1, 2], Ji[:, 2, 2] = dth_x, dth_y, -1.0
            Jj[:, 0, 0], Jj[:, 0, 1] = ca, sa
            Jj[:, 1, 0], Jj[:, 1, 1] = -sa, ca
            Jj[:, 2, 2] = 1.0
            W = info * w[:, None, None]
            WJi = W @ Ji
            WJj = W @ Jj
            Hii = np.transpose(Ji, (0, 2, 1)) @ WJi
            Hjj = np.transpose(Jj, (0, 2, 1)) @ WJj
            Hij = np.transpose(Ji, (0, 2, 1)) @ WJj
            bi = np.einsum("nki,nk->ni", WJi, e)
            bj = np.einsum("nki,nk->ni", WJj, e)
            vals = np.concatenate([Hii, Hjj, Hij, np.transpose(Hij, (0, 2, 1))])
            H = sp.coo_matrix((vals.ravel(), (rows_blk, cols_blk)), shape=(3 * n, 3 * n)).tocsc()
            b = np.zeros(3 * n)
            np.add.at(b, b_i, bi)
            np.add.at(b, b_j, bj)
            # gauge: node 0 fixed
            H = H[3:, 3:]
            b = b[3:]
            diag = H.diagonal()
            improved = False
            for _ in range(8):
                A = _damped(H, lam * np.maximum(diag, 1e-9) + 1e-12, sp)  # = H + sp.diags(…), the same matrix
                try:
                    # symmetric positive definite: a symmetric fill-reducing ordering, no pivoting
                    dx = -splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                               options={"SymmetricMode": True}).solve(b)
                except RuntimeError:
                    lam *= 10.0
                    continue
                trial = poses.copy()
                trial[1:] += dx.reshape(-1, 3)
                trial[:, 2] = wrap_angle(trial[:, 2])
                chi_t, parts_t = evaluate(trial)
                cost_t = self._cost(chi_t, loop, kernel, scale)
                if cost_t <= cost:
                    improved = True
                    rel = (cost - cost_t) / max(cost, 1e-300)
                    poses, chi, parts, cost = trial, chi_t, parts_t, cost_t
                    lam = max(lam / 10.0, 1e-9)
                    break
                lam *= 10.0
            if not improved or rel < tol:
                break
        w = self._weights(chi, loop, kernel, scale)
        for k, wk in zip(idx, w.tolist()):
            edges[k].weight = wk
        self.set_poses(poses)
        return it, cost0, cost


def _damped(h: object, damp: np.ndarray, sp: object) -> object:
    """``h + sp.diags(damp)`` for a square CSC matrix ``h`` in canonical form (sorted indices, no duplicates) whose
    diagonal entries are all stored, and ``damp`` > 0: the same matrix (structure, order and values) without
    SciPy's general sparse sum. SciPy's sum of two canonical matrices merges each column's sorted entries, adds
    the two values where both have one (h_ii + d_i: one rounding either way), keeps ``h``'s value elsewhere
    (x + 0) and drops every entry whose sum is zero — here ``h``'s stored zeros off the diagonal (the Jacobians'
    structural zeros give some). Any other ``h`` goes through SciPy's sum."""
    n = h.shape[0]
    if h.shape[0] != h.shape[1] or not h.has_canonical_format:
        return h + sp.diags(damp)
    indptr = h.indptr
    cols = np.repeat(np.arange(n, dtype=indptr.dtype), np.diff(indptr))
    on_diag = h.indices == cols
    if int(np.count_nonzero(on_diag)) != n:
        return h + sp.diags(damp)
    data = h.data.copy()
    data[on_diag] += damp
    keep = data != 0.0
    if keep.all():
        return sp.csc_matrix((data, h.indices.copy(), indptr.copy()), shape=h.shape)
    counts = np.bincount(cols[keep], minlength=n)
    ptr = np.zeros(n + 1, dtype=indptr.dtype)
    np.cumsum(counts, out=ptr[1:])
    return sp.csc_matrix((data[keep], h.indices[keep], ptr), shape=h.shape)


def relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a⁻¹ ⊕ b for poses (…, 3) (x m, y m, θ rad)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim == 1 and b.ndim == 1:  # one pose each (every keyframe): the same operations on scalars, no stack
        c, s = np.cos(a[2]), np.sin(a[2])
        dx, dy = b[0] - a[0], b[1] - a[1]
        return np.array([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[2] - a[2])])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack((c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])), axis=-1)


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊕ b for poses (…, 3) (x m, y m, θ rad)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim == 1 and b.ndim == 1:  # one pose each: as relative
        c, s = np.cos(a[2]), np.sin(a[2])
        return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_angle(a[2] + b[2])])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack((a[..., 0] + c * b[..., 0] - s * b[..., 1], a[..., 1] + s * b[..., 0] + c * b[..., 1],
                     wrap_angle(a[..., 2] + b[..., 2])), axis=-1)


def diag_info(sigma_xy: float, sigma_theta: float) -> np.ndarray:
    """Information matrix diag(1/σ_xy², 1/σ_xy², 1/σ_θ²) (m, rad)."""
    m = np.zeros((3, 3))
    m[0, 0] = m[1, 1] = 1.0 / sigma_xy**2
    m[2, 2] = 1.0 / sigma_theta**2
    return m


__all__ = ["Edge", "KERNELS", "OptimiseReport", "PoseGraph", "compose", "diag_info", "relative"]
