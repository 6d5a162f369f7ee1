"""The moving tracks' reason text in ``TrackManage._manage`` (docs/speed.md, pass trk87): the distance since birth
formatted from Python's ``math.hypot`` (:func:`dynslam2d.detect.tracktable._hypot_2f`) must print as NumPy's
``np.hypot`` of the same differences did — the two differ in the last bit for about 0.6 % of the pairs, and where
the distance is next to a tie of the two-decimal rounding the texts would differ."""

from __future__ import annotations

import math

import numpy as np

from dynslam2d.detect.tracktable import _hypot_2f


def _numpy_text(dx: float, dy: float) -> str:
    return f"{float(np.hypot(dx, dy)):.2f}"


def test_pairs_whose_hypots_straddle_a_tie() -> None:
    """Pairs (found by search) whose ``math.hypot`` is 0.12500000000000003 and ``np.hypot`` exactly 0.125: the texts
    0.13 and 0.12; the helper gives NumPy's."""
    for dx, dy in ((0.0881581011723437, 0.08861799590199959), (0.10835667300964623, 0.062320393245554925),
                   (0.10804672649720892, 0.06285622398169759)):
        assert math.hypot(dx, dy) != float(np.hypot(dx, dy))  # (the case the guard exists for)
        assert _hypot_2f(dx, dy) == _numpy_text(dx, dy) == "0.12"


def test_random_and_special_distances() -> None:
    """Random differences over six scales, exact ties, zero, negative, non-finite and huge ones."""
    rng = np.random.default_rng(87)
    for scale in (1e-3, 0.1, 1.0, 10.0, 1e3, 1e5):
        for dx, dy in (rng.normal(size=(20000, 2)) * scale).tolist():
            assert _hypot_2f(dx, dy) == _numpy_text(dx, dy)
    for dx, dy in ((0.005, 0.0), (0.015, 0.0), (0.015, 0.02), (-0.125, 0.0), (0.0, 0.0), (-0.0, -0.0),
                   (math.nan, 1.0), (math.inf, math.nan), (-math.inf, 2.0), (1e7, 1.0), (1e300, 1e300),
                   (5e-324, 0.0)):
        assert _hypot_2f(dx, dy) == _numpy_text(dx, dy)
