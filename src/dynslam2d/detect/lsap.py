"""``linear_sum_assignment`` (the Hungarian / shortest-augmenting-path solver of Crouse, IEEE TAES 2016)
without importing all of ``scipy.optimize``.

SciPy's public function *is* its compiled ``scipy.optimize._lsap`` extension's function, but importing
it through ``scipy.optimize`` loads the whole optimization package (linalg, sparse, linprog, …):
about 1.2 s and 50 MiB of a run's baseline for one solver (issue 13 item 3). This module loads that
one extension from SciPy's installed files; when SciPy's layout differs (another version), it falls
back to the public import, so the solver is always SciPy's.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def _load() -> Callable[..., tuple[np.ndarray, np.ndarray]]:
    try:
        import importlib.machinery
        import importlib.util
        from pathlib import Path

        import scipy

        folder = Path(scipy.__file__).parent / "optimize"
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = folder / f"_lsap{suffix}"
            if path.is_file():
                loader = importlib.machinery.ExtensionFileLoader("scipy.optimize._lsap", str(path))
                spec = importlib.util.spec_from_file_location("scipy.optimize._lsap", str(path), loader=loader)
                if spec is None:
                    break
                module = importlib.util.module_from_spec(spec)
                loader.exec_module(module)
                return module.linear_sum_assignment  # type: ignore[no-any-return]
    except Exception:  # any surprise in SciPy's layout: the public import below
        pass
    from scipy.optimize import linear_sum_assignment as public

    return public  # type: ignore[no-any-return]


#: ``scipy.optimize.linear_sum_assignment(cost, maximize=False) -> (row_ind, col_ind)``.
linear_sum_assignment = _load()

__all__ = ["linear_sum_assignment"]
