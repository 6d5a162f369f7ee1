"""SciPy's sparse LU factorisation and connected components without the packages around them, and SciPy's
``special`` left unexecuted until used in command-line processes (issue 13 item 3).

A run needs two functions of SciPy's sparse packages: the pose graph's ``scipy.sparse.linalg.splu`` (SuperLU,
Demmel et al., SIAM J. Matrix Anal. Appl. 20(3), 1999) and the loop closure's
``scipy.sparse.csgraph.connected_components``. Importing either through its package runs the package's
``__init__``: ``scipy.sparse.linalg`` imports its iterative solvers, ARPACK, PROPACK, the matrix functions and,
through them, the whole of ``scipy.linalg`` (≈ 8 MiB of resident memory), none of which a run calls, and
``scipy.sparse.csgraph`` imports its Laplacian, which imports ``scipy.sparse.linalg`` (≈ 12 MiB in all).
:func:`splu` calls SciPy's compiled ``_superlu.gstrf`` as ``splu`` does (the same arguments, so the same
factorisation and solves, bit for bit), and :data:`connected_components` *is* SciPy's compiled function; each
extension (and, for the graph, the two modules its initialisation imports) is loaded from SciPy's installed files
under its own name, without its package. When SciPy's layout differs (another version), both fall back to the
public imports, so the results are always SciPy's (the pattern of ``detect/lsap.py``).

:func:`defer_scipy_submodules` (the command line calls it first, beside ``lazynumpy``) makes ``scipy.special`` a
module whose code runs at its first attribute access (the standard library's :class:`importlib.util.LazyLoader`,
installed by a finder at the front of ``sys.meta_path``): the clean-up pass's and the figures' ``scipy.ndimage``
imports it (``from scipy import special``) for ``rotate`` only, ≈ 2.3 MiB.
"""

from __future__ import annotations

import functools
import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from types import ModuleType
from typing import Any

import numpy as np

#: SciPy modules a command-line run imports but never uses: executed at their first attribute access.
DEFERRED = ("scipy.special",)


def _load_alone(names: Sequence[str]) -> ModuleType:
    """Load SciPy's modules ``names`` (full dotted names, in order: each one's initialisation may import the ones
    before it) from SciPy's installed files, each registered in ``sys.modules`` under its name, without running
    the packages' ``__init__``; returns the last. A name already imported is reused. On any failure the modules
    registered here are removed again and the error raised."""
    import scipy

    root = scipy.__path__[0]
    added: list[str] = []
    try:
        module: ModuleType | None = None
        for name in names:
            if name in sys.modules:
                module = sys.modules[name]
                continue
            *pkg, leaf = name.split(".")[1:]
            folder = os.path.join(root, *pkg)
            spec = importlib.machinery.PathFinder.find_spec(leaf, [folder])
            if spec is None or spec.loader is None or spec.origin is None:
                raise ImportError(f"{name} not found in {folder}")
            loader_cls = (importlib.machinery.ExtensionFileLoader
                          if spec.origin.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES))
                          else importlib.machinery.SourceFileLoader)
            loader = loader_cls(name, spec.origin)
            spec = importlib.util.spec_from_file_location(name, spec.origin, loader=loader)
            if spec is None:
                raise ImportError(name)
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            added.append(name)
            loader.exec_module(module)
        if module is None:
            raise ImportError("no module named")
        return module
    except BaseException:
        for name in added:
            sys.modules.pop(name, None)
        raise


def _superlu() -> tuple[Callable[..., Any], Callable[..., Any]] | None:
    """SciPy's ``_superlu.gstrf`` and ``safely_cast_index_arrays`` (None: SciPy's layout differs, use ``splu``)."""
    try:
        from scipy.sparse import csc_array
        from scipy.sparse._sputils import safely_cast_index_arrays

        if not hasattr(csc_array, "_asfptype"):
            return None
        return _load_alone(("scipy.sparse.linalg._dsolve._superlu",)).gstrf, safely_cast_index_arrays
    except Exception:  # noqa: BLE001 - any surprise in SciPy's layout: the public splu
        return None


def _connected_components() -> Callable[..., tuple[int, np.ndarray]]:
    try:
        return _load_alone(("scipy.sparse.csgraph._tools", "scipy.sparse.csgraph._validation",  # type: ignore[no-any-return]
                            "scipy.sparse.csgraph._traversal")).connected_components
    except Exception:  # noqa: BLE001 - any surprise in SciPy's layout: the public import
        from scipy.sparse.csgraph import connected_components as public

        return public  # type: ignore[no-any-return]


@functools.cache
def _loaded(what: str) -> Any:
    """The compiled parts, loaded at the first call that needs them."""
    return _superlu() if what == "superlu" else _connected_components()


def splu(a: Any, permc_spec: str | None = None, diag_pivot_thresh: float | None = None,
         options: dict[str, Any] | None = None) -> Any:
    """``scipy.sparse.linalg.splu(a, permc_spec=..., diag_pivot_thresh=..., options=...)`` for a square sparse
    matrix ``a`` (CSC; other formats are converted as SciPy does): SciPy's ``SuperLU`` object. The body is
    SciPy 1.17's ``splu`` without its pydata branch (``scipy/sparse/linalg/_dsolve/linsolve.py``)."""
    parts = _loaded("superlu")
    if parts is None:
        from scipy.sparse.linalg import splu as public

        return public(a, permc_spec=permc_spec, diag_pivot_thresh=diag_pivot_thresh, options=options)
    gstrf, safely_cast_index_arrays = parts
    from scipy.sparse import SparseEfficiencyWarning, csc_array, issparse

    if not (issparse(a) and a.format == "csc"):
        a = csc_array(a)
        warnings.warn("splu converted its input to CSC format", SparseEfficiencyWarning, stacklevel=2)
    a.sum_duplicates()
    a = a._asfptype()
    m, n = a.shape
    if m != n:
        raise ValueError("can only factor square matrices")
    indices, indptr = safely_cast_index_arrays(a, np.intc, "SuperLU")
    opts: dict[str, Any] = dict(DiagPivotThresh=diag_pivot_thresh, ColPerm=permc_spec, PanelSize=None, Relax=None)
    if options is not None:
        opts.update(options)
    if opts["ColPerm"] == "NATURAL":
        opts["SymmetricMode"] = True
    return gstrf(n, a.nnz, a.data, indices, indptr, csc_construct_func=csc_array, ilu=False, options=opts)


def connected_components(*args: Any, **kwargs: Any) -> tuple[int, np.ndarray]:
    """``scipy.sparse.csgraph.connected_components(csgraph, directed=True, connection='weak',
    return_labels=True)``: SciPy's compiled function (loaded at the first call)."""
    return _loaded("components")(*args, **kwargs)  # type: ignore[no-any-return]


class _LazyFinder(importlib.abc.MetaPathFinder):
    """Finds the :data:`DEFERRED` modules with the other finders and wraps their loaders in a ``LazyLoader``."""

    def find_spec(self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None) -> Any:
        if fullname not in DEFERRED:
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None:
                if spec.loader is not None and hasattr(spec.loader, "exec_module"):
                    spec.loader = importlib.util.LazyLoader(spec.loader)
                return spec
        return None


def defer_scipy_submodules() -> bool:
    """Have the :data:`DEFERRED` modules, when imported later, executed at their first attribute access (a finder
    at the front of ``sys.meta_path``); False when one is imported already or the finder is installed."""
    if any(name in sys.modules for name in DEFERRED) or any(isinstance(f, _LazyFinder) for f in sys.meta_path):
        return False
    sys.meta_path.insert(0, _LazyFinder())
    return True
