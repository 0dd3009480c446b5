"""Extrapolated central differences of the compiled simulator, the reference the
sensitivity tests check against (issue 24).

A speed's sample ``w(t_k; p)`` is smooth in a parameter ``p`` only while no contact
change crosses ``t_k``: as a change moves past a sample instant, the sample goes from
one mode's flow to the other's, and its derivative jumps (the saltation). Steps small
enough that no change crosses any sample leave the simulator's own error (its changes
are located to a normalised 1e-12), divided by the step, as the differences' error:
the best of plain steps 1e-5 to 1e-8 resolved 7.3e-7 on paper A's drive and up to
9.0e-5 on random drives (this file's tests at a441c56). So the steps here are larger,
the samples that some change crosses between the runs are left out (about 1 % of them,
counted), and the differences are extrapolated to a vanishing step (Richardson's
extrapolation: ``(4 D(h/2) - D(h)) / 3`` has an error of order ``h^4``, and a third step
``h/4`` takes it to ``h^6``).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

import backlashkit as bk
from backlashkit._numpy_sensitivity import PARAMS

#: Largest relative steps ``h`` of the differences; each column is compared with the
#: best.
STEPS = (1e-1, 3e-2, 1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5)
#: Steps ``h, h/2, h/4`` extrapolated: an error of order ``h^6``. A light friction's
#: column is small against the simulator's error and needs large steps, at which two
#: levels (an ``h^4`` error) still missed 1e-6 on one random drive.
LEVELS = 3
#: A drive whose shaft meets or leaves a flank at a relative speed below this share of
#: its largest is near grazing, where the speeds are not smooth in the parameters (the
#: change's time moves like the inverse of that speed): not checked.
GRAZING = 0.05


@dataclass
class Agreement:
    """The largest over a drive's parameters of the best step's
    ``max |D - S| / max |S|`` over the samples kept, and the samples left out."""

    error: float
    left_out: int
    samples: int


def near_grazing(res: bk.DriveResponse) -> bool:
    """Whether a contact change of ``res`` is at a relative speed below
    :data:`GRAZING` of its largest."""
    rel = res.w_motor - res.w_load
    return any(abs(np.interp(e.time, res.t, rel)) < GRAZING * np.max(np.abs(rel))
               for e in res.contact_events)


def _changes(res: bk.DriveResponse) -> tuple[np.ndarray, list[str]]:
    """The times and kinds of ``res``'s contact changes."""
    return (np.array([e.time for e in res.contact_events]),
            [e.kind for e in res.contact_events])


def _run(drive: bk.TwoMassDrive, t, u) -> tuple[np.ndarray, np.ndarray, list[str]]:
    res = drive.simulate(t, u)
    return (np.stack([res.w_motor, res.w_load], axis=1), *_changes(res))


def _crossed(t: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Samples lying between the earliest and latest time of some change over the
    runs (``times``: one row per run)."""
    lo, hi = times.min(axis=0), times.max(axis=0)
    k_lo, k_hi = np.searchsorted(t, lo, side="left"), np.searchsorted(t, hi, side="right")
    out = np.zeros(t.size, dtype=bool)
    for a, b in zip(k_lo, k_hi, strict=True):
        out[a:b] = True
    return out


def extrapolate(diffs: list[np.ndarray]) -> np.ndarray:
    """Richardson's extrapolation of central differences at steps ``h, h/2, h/4, ...``
    to a vanishing step: each level cancels the next even power of ``h``."""
    level = 0
    while len(diffs) > 1:
        level += 1
        diffs = [(4 ** level * fine - coarse) / (4 ** level - 1)
                 for coarse, fine in itertools.pairwise(diffs)]
    return diffs[0]


def agreement(drive: bk.TwoMassDrive, t: np.ndarray, u: np.ndarray, sens: np.ndarray
              ) -> Agreement | None:
    """``sens`` (``(len(t), 2, 7)``, the parameters in :data:`PARAMS`' order) against
    the extrapolated differences; None near grazing, or where every step changes the
    sequence of contact changes for some parameter."""
    res = drive.simulate(t, u)
    if not res.contact_events or near_grazing(res):
        return None
    times0, kinds0 = _changes(res)
    values = {n: getattr(drive, n) for n in PARAMS}
    worst, left_out = 0.0, 0
    for j, name in enumerate(PARAMS):
        scale = np.max(np.abs(sens[:, :, j]))
        best, best_out = np.inf, 0
        for h in STEPS:
            steps = [h / 2 ** i for i in range(LEVELS)]
            runs = [_run(bk.TwoMassDrive(**{**values, name: values[name] * (1 + s * e)}), t, u)
                    for e in steps for s in (1.0, -1.0)]
            if any(kinds != kinds0 for _, _, kinds in runs):
                continue
            crossed = _crossed(t, np.stack([times0, *(tm for _, tm, _ in runs)]))
            diffs = [(runs[2 * i][0] - runs[2 * i + 1][0]) / (2 * e * values[name])
                     for i, e in enumerate(steps)]
            err = np.max(np.abs(extrapolate(diffs) - sens[:, :, j])[~crossed]) / scale
            if err < best:
                best, best_out = err, int(np.sum(crossed))
        if not np.isfinite(best):
            return None
        worst, left_out = max(worst, best), left_out + best_out
    return Agreement(worst, left_out, t.size * len(PARAMS))
