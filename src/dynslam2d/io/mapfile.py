"""Occupancy maps on disk in ROS map_server format (PGM image + YAML).

Conventions (ROS map_server; docs/architecture.md): pixel 254 = free, 0 = occupied, 205 =
unknown; image rows run top-down (row 0 = largest y), while :class:`GridMap`
rows run bottom-up, so reading and writing flip the rows. YAML keys: ``image``
(relative to the YAML), ``resolution`` (m/cell), ``origin`` ([x, y, yaw] of the
lower-left pixel corner; yaw must be 0 here), ``negate``, ``occupied_thresh``,
``free_thresh``, ``mode``.

map_server reads a pixel value v as occupancy p = (255 − v)/255 (negate = 0),
occupied if p > occupied_thresh, free if p < free_thresh.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import yaml

from dynslam2d.errors import DynSlamError
from dynslam2d.gridmap import GridMap
from dynslam2d.io.atomic import atomic_path, write_text_atomic
from dynslam2d.yamlfile import read_yaml_mapping

FREE_PIXEL = 254
OCCUPIED_PIXEL = 0
UNKNOWN_PIXEL = 205
DEFAULT_OCCUPIED_THRESH = 0.65
DEFAULT_FREE_THRESH = 0.196


def _pixels_trinary(grid: GridMap, occupied_thresh: float, free_thresh: float) -> np.ndarray:
    pix = np.full(grid.shape, UNKNOWN_PIXEL, dtype=np.uint8)
    pix[grid.occupied(occupied_thresh)] = OCCUPIED_PIXEL
    pix[grid.free(free_thresh)] = FREE_PIXEL
    return pix


def _pixels_scale(grid: GridMap) -> np.ndarray:
    # map_server "scale": p = (255 - v)/255, so v = 255·(1 - p); unknown stays 205.
    p = np.clip(np.nan_to_num(grid.prob, nan=-1.0), -1.0, 1.0)
    pix = np.rint(255.0 * (1.0 - p)).astype(np.int64)
    pix[~grid.known()] = UNKNOWN_PIXEL
    return np.clip(pix, 0, 255).astype(np.uint8)


def encode_pgm(pixels: np.ndarray) -> bytes:
    """Binary PGM (P5, maxval 255) of a (H, W) uint8 image whose row 0 is the top."""
    h, w = pixels.shape
    return f"P5\n{w} {h}\n255\n".encode("ascii") + np.ascontiguousarray(pixels, dtype=np.uint8).tobytes()


def decode_pgm(data: bytes, origin: str = "<bytes>") -> np.ndarray:
    """Parse a binary (P5) or ASCII (P2) PGM with maxval ≤ 255 into a (H, W) uint8 array (row 0 = top)."""
    tokens: list[bytes] = []
    pos = 0
    n = len(data)
    while len(tokens) < 4:
        while pos < n and data[pos : pos + 1].isspace():
            pos += 1
        if pos < n and data[pos : pos + 1] == b"#":
            while pos < n and data[pos : pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < n and not data[pos : pos + 1].isspace():
            pos += 1
        if start == pos:
            raise DynSlamError(f"{origin}: truncated PGM header")
        tokens.append(data[start:pos])
    magic = tokens[0]
    try:
        w, h, maxval = (int(t) for t in tokens[1:4])
    except ValueError as exc:
        raise DynSlamError(f"{origin}: malformed PGM header {tokens!r}") from exc
    if magic not in (b"P5", b"P2"):
        raise DynSlamError(f"{origin}: not a PGM image (magic {magic!r}, expected P5 or P2)")
    if w <= 0 or h <= 0 or not 0 < maxval <= 255:
        raise DynSlamError(f"{origin}: unsupported PGM size {w}x{h} or maxval {maxval} (need 8-bit)")
    if magic == b"P5":
        body = data[pos + 1 : pos + 1 + w * h]
        if len(body) != w * h:
            raise DynSlamError(f"{origin}: PGM is truncated ({len(body)} of {w * h} pixel bytes)")
        pix = np.frombuffer(body, dtype=np.uint8).reshape(h, w)
    else:
        try:
            vals = np.array(data[pos:].split(), dtype=np.int64)
        except ValueError as exc:
            raise DynSlamError(f"{origin}: non-numeric pixel in ASCII PGM") from exc
        if vals.size != w * h:
            raise DynSlamError(f"{origin}: PGM has {vals.size} of {w * h} pixels")
        pix = vals.reshape(h, w).astype(np.uint8)
    if maxval != 255:
        pix = np.rint(pix.astype(np.float64) * 255.0 / maxval).astype(np.uint8)
    return pix.copy()


def write_map(
    yaml_path: str | os.PathLike[str],
    grid: GridMap,
    *,
    mode: str = "trinary",
    occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
    free_thresh: float = DEFAULT_FREE_THRESH,
) -> tuple[Path, Path]:
    """Write ``grid`` as ``<name>.pgm`` + ``<name>.yaml`` (map_server), atomically.

    Args:
        yaml_path: path of the YAML; the image gets the same stem with ``.pgm``.
        mode: ``"trinary"`` (0/205/254 by the thresholds, what map_server users expect)
            or ``"scale"`` (grey levels 255·(1−p), unknown 205; keeps probabilities to 1/255).
    Returns:
        (yaml path, pgm path).
    """
    yaml_path = Path(yaml_path)
    if yaml_path.suffix != ".yaml":
        yaml_path = yaml_path.with_suffix(".yaml")
    pgm_path = yaml_path.with_suffix(".pgm")
    if mode == "trinary":
        pix = _pixels_trinary(grid, occupied_thresh, free_thresh)
    elif mode == "scale":
        pix = _pixels_scale(grid)
    else:
        raise DynSlamError(f"unknown map mode {mode!r} (use 'trinary' or 'scale')")
    with atomic_path(pgm_path) as tmp:
        tmp.write_bytes(encode_pgm(pix[::-1]))  # GridMap row 0 = bottom; PGM row 0 = top
    meta = {
        "image": pgm_path.name,
        "mode": mode,
        "resolution": float(grid.resolution),
        "origin": [float(grid.origin[0]), float(grid.origin[1]), 0.0],
        "negate": 0,
        "occupied_thresh": float(occupied_thresh),
        "free_thresh": float(free_thresh),
    }
    write_text_atomic(yaml_path, yaml.safe_dump(meta, sort_keys=False))
    return yaml_path, pgm_path


def read_map(yaml_path: str | os.PathLike[str]) -> GridMap:
    """Read a map_server YAML + image into a :class:`GridMap`.

    Trinary maps (and any map read with mode ``trinary``) give 1.0 occupied, 0.0 free,
    NaN unknown; ``scale`` maps give p = (255 − v)/255 for known pixels (NaN for
    pixels between the thresholds that equal the unknown value 205).
    """
    yaml_path = Path(yaml_path)
    meta = read_yaml_mapping(yaml_path, "map YAML")
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise DynSlamError(f"{yaml_path}: map YAML lacks '{key}'")
    try:
        resolution = float(meta["resolution"])
        ox, oy, oyaw = (float(v) for v in list(meta["origin"])[:3])
        occ_t = float(meta.get("occupied_thresh", DEFAULT_OCCUPIED_THRESH))
        free_t = float(meta.get("free_thresh", DEFAULT_FREE_THRESH))
        negate = int(meta.get("negate", 0))
    except (TypeError, ValueError) as exc:
        raise DynSlamError(f"{yaml_path}: malformed resolution/origin/thresholds ({exc})") from exc
    if not resolution > 0:
        raise DynSlamError(f"{yaml_path}: resolution must be > 0, got {resolution}")
    if abs(oyaw) > 1e-9:
        raise DynSlamError(f"{yaml_path}: rotated map origins (yaw={oyaw}) are not supported")
    image = Path(str(meta["image"]))
    if not image.is_absolute():
        image = yaml_path.parent / image
    try:
        pix = decode_pgm(image.read_bytes(), origin=str(image))
    except FileNotFoundError as exc:
        raise DynSlamError(f"{yaml_path}: image {image} not found") from exc
    pix = pix[::-1].astype(np.float64)  # PGM row 0 = top → GridMap row 0 = bottom
    p = pix / 255.0 if negate else (255.0 - pix) / 255.0
    mode = str(meta.get("mode", "trinary"))
    if mode == "scale":
        prob = np.where(pix == UNKNOWN_PIXEL, np.nan, p)
    else:
        prob = np.full(p.shape, np.nan)
        prob[p > occ_t] = 1.0
        prob[p < free_t] = 0.0
    if not math.isfinite(ox) or not math.isfinite(oy):
        raise DynSlamError(f"{yaml_path}: origin is not finite")
    return GridMap(prob=prob, resolution=resolution, origin=(ox, oy))
