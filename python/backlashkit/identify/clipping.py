"""Detection of clipped (saturated) speed channels in a measured record.

A speed that hits the limit of its sensor, converter or logger stays *exactly* at its
largest (or smallest) value over many samples, while the same channel is noisy
elsewhere. No model of the drive can follow such a plateau, so an identification on
it answers with a number that means nothing; the identifiers refuse the record
instead (issue 3: "a record on which the method cannot work ... is reported as such").

The samples exactly at the channel's extreme value count as clipping when all of these
hold:

* there are at least :data:`MIN_COUNT` of them (after a run at the very first sample,
  which is not counted: a record can start at a held speed, e.g. a noise-free
  simulation started at steady state) and their value is not 0 (an encoder at rest
  reads exactly 0; that is no limit);
* they are at least :data:`PILE_UP` times as many as the samples at the next value
  inwards: a limit piles up the whole tail beyond it, while a free tail thins out
  towards the extreme (with continuous values every value occurs once);
* the sample before the first of them differs from it by more than
  :data:`ENTRY_STEP` of the channel's largest magnitude (a noise-free simulation can
  settle onto its fixed point to the last bit; a clipped signal arrives with a step);
* the channel's noise (robust spread of its second difference, away from the
  extremes) is at least its quantisation step (the smallest change between two
  samples), so that it dithers between levels. A quantised speed without that much
  noise that sits on its highest level for a while (a steady state) cannot be told
  from a clipped one, and is not flagged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

#: Fewest samples at a channel's extreme counted as clipping.
MIN_COUNT = 5
#: Least ratio of the samples at the extreme to those at the next value inwards.
PILE_UP = 2.0
#: The step into the extreme value must exceed this fraction of the largest magnitude.
ENTRY_STEP = 1e-9


@dataclass(frozen=True)
class Clipping:
    """Samples of a channel stuck at its ``side`` value (``"maximum"``/``"minimum"``)."""

    first: int  # index of the first such sample
    last: int  # index of the last one
    count: int  # how many samples sit at the value
    longest: int  # the longest run of them
    value: float
    side: str


def _longest_run(mask: np.ndarray) -> int:
    edges = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return int(np.max(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1), initial=0))


def _noise_hp_d2(d2: np.ndarray) -> float:
    """:func:`backlashkit.signals.highpass_noise_std` from given second differences."""
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def find_clipping(y: np.ndarray) -> Clipping | None:
    """The samples of ``y`` clipped at its maximum or minimum, or None.

    Parameters
    ----------
    y : numpy.ndarray
        One finite channel (e.g. a measured speed in rad/s).

    Returns
    -------
    Clipping or None
        The clipped samples (module docstring for the criteria; the side with more of
        them if both are), or None if the channel is not clipped.
    """
    y = np.asarray(y, float)
    n = y.size
    if n < MIN_COUNT + 1:
        return None
    scale = float(np.max(np.abs(y)))
    steps = np.abs(np.diff(y))
    quantum = float(np.min(steps[steps > 0.0], initial=np.inf))
    # the noise off the extremes: a long plateau would make the median of the second
    # differences 0 and hide the most heavily clipped channels
    extreme = (y == np.max(y)) | (y == np.min(y))
    free = ~(extreme[2:] | extreme[1:-1] | extreme[:-2])
    d2 = np.diff(y, 2)[free]
    if not (d2.size >= 3 and _noise_hp_d2(d2) >= quantum):
        return None
    found: Clipping | None = None
    for side, value in (("maximum", float(np.max(y))), ("minimum", float(np.min(y)))):
        if value == 0.0:
            continue
        at = y == value
        lead = int(np.argmin(at)) if not at.all() else n  # a held start is no clipping
        at[:lead] = False
        idx = np.flatnonzero(at)
        if idx.size < MIN_COUNT or not abs(y[idx[0] - 1] - value) > ENTRY_STEP * scale:
            continue
        inner = y[y != value]
        nxt = float(np.max(inner)) if side == "maximum" else float(np.min(inner))
        if not idx.size >= PILE_UP * np.count_nonzero(y == nxt):
            continue
        if found is None or idx.size > found.count:
            found = Clipping(int(idx[0]), int(idx[-1]), int(idx.size), _longest_run(at),
                               value, side)
    return found


def check_not_clipped(record) -> None:
    """Raise :class:`~backlashkit.errors.InputError` if a speed of ``record`` is clipped.

    Parameters
    ----------
    record : backlashkit.identify.Record
        The record (its ``name`` goes into the message).

    Raises
    ------
    InputError
        Naming the record, the channel, where the plateau lies and what to do.
    """
    for col, quantum in zip(("w_motor", "w_load"), record.speed_quanta, strict=True):
        w = getattr(record, col)
        # an encoder's speed sits on a few levels by nature: no plateau is a limit there
        clip = None if quantum > 0 else find_clipping(w)
        if clip is None:
            continue
        t = record.t
        raise InputError(
            f"{record.name}: {col} is clipped: {clip.count} samples between t = "
            f"{t[clip.first]:.6g} s and {t[clip.last]:.6g} s (runs of up to {clip.longest}) sit "
            f"exactly at its {clip.side} {clip.value:.6g} rad/s, a sensor, converter or "
            "logger limit; no model fits a clipped speed: record it within the sensor's "
            "range"
        )
