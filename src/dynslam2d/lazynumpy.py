"""NumPy's optional submodules registered as lazy modules in command-line processes (issue 13 item 3).

Any SciPy submodule a run imports (the pose graph's ``scipy.sparse``, the clean-up pass's ``scipy.ndimage``)
imports ``scipy._lib._array_api``, which copies NumPy's whole namespace (``array_api_compat``'s
``clone_module``: ``from numpy import *`` and ``getattr`` of every name ``dir(numpy)`` lists). NumPy loads its
submodules on first attribute access, so that copy imports ``numpy.f2py`` (with ``charset_normalizer`` and
about 90 text codecs), ``numpy.testing`` (with ``unittest``), ``numpy.polynomial``, ``numpy.ctypeslib`` and
the legacy ``numpy.core`` / ``rec`` / ``char`` / ``strings`` namespaces, none of which a run uses: ≈ 7 MiB of
a MIT CSAIL run's peak resident memory with the AOT kernels, ≈ 4 MiB with JIT ones (docs/speed.md, pass mem51).

:func:`defer_numpy_submodules` registers each of them, when not imported yet, as a module whose code runs at
its first attribute access (the standard library's :class:`importlib.util.LazyLoader`), and as NumPy's
attribute: the namespace copy then holds the unexecuted module objects. Any later use (``numpy.testing.
assert_equal``, ``import numpy.polynomial``, ``from numpy.f2py import ...``) executes the module as a normal
import would. The command line calls it first: it owns the process; a library user's process is left as it is.
"""

from __future__ import annotations

import sys

#: NumPy submodules that only ``dir(numpy)`` walkers import in a run (none of the run's own code uses them).
DEFERRED = ("f2py", "testing", "polynomial", "ctypeslib", "core", "rec", "char", "strings")


def defer_numpy_submodules() -> list[str]:
    """Register NumPy's :data:`DEFERRED` submodules that are not imported yet as lazy modules; returns their
    names. Does nothing when NumPy is not imported, and leaves a submodule to NumPy on any failure."""
    numpy = sys.modules.get("numpy")
    if numpy is None:
        return []
    import importlib.util

    done = []
    for name in DEFERRED:
        full = f"numpy.{name}"
        if full in sys.modules or name in vars(numpy):
            continue
        try:
            spec = importlib.util.find_spec(full)
            if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
                continue
            spec.loader = importlib.util.LazyLoader(spec.loader)
            mod = importlib.util.module_from_spec(spec)
            sys.modules[full] = mod
            spec.loader.exec_module(mod)  # defers: the module's code runs at its first attribute access
            setattr(numpy, name, mod)
        except Exception:  # noqa: BLE001 - an optimisation only: NumPy imports the module as usual
            sys.modules.pop(full, None)
            vars(numpy).pop(name, None)
            continue
        done.append(name)
    return done
