"""The default kernel cache has one folder per version of the kernel sources (dynslam2d.jitcache).

numba keys a cached kernel by its own file only, so a kernel that compiles in another module's kernel would be
loaded stale after that module changed; the fingerprint of every kernel module names the folder instead.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from dynslam2d.jitcache import VERSION_PREFIX, kernel_sources_fingerprint, remove_stale_versions


def _package(root: Path) -> Path:
    (root / "sub").mkdir(parents=True)
    (root / "kern.py").write_text("from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    return x + 1\n")
    callee = "from numba import njit\n\n@njit(cache=True)\ndef g(x):\n    return 2 * x\n"
    (root / "sub" / "callee.py").write_text(callee)
    (root / "cli.py").write_text("print('no kernels here')\n")
    return root


def test_fingerprint_follows_every_kernel_module_and_only_them(tmp_path: Path) -> None:
    root = _package(tmp_path / "pkg")
    first = kernel_sources_fingerprint(root)
    assert len(first) == 16 and int(first, 16) >= 0
    assert kernel_sources_fingerprint(root) == first  # same sources (a reinstall): same folder
    (root / "cli.py").write_text("print('edited, still no kernels')\n")
    assert kernel_sources_fingerprint(root) == first  # a module without kernels does not invalidate the cache
    callee = root / "sub" / "callee.py"
    callee.write_text(callee.read_text().replace("2 * x", "3 * x"))
    changed = kernel_sources_fingerprint(root)
    assert changed != first  # a callee's edit invalidates its callers' cached code too
    callee.rename(root / "sub" / "moved.py")
    moved = kernel_sources_fingerprint(root)
    assert moved != changed  # the path is part of it
    lanes = root / "lanes.py"  # an intrinsic's code lands in its callers' cached code, as a callee's does
    lanes.write_text("from numba.extending import intrinsic\n\n@intrinsic\ndef op(typingctx, a):\n    return None\n")
    with_lanes = kernel_sources_fingerprint(root)
    assert with_lanes != moved
    lanes.write_text(lanes.read_text().replace("return None", "return a"))
    assert kernel_sources_fingerprint(root) != with_lanes


def test_fingerprint_of_the_installed_package_is_its_cache_folder() -> None:
    import dynslam2d

    folder = Path(os.environ["NUMBA_CACHE_DIR"])
    if not folder.name.startswith(VERSION_PREFIX):  # the user (or a test runner) chose the folder
        return
    assert folder.name == VERSION_PREFIX + kernel_sources_fingerprint(Path(dynslam2d.__file__).parent)


def test_remove_stale_versions_keeps_the_current_recent_and_foreign(tmp_path: Path) -> None:
    old = time.time() - 30 * 86400
    current = tmp_path / "k-0123456789abcdef"
    stale = tmp_path / "k-fedcba9876543210"
    recent = tmp_path / "k-00000000000000aa"
    foreign = tmp_path / "k-notahexname0000"
    legacy = tmp_path / "slam_0a1b"  # numba's own per-file folders of the earlier layout
    for path in (current, stale, recent, foreign, legacy):
        path.mkdir()
        (path / "index.nbi").write_bytes(b"x")
    for path in (current, stale, foreign, legacy):
        os.utime(path, (old, old))
    removed = remove_stale_versions(tmp_path, current, days=14.0)
    assert removed == [stale]
    assert not stale.exists()
    assert current.exists() and recent.exists() and foreign.exists() and legacy.exists()
