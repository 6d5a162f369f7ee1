"""Pass upd47 (issue 13 item 1): a large level that grows by rows at its top extends its zeroed arrays' memory
maps in place (``mremap``) instead of copying them; the level must hold exactly what the copying growth gives."""

from __future__ import annotations

import numpy as np
import pytest

from dynslam2d.slam.grid import GridLevel, MultiResMap
from dynslam2d.types import Pose2D

#: the method itself (a test's spy replaces it on the class)
_EXTEND_ROWS = GridLevel._extend_rows


def _scan(rng: np.random.Generator, n: int = 360) -> np.ndarray:
    a = np.linspace(-np.pi, np.pi, n, endpoint=False)
    r = rng.uniform(1.0, 12.0, n)
    return np.column_stack((r * np.cos(a), r * np.sin(a)))


def _run(no_extend: bool, monkeypatch: pytest.MonkeyPatch, hold_view: bool = False) -> tuple[MultiResMap, int]:
    """A map driven up (+y: growths at the top rows), then down (growths at the bottom), then right; per scan the
    levels' arrays compared against their state before (the content outside the new rows unchanged)."""
    rng = np.random.default_rng(7)
    taken = 0
    orig = _EXTEND_ROWS

    def counting(self, *a):  # noqa: ANN001, ANN002, ANN202 - a test spy
        nonlocal taken
        ok = False if no_extend else orig(self, *a)
        taken += ok
        return ok

    monkeypatch.setattr(GridLevel, "_extend_rows", counting)
    m = MultiResMap(0.05, 3, -0.4, 0.85, growth_margin=1.0)
    held = []
    path = [(0.0, 0.4 * k) for k in range(40)] + [(0.0, 16.0 - 0.5 * k) for k in range(60)] + [
        (0.5 * k, -14.0) for k in range(30)]
    for x, y in path:
        if hold_view:
            held = [m.levels[0].logodds]  # (another view of the finest log-odds, as the tracker's map view)
        m.integrate(Pose2D(x, y, 0.3), _scan(rng), _scan(rng, 40) * 1.2)
    del held
    return m, taken


def test_growth_at_the_top_extends_in_place_with_the_copying_growths_content(monkeypatch: pytest.MonkeyPatch) -> None:
    ref, n_ref = _run(True, monkeypatch)
    new, n_new = _run(False, monkeypatch)
    assert n_ref == 0 and n_new > 0  # (the top growths of the large levels took the in-place way)
    for a, b in zip(ref.levels, new.levels):
        assert (a.i0, a.j0, a.update_counter, a.n_grows) == (b.i0, b.j0, b.update_counter, b.n_grows)
        for name in ("logodds", "prob", "uidx"):
            x, y = getattr(a, name), getattr(b, name)
            assert x.shape == y.shape and x.dtype == y.dtype and x.flags.c_contiguous and y.flags.c_contiguous
            assert x.tobytes() == y.tobytes(), name


def test_a_level_viewed_elsewhere_is_copied_and_the_view_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    """With another array viewing the finest log-odds on every scan their map cannot be resized: the copying
    growth instead, the same content."""
    ref, _ = _run(True, monkeypatch)
    new, _ = _run(False, monkeypatch, hold_view=True)
    for a, b in zip(ref.levels, new.levels):
        for name in ("logodds", "prob", "uidx"):
            assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name


def test_extend_rows_refuses_an_array_that_is_not_its_maps() -> None:
    lv = GridLevel(0.05)
    lv.ensure(0, 0, 599, 599)  # (800 × 800 cells with the margins, 2.4 MiB an array: zeroed memory maps)
    h, w = lv.shape
    assert set(lv._maps) == {"logodds", "prob", "uidx"}
    lv.logodds = lv.logodds.copy()
    lv.logodds[3, 4] = 1.5
    assert not lv._extend_rows("logodds", np.float32, h, h + 100)
    assert lv.logodds.shape == (h, w) and lv.logodds[3, 4] == 1.5
    lv.ensure(lv.i0, lv.j0, lv.i0 + w - 1, lv.j0 + h + 5)  # (a top growth: the log-odds copied, the others extended)
    assert lv.shape[1] == w and lv.shape[0] > h
    assert lv.logodds.shape == lv.uidx.shape == lv.prob.shape and lv.logodds[3, 4] == 1.5
    assert lv.logodds.sum() == 1.5 and not lv.uidx.any() and not lv.prob.any()  # (0: probability 0.5)
    assert set(lv._maps) == {"logodds", "prob", "uidx"}
