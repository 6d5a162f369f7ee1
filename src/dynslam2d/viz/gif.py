"""A streaming animated-GIF writer with one fixed palette (bounded memory).

Frames are quantised to a fixed 256-colour palette that holds the exact colours of
:mod:`dynslam2d.viz.style`, their blends with white, 48 greys and a colour cube, then
LZW-encoded by Pillow (``GifImagePlugin.getdata``) and appended to an anonymous temporary
file. Only the encoded frames are kept (on disk), never the decoded images, so a long
animation costs no memory. :meth:`GifStream.close` writes the final file atomically.
"""

from __future__ import annotations

import os
import shutil
import struct
import tempfile
from pathlib import Path

import numpy as np

from dynslam2d.io.atomic import atomic_path
from dynslam2d.viz import style

_NAMED = (style.TRAJECTORY, style.GROUND_TRUTH, style.REMOVED, style.KEPT, style.TRACK_M, style.TRACK_OTHER,
          style.GHOST, style.MISSED, style.TRUTH_OUTLINE, style.UNKNOWN)


def fixed_palette() -> np.ndarray:
    """(256, 3) uint8 palette: named style colours (exact), their blends with white
    (25 / 50 / 75 %), 48 greys, a 5×5×5 colour cube; padded with black."""
    cols: list[tuple[int, int, int]] = []
    for c in _NAMED:
        rgb = np.array(style.rgb255(c), dtype=float)
        cols.append(tuple(int(v) for v in rgb))  # type: ignore[arg-type]
        for a in (0.25, 0.5, 0.75):
            cols.append(tuple(round(v) for v in rgb * (1 - a) + 255 * a))  # type: ignore[arg-type]
    for g in np.linspace(0, 255, 48):
        cols.append((round(g),) * 3)  # type: ignore[arg-type]
    lv = np.linspace(0, 255, 5).round().astype(int)
    for r in lv:
        for g in lv:
            for b in lv:
                cols.append((int(r), int(g), int(b)))
    out: list[tuple[int, int, int]] = []
    seen: set[tuple[int, int, int]] = set()
    for c in cols:
        if c not in seen:
            seen.add(c)
            out.append(c)
    if len(out) > 256:
        raise AssertionError("palette overflow")  # cannot happen with the lists above
    out += [(0, 0, 0)] * (256 - len(out))
    return np.array(out, dtype=np.uint8)


class GifStream:
    """Append RGB frames, then :meth:`close` to write an endlessly looping GIF at ``path``.

    Args:
        path: final file (written atomically at :meth:`close`).
        duration_ms: display time of every frame, ms (GIF stores centiseconds).
    """

    def __init__(self, path: str | os.PathLike[str], duration_ms: int = 100) -> None:
        self.path = Path(path)
        self.duration_ms = int(duration_ms)
        self.n_frames = 0
        self.size: tuple[int, int] | None = None
        self._palette = fixed_palette()
        self._tmp = tempfile.TemporaryFile()  # noqa: SIM115 - lives until close()

    def add(self, rgb: np.ndarray) -> None:
        """Append one (H, W, 3) uint8 frame (every frame must have the size of the first)."""
        from PIL import GifImagePlugin, Image

        rgb = np.ascontiguousarray(rgb[..., :3], dtype=np.uint8)
        size = (rgb.shape[1], rgb.shape[0])
        if self.size is None:
            self.size = size
        elif size != self.size:
            raise ValueError(f"GIF frame size {size} differs from the first frame's {self.size}")
        p = Image.fromarray(self.indices(rgb), "P")
        p.putpalette(self._palette.reshape(-1).tolist())
        for chunk in GifImagePlugin.getdata(p, duration=self.duration_ms):
            self._tmp.write(chunk)
        self.n_frames += 1

    def indices(self, rgb: np.ndarray) -> np.ndarray:
        """(H, W) uint8 index of the nearest palette colour (Euclidean in RGB) of every pixel."""
        key = (rgb[..., 0].astype(np.uint32) << 16) | (rgb[..., 1].astype(np.uint32) << 8) | rgb[..., 2]
        uniq, inv = np.unique(key.ravel(), return_inverse=True)
        cols = np.stack([(uniq >> 16) & 255, (uniq >> 8) & 255, uniq & 255], axis=1).astype(np.int32)
        pal = self._palette.astype(np.int32)
        best = np.empty(len(cols), dtype=np.uint8)
        for i in range(0, len(cols), 4096):
            d = ((cols[i:i + 4096, None, :] - pal[None, :, :]) ** 2).sum(axis=2)
            best[i:i + 4096] = d.argmin(axis=1)
        return best[inv].reshape(rgb.shape[:2])

    def close(self) -> Path | None:
        """Write the GIF (header, global palette, loop forever, frames) atomically; None if no frame."""
        try:
            if self.n_frames == 0 or self.size is None:
                return None
            w, h = self.size
            header = (b"GIF89a" + struct.pack("<HH", w, h) + bytes((0xF7, 0, 0)) + self._palette.tobytes()
                      + b"!\xff\x0bNETSCAPE2.0\x03\x01" + struct.pack("<H", 0) + b"\x00")
            self._tmp.seek(0)
            with atomic_path(self.path) as tmp, tmp.open("wb") as fh:
                fh.write(header)
                shutil.copyfileobj(self._tmp, fh)
                fh.write(b";")
            return self.path
        finally:
            self._tmp.close()


__all__ = ["GifStream", "fixed_palette"]
