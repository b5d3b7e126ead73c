"""Validators used at the public API: they return clean arrays or raise :class:`InputError`."""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum
from typing import TypeVar

import numpy as np

from virtus.errors import InputError

E = TypeVar("E", bound=Enum)


def as_float_array(
    name: str,
    value: object,
    shape: Sequence[int | None] | None = None,
    *,
    allow_nan: bool = False,
) -> np.ndarray:
    """Convert ``value`` to a float64 array and check its shape and finiteness.

    Parameters
    ----------
    name : argument name used in the error message.
    shape : expected shape; ``None`` entries match any length, a leading ``...`` is not
        supported (use :func:`as_points` for ``(N, k)`` arrays).
    allow_nan : accept NaN entries (invalid pixels in maps); infinities are always rejected.
    """
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an int beyond float64
        raise InputError(name, "a numeric array", value) from None
    if shape is not None:
        check_shape(name, array.shape, shape)
    bad = np.isinf(array) if allow_nan else ~np.isfinite(array)
    if bad.any():
        raise InputError(name, "finite values", f"{int(bad.sum())} non-finite entries")
    return array


def check_shape(name: str, have: tuple[int, ...], shape: Sequence[int | None]) -> None:
    """Raise :class:`InputError` unless ``have`` matches ``shape`` (``None`` = any length)."""
    if len(have) != len(shape) or any(
        want is not None and got != want for got, want in zip(have, shape, strict=True)
    ):
        want_text = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InputError(name, f"an array of shape {want_text}", f"shape {have}")


def as_points(name: str, value: object, dim: int, *, allow_nan: bool = False) -> np.ndarray:
    """Return ``value`` as a ``(N, dim)`` float64 array; a single ``(dim,)`` point is refused."""
    return as_float_array(name, value, (None, dim), allow_nan=allow_nan)


def positive(name: str, value: object) -> float:
    """Return ``value`` as a finite float > 0."""
    number = finite(name, value)
    if number <= 0:
        raise InputError(name, "a positive number", value)
    return number


def finite(name: str, value: object) -> float:
    """Return ``value`` as a finite float."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except OverflowError:  # an int beyond float64
        raise InputError(name, "a finite number", value) from None
    except (TypeError, ValueError):
        raise InputError(name, "a number", value) from None
    if not np.isfinite(number):
        raise InputError(name, "a finite number", value)
    return number


def positive_int(name: str, value: object, minimum: int = 1) -> int:
    """Return ``value`` as an int >= ``minimum`` (bools and non-integral floats refused)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise InputError(name, f"an integer >= {minimum}", value)
    if value < minimum:
        raise InputError(name, f"an integer >= {minimum}", value)
    return int(value)


def as_rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    """Normalise the project's ``rng`` argument (Generator, seed or None) to a Generator."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, int | np.integer):
        return np.random.default_rng(rng)
    raise InputError("rng", "a numpy Generator, an int seed or None", rng)


def as_member(enum: type[E], name: str, value: object) -> E:
    """``value`` as a member of the string enum ``enum``, or :class:`InputError` naming
    ``name`` and the allowed values."""
    try:
        return enum(value)
    except ValueError:
        raise InputError(name, f"one of {[m.value for m in enum]}", value) from None
