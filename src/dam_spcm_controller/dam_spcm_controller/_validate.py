"""Boundary checks shared by the modules of this package (internal)."""

from __future__ import annotations

import math

import numpy as np

from dam_common.echo import brief_repr
from dam_spcm_controller.errors import InputError

_ALL = np.logical_and.reduce  # ndarray.all without its Python wrapper


def finite_scalar(name: str, value: float, *, positive: bool = False,
                  nonnegative: bool = False) -> float:
    """Return ``value`` as a float; raise :class:`InputError` naming it when it is bad."""
    if isinstance(value, bool):
        raise InputError(f'{name} must be a number, got {brief_repr(value)}')
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InputError(f'{name} must be a number, got {brief_repr(value)}') from None
    if not math.isfinite(out):
        raise InputError(f'{name} must be finite, got {brief_repr(value)}')
    if positive and out <= 0.0:
        raise InputError(f'{name} must be positive, got {brief_repr(value)}')
    if nonnegative and out < 0.0:
        raise InputError(f'{name} must be non-negative, got {brief_repr(value)}')
    return out


def finite_vector(name: str, value: object, length: int | None = None, *,
                  positive: bool = False, nonnegative: bool = False) -> np.ndarray:
    """Return ``value`` as a 1-D float64 array; raise :class:`InputError` naming it when bad.

    A scalar is accepted and broadcast when ``length`` is given.
    """
    if (type(value) is np.ndarray and value.dtype == np.float64 and value.ndim == 1
            and (length is None or value.shape[0] == length) and not positive
            and not nonnegative and _ALL(np.isfinite(value))):
        return value  # the common case of the control loop, in two numpy calls
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f'{name} must be numeric, got {brief_repr(value)}') from None
    if arr.ndim == 0 and length is not None:
        arr = np.full(length, float(arr))
    if arr.ndim != 1:
        raise InputError(f'{name} must be one-dimensional, got shape {arr.shape}')
    if length is not None and arr.shape[0] != length:
        raise InputError(f'{name} must have {length} values, got {arr.shape[0]}: '
                         f'{brief_repr(arr)}')
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f'{name}[{i}] must be finite, got {arr[i]!r}')
    if positive and (arr <= 0.0).any():
        i = int(np.flatnonzero(arr <= 0.0)[0])
        raise InputError(f'{name}[{i}] must be positive, got {arr[i]!r}')
    if nonnegative and (arr < 0.0).any():
        i = int(np.flatnonzero(arr < 0.0)[0])
        raise InputError(f'{name}[{i}] must be non-negative, got {arr[i]!r}')
    return arr
