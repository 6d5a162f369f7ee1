"""Saving figures: PNG, atomically, and the figure's memory released."""

from __future__ import annotations

import os
from pathlib import Path

from dynslam2d.io.atomic import atomic_path


def save_png(fig: object, path: str | os.PathLike[str], dpi: int = 120) -> Path:
    """Write matplotlib figure ``fig`` as a PNG at ``path`` (atomically) and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")  # type: ignore[attr-defined]
    plt.close(fig)  # type: ignore[arg-type]
    return path
