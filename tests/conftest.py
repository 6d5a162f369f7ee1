"""Shared test fixtures.

Real datasets live in ``../shared/data`` beside the repository (CI has it; a
user's machine usually does not). Tests that need them take the ``shared_data``
fixture and are skipped with a clear reason when the folder is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("DYNSLAM2D_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))


def shared_file(relative: str) -> Path:
    """Path of a file under ../shared/data, skipping the test if it is absent."""
    path = SHARED_DATA / relative
    if not path.exists():
        pytest.skip(f"real dataset {relative} not found under {SHARED_DATA} (only in CI / with ../shared/data)")
    return path


@pytest.fixture
def shared_data() -> Path:
    """The ../shared/data folder; skips the test when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real datasets not available: {SHARED_DATA} does not exist")
    return SHARED_DATA


class ScanList:
    """A scan source over scans already in memory (one read of a recording for several runs)."""

    def __init__(self, scans, meta):
        self.scans, self.meta = list(scans), meta

    def __iter__(self):
        return iter(self.scans)

    def __len__(self):
        return len(self.scans)


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    """Run ``dynslam2d ARGS`` in-process: (exit code, stdout, stderr)."""
    import sys

    from dynslam2d.cli import main

    old = sys.argv
    sys.argv = ["dynslam2d", *args]
    code = 0
    try:
        main()
    except SystemExit as exc:
        code = int(exc.code or 0)
    finally:
        sys.argv = old
    out, err = capsys.readouterr()
    return code, out, err
