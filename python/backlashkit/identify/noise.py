"""Measurement-noise models of the joint estimator.

Configuration objects for ``JointIdentifier(noise_model=...)``:

* :class:`AutoNoise` (the default) -- :class:`ARNoise` where the speeds' own noise is
  coloured (seen on the level held before the step-down, before the fit),
  :class:`WhiteNoise` otherwise.
* :class:`WhiteNoise` -- independent Gaussian samples, one variance per
  record and speed. Right for simulated data and for speeds sampled without
  filtering; the fit is then maximum likelihood.
* :class:`ARNoise` -- an autoregressive process per record and speed,
  ``A(q) e_t = eps_t`` with ``A(q) = 1 + a_1 q^-1 + ... + a_p q^-p`` and white
  ``eps``. Measured speeds are often filtered (a speed observer, the differentiation
  of an encoder, an anti-alias filter), so that neighbouring samples of their noise
  are correlated. Treated as white, such noise makes every sample count as new
  information and the interval of ``theta`` too narrow, by up to
  ``sqrt(S(0) / var)`` (``S(0)`` the noise's spectrum at zero frequency, ``var`` its
  variance: 3 for a first-order filter with lag-1 correlation 0.8). With
  :class:`ARNoise` the residuals are whitened by ``A(q)`` before they are weighted (the
  prediction-error method with an autoregressive noise model, Ljung, *System
  Identification*, 2nd ed., Sec. 7.3): maximum likelihood again, conditional on the
  first ``p`` samples of every record.

:func:`fit_ar` (Yule-Walker) and :func:`whiten` are the pieces the fit uses; they are
public because users may want to look at their residuals the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import validate as v
from ..errors import InputError

__all__ = ["ARNoise", "AutoNoise", "WhiteNoise", "fit_ar", "innovation_ratio", "whiten"]

#: Highest order accepted (the whitening filter drops this many samples per record).
MAX_ORDER = 50


@dataclass(frozen=True)
class WhiteNoise:
    """Independent Gaussian noise samples, one variance per record and speed.

    The variances are estimated from the data (a high-pass estimate, then the
    residuals of the fit), unless ``JointIdentifier(noise=(s_M, s_L))`` fixes them.
    """


@dataclass(frozen=True)
class ARNoise:
    """Autoregressive noise of order ``order`` per record and speed.

    After the fit with white noise, the coefficients of ``A(q)`` and the innovation
    variance of every record and speed are estimated from its residuals
    (:func:`fit_ar`), the residuals of the model are whitened by ``A(q)``
    (:func:`whiten`) and weighted by the innovation standard deviation, and the fit is
    refined again; this is repeated ``JointIdentifier(noise_iter=...)`` times (at
    least once). The Fisher information, the profile likelihood and the parametric
    bootstrap all use the whitened residuals (the bootstrap simulates the fitted
    autoregressive noise). On white noise the coefficients come out within a few
    ``1 / sqrt(N)`` of 0 and the estimate hardly moves.

    Parameters
    ----------
    order : int, optional
        Order ``p`` of ``A(q)``, 1 to 50 (default 2: a first- or second-order filter
        on the speed measurement).
    """

    order: int = 2

    def __post_init__(self) -> None:
        _check_order(self.order)


@dataclass(frozen=True)
class AutoNoise:
    """:class:`ARNoise` where the speeds' own noise is coloured, :class:`WhiteNoise`
    elsewhere.

    Before the fit, the lag-1 autocorrelation of every record's speed noise is
    estimated from the speeds alone on the level held before the step-down
    (``JointIdentifier.held_noise_lag1_``: white noise gives 0 within about
    ``1.4 / sqrt(n)``), from 12 time constants of the prior's shaft ringing after the
    torque last changed (7 s on paper A's drive) to the step-down. Beyond 0.02 and 5
    of those standard deviations in any record and speed the fit uses
    ``ARNoise(order)``, otherwise ``WhiteNoise()``; also white where no record holds
    such a level of 200 samples, where ``noise=(s_M, s_L)`` fixes the noise
    levels, and with ``final_horizon`` (which :class:`ARNoise` cannot whiten).
    ``JointIdentifier.noise_model_`` says which was used. On white noise the answer is
    the white model's; on speeds filtered by an observer it is the autoregressive
    model's, whose interval is calibrated where the white one is 2.6 times too narrow
    (README, "Coloured noise").

    Parameters
    ----------
    order : int, optional
        Order of the :class:`ARNoise` used where the noise is coloured, 1 to 50
        (default 2).
    """

    order: int = 2

    def __post_init__(self) -> None:
        _check_order(self.order)


def _check_order(order) -> None:

    v.integer("order", order, 1)
    if order > MAX_ORDER:
        raise InputError(f"order must be at most {MAX_ORDER}, got {order!r}")


def fit_ar(e, order: int) -> tuple[np.ndarray, float]:
    """Autoregressive model of a residual sequence by the Yule-Walker equations.

    Parameters
    ----------
    e : array_like
        The sequence (1-D, finite; its mean is removed first), at least
        ``2 order + 2`` samples.
    order : int
        Order ``p`` >= 1.

    Returns
    -------
    a : numpy.ndarray
        Coefficients ``a_1 .. a_p`` of ``A(q) = 1 + a_1 q^-1 + ... + a_p q^-p``
        (``A(q) e_t`` is white). From the biased autocovariance, so ``A`` has its
        roots inside the unit circle (a stationary model).
    innovation_var : float
        Variance of the white innovation ``A(q) e_t``, in the units of ``e`` squared.

    Raises
    ------
    InputError
        If ``e`` is too short, not finite, or constant.
    """

    x = np.asarray(e, float)
    order = v.integer("order", order, 1)
    if x.ndim != 1 or x.size < 2 * order + 2:
        raise InputError(
            f"fit_ar needs a 1-D sequence of at least {2 * order + 2} samples for order "
            f"{order}, got shape {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise InputError("fit_ar: the sequence has NaN or inf samples")
    from scipy.linalg import solve_toeplitz  # lazily: scipy.linalg takes 0.2 s to import

    x = x - x.mean()
    n = x.size
    r = np.array([x[: n - k] @ x[k:] for k in range(order + 1)]) / n
    if not r[0] > 0:
        raise InputError("fit_ar: the sequence is constant; no noise to model")
    a = solve_toeplitz(r[:order], -r[1 : order + 1])
    return a, float(r[0] + a @ r[1 : order + 1])


def whiten(e, a) -> np.ndarray:
    """Filter residuals by ``A(q) = 1 + a_1 q^-1 + ... + a_p q^-p`` along the last axis.

    Parameters
    ----------
    e : array_like
        Residuals, shape ``(..., n)`` with ``n > p``.
    a : array_like
        Coefficients ``a_1 .. a_p``.

    Returns
    -------
    numpy.ndarray
        ``e_t + a_1 e_{t-1} + ... + a_p e_{t-p}`` for ``t = p .. n - 1``, shape
        ``(..., n - p)``: the first ``p`` samples, which lack a past, are dropped (the
        likelihood conditional on them).
    """
    x = np.asarray(e, float)
    a = np.asarray(a, float)
    p, n = a.size, x.shape[-1]
    if n <= p:
        raise InputError(f"whiten needs more than {p} samples, got {n}")
    out = x[..., p:].copy()
    for i, ai in enumerate(a, start=1):
        out += ai * x[..., p - i : n - i]
    return out


def _impulse_length(a: np.ndarray, tol: float = 1e-12) -> int:
    """Samples until the impulse response of ``1 / A(q)`` decays below ``tol``."""
    if a.size == 0:
        return 1
    radius = float(np.max(np.abs(np.roots(np.r_[1.0, a]))))
    if radius <= 0.0:
        return a.size + 1
    return int(min(1e7, max(100, math.log(tol) / math.log(min(radius, 1.0 - 1e-9)))))


def innovation_ratio(a) -> float:
    """Variance of the innovation of a stationary AR process over the process's own.

    Parameters
    ----------
    a : array_like
        Coefficients ``a_1 .. a_p`` of ``A(q)``, its roots inside the unit circle.

    Returns
    -------
    float
        ``var(eps) / var(e) = 1 / sum_k psi_k^2`` with ``psi`` the impulse response of
        ``1 / A(q)`` (``1 - rho^2`` for a first-order process of lag-1 correlation
        ``rho``).

    Raises
    ------
    InputError
        If ``A(q)`` has a root on or outside the unit circle (no stationary process).
    """
    from scipy.signal import lfilter

    a = np.asarray(a, float).ravel()
    if a.size and not float(np.max(np.abs(np.roots(np.r_[1.0, a])))) < 1.0:
        raise InputError(
            f"the autoregression {a.tolist()} is not stationary (a root of A(q) on or "
            "outside the unit circle)"
        )
    n = _impulse_length(a)
    impulse = np.zeros(n)
    impulse[0] = 1.0
    psi = lfilter([1.0], np.r_[1.0, a], impulse)
    return float(1.0 / (psi @ psi))
