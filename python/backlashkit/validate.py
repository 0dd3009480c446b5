"""Argument checks shared by the public API.

Messages follow one pattern: the parameter's name, the constraint, the value received,
and, where useful, what to do.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .errors import InputError

#: Relative tolerance on the spacing of a time vector for it to count as uniform.
UNIFORM_RTOL = 1e-6
#: A backlash half-width (rad) above this is noted as likely degrees: a gear's backlash
#: half-width is a few degrees at most, and 0.5 rad is 29 deg (paper A's is 2, its
#: search goes to 15).
THETA_DEGREES_LIKELY = 0.5


def positive(name: str, value: float) -> float:
    """Return ``value`` as a float, or raise if it is not finite and > 0."""
    v = finite_scalar(name, value)
    if not v > 0:
        raise InputError(f"{name} must be > 0, got {value!r}")
    return v


def nonnegative(name: str, value: float) -> float:
    """Return ``value`` as a float, or raise if it is not finite and >= 0."""
    v = finite_scalar(name, value)
    if not v >= 0:
        raise InputError(f"{name} must be >= 0, got {value!r}")
    return v


def degrees_note(name: str, theta: float) -> str | None:
    """The note that ``name = theta`` (a half-width in rad) looks like degrees written as
    rad, where it exceeds :data:`THETA_DEGREES_LIKELY`; else None."""
    if not theta > THETA_DEGREES_LIKELY:
        return None
    return (f"{name} = {theta:g} rad is a half-width of {math.degrees(theta):.3g} deg: "
            f"{name.rsplit('.', 1)[-1]} is in rad (degrees written as rad? {theta:g} deg is "
            f"{math.radians(theta):.4g} rad)")


def real_numbers(name: str, value: object, what: str = "real numbers") -> None:
    """Refuse a string, a bool, None or a complex number anywhere in ``value`` (a number,
    or nested lists, tuples or arrays of them): NumPy would read ``"-2.0"`` as -2 and
    True as 1, and drop an imaginary part with a warning); ``what`` words the kind."""
    if isinstance(value, (list, tuple)):
        for item in value:
            real_numbers(name, item, what)
    elif isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise InputError(f"{name} must be {what}, got an array of {value.dtype}")
    elif (isinstance(value, (str, bytes, bool, np.bool_, complex, np.complexfloating))
          or value is None):
        raise InputError(f"{name} must be {what}, got {value!r:.80}")


def finite_scalar(name: str, value: float) -> float:
    """Return ``value`` as a float, or raise if it is not a finite real number."""
    if isinstance(value, (bool, str, bytes)):  # float("1") works, but "1" is no number
        raise InputError(f"{name} must be a real number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{name} must be finite, got {value!r}")
    return v


def finite_array(name: str, values: Sequence[float] | np.ndarray, *, ndim: int = 1) -> np.ndarray:
    """Return ``values`` as a C-contiguous float64 array with every sample finite."""
    try:
        arr = np.ascontiguousarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of real numbers") from None
    if arr.ndim != ndim:
        raise InputError(f"{name} must be {ndim}-dimensional, got shape {arr.shape}")
    # A finite sum proves every sample finite (NaN and inf propagate); only a
    # non-finite sum needs the element-wise look, which may still find none (overflow).
    with np.errstate(over="ignore", invalid="ignore"):
        if math.isfinite(arr.sum()):
            return arr
    bad = ~np.isfinite(arr)
    if bad.any():
        first = np.argwhere(bad)[0]
        where = int(first[0]) if ndim == 1 else tuple(int(i) for i in first)
        raise InputError(
            f"{name} has a non-finite value ({arr[tuple(first)]}) at index {where}; "
            "remove or fill NaN/inf values first"
        )
    return arr


def uniform_tolerance(t: np.ndarray, ts: float) -> float:
    """Largest deviation of a step from ``ts`` that still counts as uniform sampling:
    ``UNIFORM_RTOL`` of the step, or the rounding of the time values themselves (time
    stamps of 1.7e9 s, Unix time, are stored to 2.4e-7 s in float64)."""
    resolution = 4.0 * float(np.finfo(np.float64).eps) * float(np.max(np.abs(t[[0, -1]])))
    return max(UNIFORM_RTOL * ts, resolution)


#: Significant digits of times in messages: enough to tell two samples of a long record
#: apart, few enough to leave out the binary rounding of a difference (0.0015 s, not
#: 0.0015000000000000013 s).
TIME_DIGITS = 12


def time_grid(
    t: Sequence[float] | np.ndarray, *, name: str = "t", min_samples: int = 2
) -> tuple[np.ndarray, float]:
    """Check a uniform, increasing time vector; return it and its sample time ``Ts``."""
    arr = finite_array(name, t)
    if arr.size < min_samples:
        raise InputError(f"{name} must have at least {min_samples} samples, got {arr.size}")
    dt = np.diff(arr)
    ts = (arr[-1] - arr[0]) / (arr.size - 1)
    tol = uniform_tolerance(arr, ts)
    lo, hi = dt.min(), dt.max()
    if lo > 0 and hi - ts <= tol and ts - lo <= tol:
        return arr, float(ts)
    var = name.rsplit(": ", 1)[-1]  # "exp.csv: t" names its samples t[i]
    if not (dt > 0).all():
        i = int(np.argmax(~(dt > 0)))
        raise InputError(
            f"{name} must be strictly increasing; {var}[{i + 1}] = {arr[i + 1]:.{TIME_DIGITS}g} "
            f"follows {var}[{i}] = {arr[i]:.{TIME_DIGITS}g}"
        )
    dev = np.abs(dt - ts)
    if dev.max() > tol:
        i = int(np.argmax(dev))
        raise InputError(
            f"{name} must be uniformly sampled; step {i} is {dt[i]:.{TIME_DIGITS}g} s but the "
            f"mean step is {ts:.{TIME_DIGITS}g} s; resample the data onto a uniform grid first"
        )
    return arr, float(ts)


def flag(name: str, value: object) -> bool:
    """``value`` as a bool, refused unless True or False (``"no"`` would count as true)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def integer(name: str, value: object, minimum: int) -> int:
    """``value`` as an int, refused unless an integer (not a bool) of at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)
