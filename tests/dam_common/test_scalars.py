"""dam_common.scalars.clip against numpy.clip, the reference it must match bit for bit."""

from __future__ import annotations

import itertools
import math

import numpy as np

from dam_common.scalars import clip

VALUES = (-2.0, -1.0, -0.0, 0.0, 0.5, 1.0, 3.0, math.inf, -math.inf, math.nan)


def test_clip_matches_numpy_clip_with_array_bounds_bit_for_bit() -> None:
    for value, low, high in itertools.product(VALUES, (-1.0, -0.0, 0.0), (0.0, -0.0, 1.0)):
        if low > high:
            continue
        expected = float(np.clip(np.array([value]), np.array([low]), np.array([high]))[0])
        got = clip(value, low, high)
        if math.isnan(expected):
            assert math.isnan(got), (value, low, high)
        else:
            assert got == expected and math.copysign(1.0, got) == math.copysign(1.0, expected), \
                (value, low, high, got, expected)
