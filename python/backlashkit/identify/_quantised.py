"""How far the encoders' quantisation moves the joint estimate of ``theta``.

An encoder's quantisation error is not white noise of variance ``q^2 / 12``. Along a
shaft that turns smoothly it sweeps the count evenly, like a low-discrepancy sequence,
so the weighted sums that make the estimate's error shrink much faster than white
noise would let them; where a shaft stands still it does not shrink at all. The
white-noise interval can therefore be far too wide or too narrow.

Near the optimum the estimate's error is linear in the measurement errors ``r`` (the
weighted residual rows): ``dz = -(J^T J)^-1 J^T r``. Its spread over what is unknown,
each encoder's offset within a count, is drawn directly: each draw quantises the
fitted model's angles from a uniformly random offset per encoder. Rows without an
encoder (analogue speeds, the prior's rows) get standard normal errors, as the
white-noise interval assumes. The draws are not Gaussian (lighter-tailed, and skewed
where a shaft crawls), so the interval's ends are their quantiles.
"""

from __future__ import annotations

import math

import numpy as np

from ._model import model_angles
from ._problem import Residual

#: Draws of the encoders' offsets: the interval's ends are their 2.5 and 97.5 %
#: quantiles, each then from 25 draws beyond it.
OFFSET_DRAWS = 1000
#: Seed of the offsets' draws: fixed, so that a fit is repeatable.
OFFSET_SEED = 20
#: Draws quantised at once (bounds the memory of a long record: draws x samples).
CHUNK = 50


def quantised(res: Residual) -> bool:
    """Whether ``res`` fits the angles of an encoder of known step."""
    return any(sp.positions and sp.record.quantum > 0 for sp in res.spans)


def log_theta_draws(res: Residual, jz: np.ndarray, cov_z: np.ndarray, z: np.ndarray,
                    draws: int = OFFSET_DRAWS) -> np.ndarray:
    """The error of the estimate of ``log theta`` for ``draws`` random offsets of the
    encoders (to first order).

    ``jz`` is the Jacobian of ``res`` at the log-parameters ``z`` (``theta`` first) and
    ``cov_z`` the inverse of ``jz^T jz``.
    """
    rng = np.random.default_rng(OFFSET_SEED)
    w = jz @ cov_z[:, 0]  # d(log theta) = -w . r
    sims = res.problem.simulate(z[np.newaxis, :], res.spans, res.ends)
    dz = np.zeros(draws)
    white = 0.0  # variance of the rows with Gaussian errors
    pos = 0
    for sp, s_, x, m in zip(res.spans, res.sels, sims, res.sizes, strict=True):
        angles = model_angles(x) if sp.positions else None
        for c in (0, 1):
            wb = w[pos : pos + m - res.lag]
            pos += m - res.lag
            if angles is None or not sp.record.quantum > 0:
                white += float(wb @ wb)
                continue
            phi = angles[c][0, s_]
            for lo in range(0, draws, CHUNK):
                offset = rng.uniform(0.0, sp.record.quantum, min(CHUNK, draws - lo))
                dz[lo : lo + offset.size] -= res.weigh(
                    sp, c, quantisation_error(phi, offset, sp.record.quantum)) @ wb
    white += float(w[pos:] @ w[pos:])  # the prior's rows
    dz += math.sqrt(white) * rng.standard_normal(draws)
    return dz


def quantisation_error(phi: np.ndarray, offset: np.ndarray, q: float) -> np.ndarray:
    """Errors ``(len(offset), len(phi))`` of an encoder of step ``q`` (rad) reading the
    angles ``phi`` (rad) shifted by each offset: ``q floor((phi + a) / q) - (phi + a)``."""
    shifted = phi[np.newaxis, :] + offset[:, np.newaxis]
    return q * np.floor(shifted / q) - shifted
