"""Resident pages of the SLAM map levels, row-major (as stored) against 2-D tiled layouts (issue 13 item 3, a study).

A level's three per-cell arrays (float32 log-odds, uint32 probability words with 0 = 0.5, int32 update indices with
0 = never updated; ``slam/grid.py`` ``GridLevel``) are row-major: a 4 KiB page holds 1024 consecutive cells of a row.
This script runs the scan loop of a recording (``dynslam2d run``'s loop, stopped before the loop's end releases the
map) and, at chosen scans and at the loop's end, counts for every level

- the cells ever updated (``uidx != 0``: the cells whose three words a ray or the erasure wrote);
- the pages of each array present in ``/proc/self/pagemap`` (bit 63) and of those the ones mapped exclusively
  (bit 56: a private page of the process; a page only read is the shared zero page, present but not exclusive and
  not in the RSS);
- the pages holding an updated cell, row-major as stored (the simulated count, from the array's own address) and in
  tiles of 32 × 32, 64 × 16 and 16 × 64 cells (columns × rows; one 4 KiB page per tile of 4-byte cells), each tile
  aligned to the level's array origin;
- "read only": cells in pages present but not exclusive (only read by a kernel), bounded above by the tiles that
  hold a cell of such a page (what the tiled layout would add for them if those reads were writes; they cost no
  RSS in either layout, since a page only read maps the zero page).

MiB columns are the three arrays together (3 × pages × 4 KiB).

    PYTHONPATH=src python benchmarks/bench_mem_tiles.py <data>/mit-csail/mit-csail.clf [--at 1735,1914]

Not run by pytest; numbers go to docs/speed.md with this command (< 2 min on MIT CSAIL with warm kernels).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from scratch import scratch_dir

PAGE = os.sysconf("SC_PAGE_SIZE")
TILES = ((32, 32), (64, 16), (16, 64))  # (columns, rows) of cells per tile: 1024 cells, one page of 4-byte cells
ARRAYS = ("logodds", "prob", "uidx")


class _Stop(Exception):
    """Raised once the loop's end is recorded: the rest of the run (loop closure, clean-up, results) is skipped."""


