"""Arithmetic on plain Python floats for per-cycle loops (no numpy call per number)."""

from __future__ import annotations


def clip(value: float, low: float, high: float) -> float:
    """``value`` clipped to ``[low, high]`` as ``numpy.clip`` does it with array bounds: a NaN
    value stays NaN, and on a tie the bound is returned (the sign of a zero)."""
    if value != value:
        return value
    value = value if value > low else low
    return value if value < high else high
