"""The torque of a record: noise check and piecewise-constant levels.

The identifiers take the torque column as the *exact* input of the model. A measured
torque (a current times the torque constant) carries noise, and the model driven by
it rattles in the backlash where the real drive did not: on paper A's drive 0.3 mN m
of white noise on a 0.157 N m step (0.2 %) shrinks the joint fit's standard error by
up to half, 1 mN m hundreds of times or more, with the truth hundreds of them away
(``tests/test_torque.py::test_why_the_limit``). So a record whose torque is noisy is
refused, with two ways out: the torque command (the set-point) instead of
the measured torque, or :func:`torque_levels`, which replaces a noisy
piecewise-constant torque (paper A's steps) by its levels.

Units: N m.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError, Option

if TYPE_CHECKING:
    from .record import Record

__all__ = ["TORQUE_NOISE_LIMIT", "check_torque_noise", "torque_levels", "torque_noise_std"]

#: Largest torque noise (std) accepted, relative to the largest torque magnitude:
#: 0.13 % left the joint fit's estimate and standard error nearly unchanged on paper
#: A's drive (0.003 standard errors, 9 %), 0.19 % shrank them by 38 to 47 % (the
#: machine's rounding decides where the search ends among the contact changes the
#: model makes of the noise), 0.64 % hundreds to thousands of times
#: (``tests/test_torque.py::test_why_the_limit``).
TORQUE_NOISE_LIMIT = 5e-4
#: A sample-to-sample change of more than this many noise std of the first
#: differences starts a new level in :func:`torque_levels`.
JUMP_THRESHOLD = 8.0
_MAD = 1.4826  # median absolute deviation -> std of a Gaussian
#: A torque that changes on at most this fraction of its samples is already piecewise
#: constant (its jumps and short ramps): :func:`torque_levels` leaves it alone.
PIECEWISE_CONSTANT = 0.01
#: Samples of the held level before the largest drop that measure the torque's noise.
PLATEAU_SAMPLES = 5000
#: :func:`torque_levels` refuses a level whose samples, averaged over RAMP_WINDOW
#: samples, depart from it by more than RAMP_SIGMAS std of that average's noise (and
#: than TORQUE_NOISE_LIMIT of the largest torque): a ramp, a smooth torque, or a step
#: the noise hides from one sample to the next, not a step through noise
#: (``tests/test_torque.py`` checks records with white noise and noise filtered over
#: 10-200 samples: none is refused).
RAMP_WINDOW = 51
RAMP_SIGMAS = 8.0
#: Samples per block of the estimate of that noise.
NOISE_BLOCK = 500
#: The advice to level the torque, in a message.
TORQUE_LEVELS = Option("torque_levels", None, python="backlashkit.torque_levels")


def torque_noise_std(torque: np.ndarray) -> float:
    """Noise std of a torque signal in N m.

    The larger of two robust estimates: from the second differences, which vanish on
    steps' plateaus and ramps and are tiny on slow signals (a 2 rad/s sine at 1 ms: 4e-6
    of its amplitude) while white noise of std ``s`` gives them std ``s sqrt(6)``; and
    from the spread of the level held before the largest drop (up to 5000 samples since
    the previous jump), which also sees low-pass-filtered noise (the second differences
    of noise filtered over 40 samples understate it 7 times). Medians of absolute
    deviations ignore the few samples at jumps.

    Parameters
    ----------
    torque : numpy.ndarray
        The torque samples in N m.

    Returns
    -------
    float
        Estimated noise std in N m (0 for a piecewise-constant torque).
    """
    u = np.asarray(torque, float)
    if u.size < 3:
        return 0.0
    local = float(_MAD * np.median(np.abs(np.diff(u, 2))) / math.sqrt(6.0))
    return max(local, _plateau_std(u))


def _plateau_std(u: np.ndarray) -> float:
    """Robust std of the level held before the largest drop (0 if there is none)."""
    du = np.diff(u)
    k = int(np.argmin(du))
    drop = -float(du[k])
    if not drop > 0:
        return 0.0
    jumps = np.flatnonzero(np.abs(du[:k]) > 0.1 * drop)
    start = int(jumps[-1]) + 1 if jumps.size else 0
    level = u[max(start, k + 1 - PLATEAU_SAMPLES) : k + 1]
    if level.size < 50:  # a ramp, or a level too short to tell
        return 0.0
    return float(_MAD * np.median(np.abs(level - np.median(level))))


def check_torque_noise(rec: Record) -> None:
    """Refuse a record whose torque is noisy (module docstring).

    Parameters
    ----------
    rec : Record
        The record (its ``name`` goes into the message).

    Raises
    ------
    InputError
        If the torque's noise std exceeds :data:`TORQUE_NOISE_LIMIT` times its largest
        magnitude.
    """
    scale = float(np.max(np.abs(rec.torque)))
    noise = rec.torque_noise
    if scale > 0 and noise > TORQUE_NOISE_LIMIT * scale:
        raise InputError(
            f"{rec.name}: the torque is noisy (std about {noise:.3g} N m, "
            f"{100 * noise / scale:.2g} % of its largest value): the model takes the torque "
            "as its exact input and rattles on the noise; give the torque command (the "
            "set-point) instead of a measured torque, or replace the torque by its "
            "piecewise-constant levels (", TORQUE_LEVELS, ")"
        )


def torque_levels(rec: Record) -> Record:
    """The record with its torque replaced by piecewise-constant levels.

    A new level starts where the torque changes by more than :data:`JUMP_THRESHOLD`
    noise std of its first differences from one sample to the next; each level is the
    median of its samples. For steps through noise (paper A's experiments measured
    with a current sensor); a ramp slower than that threshold per sample, or a smooth
    torque, would become part of a level, so a level its samples depart from by more
    than noise is refused.

    Parameters
    ----------
    rec : Record
        The record.

    Returns
    -------
    Record
        The same record (same name) with the levels as its torque; ``rec`` itself
        when the torque is already piecewise constant (it changes on at most 1 % of its
        samples).

    Raises
    ------
    InputError
        If ``rec`` is not a record, or if the torque departs from a level by more than
        noise (:data:`RAMP_SIGMAS`; a ramp or a smooth torque, which levels would
        replace by a step: the message gives the time span).

    Examples
    --------
    >>> import numpy as np
    >>> import backlashkit as bk
    >>> t = np.arange(0, 2, 1e-3)
    >>> u = np.where(t < 1, 0.157, 0.0) + 1e-3 * np.random.default_rng(0).normal(size=t.size)
    >>> rec = bk.torque_levels(bk.Record(t, u, np.sin(t), np.sin(t)))
    >>> sorted({round(float(x), 2) for x in rec.torque})
    [0.0, 0.16]
    """
    if not hasattr(rec, "torque") or not hasattr(rec, "t"):
        raise InputError(
            f"torque_levels needs a Record, got {type(rec).__name__} (a file? read it with "
            "backlashkit.read_records)"
        )
    u = rec.torque
    d = np.abs(np.diff(u))
    moves = d[d > 0]
    if moves.size <= PIECEWISE_CONSTANT * d.size:  # the jumps alone: nothing to remove
        return rec
    # quantised noise (an ADC's counts) may leave most differences 0: then the count
    noise_d = max(_MAD * float(np.median(d)), float(moves.min()))
    starts = np.flatnonzero(d > JUMP_THRESHOLD * noise_d) + 1
    levels = np.empty_like(u)
    segments = np.split(np.arange(u.size), starts)
    for seg in segments:
        levels[seg] = np.median(u[seg])
    for seg in segments:  # noise per sample from the differences: noise_d / sqrt(2)
        _refuse_a_drift(rec, u[seg], float(levels[seg[0]]), int(seg[0]),
                        noise_d / math.sqrt(2.0), len(segments) == 1)
    if len(segments) == 1:  # no step left: a slow ramp under the threshold, or no step
        raise InputError(
            f"{rec.name}: ", Option("torque_levels", None), " found one level only: the "
            f"torque never changes by more than {JUMP_THRESHOLD:g} noise std from one "
            "sample to the next (a slow ramp?); give the torque command (the set-point) "
            "instead")
    return dataclasses.replace(rec, torque=levels)


def _refuse_a_drift(rec: Record, u: np.ndarray, level: float, i0: int, floor: float,
                    only: bool) -> None:
    """Refuse a level the torque departs from by more than noise (:data:`RAMP_SIGMAS`).

    The torque's departure from the level is averaged over :data:`RAMP_WINDOW`
    samples, and compared with the spread of that average: its robust spread in
    blocks of :data:`NOISE_BLOCK` samples about their own medians, the median over the
    blocks (neither a ramp nor a second level within the segment moves it, and it
    follows noise filtered over tens of samples), at least the first differences'
    noise averaged (``floor``, which sees quantised noise whose spread is mostly 0).
    """
    if u.size < RAMP_WINDOW:
        return
    c = np.concatenate([[0.0], np.cumsum(u - level)])
    mean = (c[RAMP_WINDOW:] - c[:-RAMP_WINDOW]) / RAMP_WINDOW  # over [j, j + W)
    blocks = np.array_split(mean, max(1, mean.size // NOISE_BLOCK))
    spread = float(np.median([np.median(np.abs(b - np.median(b))) for b in blocks]))
    noise = max(_MAD * spread, floor / math.sqrt(RAMP_WINDOW))
    limit = max(RAMP_SIGMAS * noise, TORQUE_NOISE_LIMIT * float(np.max(np.abs(rec.torque))))
    out = np.flatnonzero(np.abs(mean) > limit)
    if not out.size:
        return
    a = rec.t[i0 + out[0]]
    b = rec.t[i0 + out[-1] + RAMP_WINDOW - 1]
    worst = float(np.max(np.abs(mean)))
    what = ("found one level only: the torque never changes by more than "
            f"{JUMP_THRESHOLD:g} noise std from one sample to the next" if only else
            "cannot level the torque")
    raise InputError(
        f"{rec.name}: ", Option("torque_levels", None),
        f" {what}, and between t = {a:.6g} s and {b:.6g} s it "
        f"departs from its level {level:.4g} N m by up to {worst:.3g} N m (averaged over "
        f"{RAMP_WINDOW} samples, whose noise std is about {noise:.3g} N m): a ramp, a "
        "smooth torque, or a step too small for the noise to tell from one sample to the "
        "next; give the torque command (the set-point) instead"
    )
