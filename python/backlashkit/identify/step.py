"""The torque step-down of a record, and the speed held before it.

Paper A's experiment holds a positive torque and then drops it
(``C_M = a 1(t) - a 1(t - t_s)``); :func:`find_step_down` locates the drop and
:func:`held_speed_gain` compares the speed held before it with the prior's rigid-body
response, which catches speeds in wrong units before a fit answers with a wrong
backlash.

Units are SI: s, N m, rad/s.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..errors import InputError
from ..plants import TwoMassDrive
from .record import Record, check_prior
from .torque import JUMP_THRESHOLD, torque_noise_std

__all__ = ["FAR_FROM_PRIOR", "find_step_down", "held_speed_gain", "is_far"]

#: A record's held speed (:func:`held_speed_gain`) or a joint fit's linear parameter
#: this many times off the prior's (either way) raises a PriorMismatchWarning.
FAR_FROM_PRIOR = 3.0

#: Fewest samples before the step-down that :func:`held_speed_gain` fits (else NaN).
HELD_MIN_SAMPLES = 10

def find_step_down(record: Record) -> tuple[int, float, float, float]:
    """Locate the torque step-down of a record.

    Parameters
    ----------
    record : Record
        The experiment.

    Returns
    -------
    i_s : int
        Index of the first sample of the lower level.
    t_s : float
        Its time in s.
    level_before, level_after : float
        Torque in N m on the sample before the step and from ``i_s`` on.

    Raises
    ------
    InputError
        If the torque has no drop from a positive level (the method needs the shaft
        to leave its positive flank), or none beyond the torque's noise.
    """
    u = record.torque
    du = np.diff(u)
    k = int(np.argmin(du))
    scale = float(np.max(np.abs(u)))
    if scale == 0.0 or not du[k] < -1e-9 * scale or not u[k] > 0:
        j = int(np.argmax(du))
        mirror = scale > 0.0 and du[j] > 1e-9 * scale and u[j] < 0
        raise InputError(
            f"{record.name}: the torque has no step-down (a drop from a positive level); "
            "the identification needs paper A's experiment C_M = a 1(t) - a 1(t - t_s), a > 0"
            + ("; this one rises from a negative level: negate the torque and both speeds "
               "(the mirror experiment)" if mirror else "")
        )
    noise = torque_noise_std(u)
    if -du[k] <= JUMP_THRESHOLD * math.sqrt(2.0) * noise:
        raise InputError(
            f"{record.name}: the torque has no step-down beyond its noise (largest drop "
            f"{-du[k]:.3g} N m at t = {record.t[k + 1]:.6g} s, noise std about {noise:.3g} N m); "
            "the identification needs paper A's experiment C_M = a 1(t) - a 1(t - t_s), a > 0"
        )
    i_s = k + 1
    return i_s, float(record.t[i_s]), float(u[k]), float(u[i_s])

def held_speed_gain(record: Record, prior: TwoMassDrive) -> float:
    """How many times the prior's speed the record holds before its step-down.

    Before the step-down the inertia-weighted speed ``v = (J_M w_M + J_L w_L) / J``
    (``J = J_M + J_L``) follows the rigid body ``J v' = torque - (f_M + f_L) v``: the
    shaft's forces cancel, and the backlash does not change where it settles. With
    the prior's inertias and frictions, ``v = g r + a^k v_0`` is fitted by least
    squares, ``r`` the body's response to the record's torque from rest (zero-order
    hold, exact) and ``a^k`` the decay of an initial speed; ``g`` is returned. The
    two-step and regression methods simulate the prior from the held speed: a ``g``
    far from 1 means speeds or torque in other units (rpm read as rad/s gives about
    9.55) or frictions that far off. (Swapped speed columns do not show here: both
    speeds are equal on a held level.)

    Parameters
    ----------
    record : Record
        A step-down experiment.
    prior : TwoMassDrive
        The prior drive (its ``theta`` is not used).

    Returns
    -------
    float
        The least-squares gain ``g`` (1 when the record fits the prior's rigid body);
        NaN when fewer than :data:`HELD_MIN_SAMPLES` samples precede the step-down.

    Raises
    ------
    InputError
        If ``record`` or ``prior`` is not one, the prior has no friction
        (``f_M + f_L = 0``: no steady speed), or the record has no step-down (see
        :func:`find_step_down`).
    """
    from itertools import accumulate

    if not isinstance(record, Record):
        raise InputError(f"record must be a Record, got {type(record).__name__}")
    check_prior(prior)
    friction, inertia = prior.f_M + prior.f_L, prior.J_M + prior.J_L
    if not friction > 0:
        raise InputError(f"held_speed_gain needs f_M + f_L > 0 (a steady speed), got "
                         f"{friction!r}")
    i_s = find_step_down(record)[0]
    if i_s < HELD_MIN_SAMPLES:
        return math.nan
    a = math.exp(-friction * record.ts / inertia)
    b = (1.0 - a) / friction
    # r[k] = a r[k-1] + b u[k-1], r[0] = 0 (scipy.signal.lfilter would cost its import)
    rest = np.fromiter(accumulate((b * float(x) for x in record.torque[: i_s - 1]),
                                  lambda r, x: a * r + x, initial=0.0), float, i_s)
    v = (prior.J_M * record.w_motor[:i_s] + prior.J_L * record.w_load[:i_s]) / inertia
    basis = np.column_stack([rest, a ** np.arange(i_s)])
    # both sides scaled to 1 (speeds of 1e300 would overflow the squares, a torque of
    # 1e-15 fall below lstsq's rank cut-off)
    scale = float(np.max(np.abs(v))) or 1.0
    col = float(np.max(np.abs(rest))) or 1.0
    (gain, _), *_ = np.linalg.lstsq(basis / [col, 1.0], v / scale, rcond=None)
    return float(gain) * scale / col

def is_far(ratio: float, factor: float = FAR_FROM_PRIOR) -> bool:
    """Whether a ratio to the prior is more than ``factor`` off (either way)."""
    return not 1.0 / factor <= ratio <= factor

def warn_held_speeds(recs: list[Record], prior: TwoMassDrive) -> list[float]:
    """:func:`held_speed_gain` of every record; a PriorMismatchWarning for those far
    off (:data:`FAR_FROM_PRIOR`)."""




    gains = [held_speed_gain(rec, prior) for rec in recs]
    for rec, gain in zip(recs, gains, strict=True):
        if math.isfinite(gain) and is_far(gain):
            warnings.warn(
                f"{rec.name}: under the torque held before the step-down the speeds are "
                f"{gain:.3g} times the prior's, and this method simulates the prior from "
                "them: check the units of the speeds (rpm read as rad/s?) and of the "
                "torque, and the prior's frictions",
                PriorMismatchWarning, stacklevel=3)
    return gains