def pagemap_flags(arr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(present, exclusive) boolean arrays, one entry per page spanned by ``arr``'s data."""
    addr = arr.__array_interface__["data"][0]
    first = addr // PAGE
    last = (addr + arr.nbytes - 1) // PAGE
    n = last - first + 1
    with open("/proc/self/pagemap", "rb") as fh:
        fh.seek(first * 8)
        words = np.frombuffer(fh.read(n * 8), dtype=np.uint64)
    return (words >> np.uint64(63)) & np.uint64(1) == 1, (words >> np.uint64(56)) & np.uint64(1) == 1


def rowmajor_pages(mask: np.ndarray, arr: np.ndarray) -> np.ndarray:
    """Sorted page numbers (relative to the array's first page) holding a cell of ``mask``, as ``arr`` is stored."""
    off = arr.__array_interface__["data"][0] % PAGE
    flat = np.flatnonzero(mask.ravel())
    return np.unique((off + flat * arr.itemsize) // PAGE)


def tiled_pages(mask: np.ndarray, tw: int, th: int) -> int:
    """Tiles of ``tw`` × ``th`` cells (columns × rows, aligned to the array's origin) holding a cell of ``mask``."""
    h, w = mask.shape
    ph, pw = -h % th, -w % tw
    m = np.pad(mask, ((0, ph), (0, pw)))
    return int(m.reshape((h + ph) // th, th, (w + pw) // tw, tw).any(axis=(1, 3)).sum())


def cells_of_pages(pages: np.ndarray, arr: np.ndarray) -> np.ndarray:
    """Boolean (H, W) mask of the cells stored in ``pages`` (relative page numbers) of row-major ``arr``."""
    off = arr.__array_interface__["data"][0] % PAGE
    per = PAGE // arr.itemsize
    out = np.zeros(arr.size, dtype=bool)
    for p in pages.tolist():
        a = max(p * PAGE - off, 0) // arr.itemsize
        out[a:a + per] = True
    return out.reshape(arr.shape)


def census(levels) -> list[dict]:
    rows = []
    for k, lv in enumerate(levels):
        arrays = {name: getattr(lv, name) for name in ARRAYS}
        if arrays["uidx"].size == 0:
            continue
        touched = arrays["uidx"] != 0
        row = {"level": k, "shape": arrays["uidx"].shape, "cells": touched.size, "touched": int(touched.sum())}
        present = exclusive = sim = alloc = 0
        read_only = np.zeros_like(touched)
        for a in arrays.values():
            pres, excl = pagemap_flags(a)
            present += int(pres.sum())
            exclusive += int((pres & excl).sum())
            alloc += pres.size
            sim += rowmajor_pages(touched, a).size
            read_only |= cells_of_pages(np.flatnonzero(pres & ~excl), a)
        read_only &= ~touched
        row.update(alloc=alloc, present=present, exclusive=exclusive, sim=sim, read_only=int(read_only.sum()))
        for tw, th in TILES:
            n = tiled_pages(touched, tw, th)
            row[f"t{tw}x{th}"] = 3 * n
            row[f"t{tw}x{th}+ro"] = 3 * tiled_pages(touched | read_only, tw, th)
            row[f"alloc{tw}x{th}"] = 3 * (-(-touched.shape[0] // th)) * (-(-touched.shape[1] // tw))
        rows.append(row)
    return rows


def mib(pages: int) -> str:
    return f"{pages * PAGE / 2**20:.2f}"


def print_table(title: str, rows: list[dict]) -> None:
    print(f"\n{title}  (pages and MiB: the three arrays together)")
    head = ("level", "W × H cells", "updated", "allocated", "present", "resident (excl.)", "row-major", "32 × 32",
            "64 × 16", "16 × 64", "read-only cells", "32 × 32 + read")
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    tot = {key: 0 for key in ("alloc", "present", "exclusive", "sim", "t32x32", "t64x16", "t16x64", "t32x32+ro")}
    for r in rows:
        for key in tot:
            tot[key] += r[key]
        h, w = r["shape"]
        print(f"| {r['level']} | {w} × {h} | {100 * r['touched'] / r['cells']:.1f} % | {mib(r['alloc'])} | "
              f"{mib(r['present'])} | {mib(r['exclusive'])} | {mib(r['sim'])} | {mib(r['t32x32'])} | "
              f"{mib(r['t64x16'])} | {mib(r['t16x64'])} | {r['read_only']} | {mib(r['t32x32+ro'])} |")
    print(f"| all | | | {mib(tot['alloc'])} | {mib(tot['present'])} | {mib(tot['exclusive'])} | {mib(tot['sim'])} | "
          f"{mib(tot['t32x32'])} | {mib(tot['t64x16'])} | {mib(tot['t16x64'])} | | {mib(tot['t32x32+ro'])} |")
    best = min(tot["t32x32"], tot["t64x16"], tot["t16x64"])
    print(f"saving, RSS(excl) - best tiled: {mib(tot['exclusive'] - best).strip()} MiB; "
          f"row-major simulated - best tiled: {mib(tot['sim'] - best).strip()} MiB")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input")
    ap.add_argument("--at", default="1735,1914", help="scan numbers (1-based, comma-separated) to record at")
    ap.add_argument("extra", nargs="*", help="more `dynslam2d run` arguments (e.g. --topic T)")
    args = ap.parse_args()
    at = {int(s) for s in args.at.split(",") if s}
    import dynslam2d.cli
    import dynslam2d.pipeline as P

    tables: list[tuple[str, list[dict]]] = []
    first = P.Pipeline.process
    count = [0]

    def process(self, scan):
        step = first(self, scan)
        count[0] += 1
        if count[0] in at:
            tables.append((f"scan {count[0]}", census(self.slam.map.levels)))
        return step

    release = P._release_unexported

    def at_end(hmap):
        tables.append((f"loop's end (scan {count[0]})", census(hmap.levels)))
        raise _Stop

    P.Pipeline.process = process
    P._release_unexported = at_end
    t0 = time.perf_counter()
    out = scratch_dir("bench-mem-tiles-")
    sys.argv = ["dynslam2d", "run", args.input, "--out", out + "/run", "-q", *args.extra]
    try:
        dynslam2d.cli.main()
    except (_Stop, SystemExit):
        pass
    finally:
        P._release_unexported = release
    for title, rows in tables:
        print_table(title, rows)
    print(f"\n{time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
