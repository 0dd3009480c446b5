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
from ..plants import TwoMassDrive
from .quantum import QUANTUM_RTOL
from .record import Record
from .step import find_step_down

__all__ = [
    "ARNoise",
    "AutoNoise",
    "WhiteNoise",
    "encoder_angles",
    "fit_ar",
    "held_noise_lag1",
    "innovation_ratio",
    "noise_label",
    "whiten",
]

#: Highest order accepted (the whitening filter drops this many samples per record).
MAX_ORDER = 50

#: A lag-1 autocorrelation is beyond white noise when it exceeds both this (white
#: noise fitted by the right model gives about ``1 / sqrt(n)``, 0.004 for 80 s at
#: 1 kHz, a model in a wrong basin 0.2 and more)...
MISFIT_LAG1 = 0.02
#: ... and this many of its standard deviations under white noise (short records:
#: ``1 / sqrt(n)`` is 0.03 for 1000 samples).
MISFIT_SIGMAS = 5.0
#: Seconds (at most) of the level held before each step-down whose speeds show the
#: noise's own colour, model-free, and the fewest samples that tell it.
HELD_NOISE_SECONDS = 5.0
HELD_NOISE_MIN = 200
#: Degree of the polynomial trend removed there first (a speed still settling).
HELD_TREND_DEGREE = 3
#: The window starts this many time constants of the prior's shaft ringing
#: (``2 J_M J_L / ((J_M + J_L) f_sh)``) after the last torque change before the
#: step-down: ringing left there reads as coloured noise (e^-12: below 1e-5 of it).
HELD_RINGING_DECAYS = 12.0
#: Standard deviation of the held-noise estimate ``1 + 2 r_1`` under white noise, in
#: units of ``1 / sqrt(n)``: twice Bartlett's ``sqrt(1/2)`` for the ``r_1 = -1/2`` of
#: white noise's first differences.
HELD_WHITE_STD = 1.4


@dataclass(frozen=True)
class WhiteNoise:
    """Independent Gaussian noise samples, one variance per record and speed.

    The variances are estimated from the data (a high-pass estimate, then the
    residuals of the fit), unless ``JointIdentifier(noise=(s_M, s_L))`` fixes them.
    """

    def _check_with(self, noise, final_horizon) -> None:
        """Nothing to refuse: white noise works with fixed levels and short windows."""

    def _resolve(self, held_lag1, held_samples, *, fixed_noise: bool, final_horizon):
        return self

    def _whitening_passes(self, noise_iter: int) -> int:
        return 0  # the residuals are white as they are


@dataclass(frozen=True)
class ARNoise:
    """Autoregressive noise of order ``order`` per record and speed.

    After the fit with white noise, the coefficients of ``A(q)`` and the innovation
    variance of every record and speed are estimated from its residuals
    (:func:`fit_ar`), the residuals of the model are whitened by ``A(q)``
    (:func:`whiten`) and weighted by the innovation standard deviation, and the fit is
    refined again; this is repeated ``JointSearch(noise_iter=...)`` times (at
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

    def _check_with(self, noise, final_horizon) -> None:
        """Refuse what an autoregression cannot be combined with."""
        if noise is not None:
            raise InputError(
                "noise=(s_M, s_L) fixes white noise levels; with noise_model=ARNoise(...) "
                "the noise is estimated from the residuals: give one or the other"
            )
        if final_horizon is not None:
            raise InputError(
                "noise_model=ARNoise(...) whitens the residuals of whole records; it "
                f"cannot be combined with final_horizon (got {final_horizon!r})"
            )

    def _resolve(self, held_lag1, held_samples, *, fixed_noise: bool, final_horizon):
        return self

    def _whitening_passes(self, noise_iter: int) -> int:
        return max(1, noise_iter)  # whitened at least once, else it were white noise

    def _fit_channel(self, residual: np.ndarray) -> tuple[np.ndarray, float]:
        return fit_ar(residual, self.order)


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
    levels, and with ``JointSearch(final_horizon=...)`` (which :class:`ARNoise` cannot
    whiten).
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

    def _check_with(self, noise, final_horizon) -> None:
        """Nothing to refuse: it stays white where ARNoise could not be used."""

    def _resolve(self, held_lag1, held_samples, *, fixed_noise: bool, final_horizon):
        """The model to fit: ARNoise where the held speeds' noise is coloured."""
        coloured = (not fixed_noise and final_horizon is None
                    and noise_coloured(held_lag1, held_samples))
        return ARNoise(self.order) if coloured else WhiteNoise()


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


def encoder_angles(rec: Record, *, quanta: tuple[float, float] | None = None) -> Record:
    """The record as encoder angles where both its speeds are differenced counts.

    Such speeds are the mean speeds over each sample, and their errors are the
    differences of the angles' quantisation errors: a moving average that no white
    or autoregressive model of the speeds fits. Their running sum gives the angles
    back (:meth:`Record.with_positions`), whose quantisation errors are nearly
    white, of variance ``q^2 / 12``: the joint estimator fits those.

    Parameters
    ----------
    rec : Record
        A record.
    quanta : tuple of float, optional
        The steps of its speeds ``w_motor``, ``w_load`` in rad/s where already known
        (:func:`speed_quantum` of each); found here otherwise.

    Returns
    -------
    Record
        With angles where both speeds are quantised to the same step (:func:`speed_quantum`);
        ``rec`` otherwise.
    """
    if rec.has_positions:
        return rec
    q_m, q_l = quanta if quanta is not None else rec.speed_quanta
    if not (q_m > 0 and q_l > 0):
        return rec
    same = math.isclose(q_m, q_l, rel_tol=QUANTUM_RTOL)
    return rec.with_positions(q_m * rec.ts if same else 0.0)


def lag1(e: np.ndarray) -> float:
    """Lag-1 autocorrelation of a residual (mean removed; 0 for a constant one)."""
    x = e - e.mean()
    den = float(x @ x)
    return float(x[1:] @ x[:-1]) / den if den > 0 else 0.0


def beyond_noise(lag1_: np.ndarray, white_std: np.ndarray) -> bool:
    """Whether any lag-1 autocorrelation exceeds both :data:`MISFIT_LAG1` and
    :data:`MISFIT_SIGMAS` times its std under white noise."""
    return bool(np.any(np.abs(lag1_) > np.maximum(MISFIT_LAG1, MISFIT_SIGMAS * white_std)))


def noise_coloured(held_lag1: np.ndarray, held_samples: np.ndarray) -> bool:
    """Whether the speeds' own noise (:func:`held_noise_lag1`) is correlated beyond
    white noise (:func:`beyond_noise`)."""
    return beyond_noise(np.nan_to_num(held_lag1),
                        HELD_WHITE_STD / np.sqrt(held_samples)[:, np.newaxis])


def held_noise_lag1(records: list[Record], prior: TwoMassDrive
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Lag-1 autocorrelation of each record's speed noise, from the speeds alone.

    On the last :data:`HELD_NOISE_SECONDS` of the level held before each step-down,
    from :data:`HELD_RINGING_DECAYS` time constants of the prior's shaft ringing after
    the last torque change on (ringing reads as coloured noise), the speeds less a
    cubic trend are differenced; noise ``e_t = rho e_(t-1) + w_t`` gives their lag-1
    autocorrelation ``(rho - 1) / 2``, so ``rho = 1 + 2 r_1`` (white noise: 0 within
    about ``1.4 / sqrt(n)``; noise averaged over a few samples, by an observer, about
    1).

    Parameters
    ----------
    records : list of Record
        The records.
    prior : TwoMassDrive
        Prior linear parameters (the ringing's time constant).

    Returns
    -------
    lag1 : numpy.ndarray
        ``(n_records, 2)`` for ``(w_M, w_L)`` (for ``(phi_M, phi_L)`` where the record
        holds encoder angles: the angles' own lag-1 less their trend, since they are
        fitted); NaN where the record holds no level of
        :data:`HELD_NOISE_MIN` samples, or where the speed's own motion dominates the
        differences (above 2); values between 1 and 2 (noise averaged over samples)
        count as 1.
    samples : numpy.ndarray
        Samples used per record (1 where none).
    """
    out = np.full((len(records), 2), np.nan)
    samples = np.ones(len(records))
    j_eff = prior.J_M * prior.J_L / (prior.J_M + prior.J_L)
    tau = 2.0 * j_eff / prior.f_sh if prior.f_sh > 0 else math.inf
    for k, rec in enumerate(records):
        try:
            i_s = find_step_down(rec)[0]
        except InputError:
            continue
        u = rec.torque[:i_s]
        changes = np.flatnonzero(u != u[-1])
        settled = (int(changes[-1]) + 1 if changes.size else 0) + HELD_RINGING_DECAYS * tau / rec.ts
        m = min(int(round(HELD_NOISE_SECONDS / rec.ts)), int(i_s - min(settled, i_s)))
        if m < HELD_NOISE_MIN:
            continue
        samples[k] = m
        x = np.linspace(-1.0, 1.0, m)
        angles = rec.has_positions
        for c, w in enumerate((rec.phi_motor, rec.phi_load) if angles
                              else (rec.w_motor, rec.w_load)):
            y = w[i_s - m : i_s]
            y = y - np.polynomial.polynomial.polyval(  # a speed still settling: its trend
                x, np.polynomial.polynomial.polyfit(x, y, HELD_TREND_DEGREE + angles))
            # an angle's noise is what is left of it; a speed's is seen in its differences
            rho = lag1(y) if angles else 1.0 + 2.0 * lag1(np.diff(y))
            out[k, c] = min(rho, 1.0) if rho <= 2.0 else np.nan
    return out, samples


def sample_noise(rng: np.random.Generator, std: float, a: np.ndarray | None, n: int
                 ) -> np.ndarray:
    """``n`` samples of fitted noise: white of ``std``, or ``1 / A(q)`` driven by it.

    An autoregression starts in its stationary regime: it is run in until its slowest
    pole has decayed to 1e-6.
    """
    if a is None:
        return rng.normal(0.0, std, n)
    from scipy.signal import lfilter

    burn = _impulse_length(a, 1e-6)
    eps = rng.normal(0.0, std, n + burn)
    return lfilter([1.0], np.r_[1.0, a], eps)[burn:]


def noise_label(noise_ar: np.ndarray | None) -> str:
    """A fit's noise model in words: ``"white"``, or ``"ar(p)"`` for the order of its
    autoregressive coefficients.

    Parameters
    ----------
    noise_ar : numpy.ndarray or None
        ``JointIdentifier.noise_ar_``: ``(n_records, 2, p)``, or None for white noise.

    Returns
    -------
    str
        The model's name.
    """
    return "white" if noise_ar is None else f"ar({np.shape(noise_ar)[-1]})"


def check_noise_model(noise_model) -> None:
    """Refuse what is not one of this module's noise models."""
    if not isinstance(noise_model, (WhiteNoise, ARNoise, AutoNoise)):
        raise InputError(
            "noise_model must be a WhiteNoise, ARNoise or AutoNoise "
            f"(backlashkit.identify.noise), got {type(noise_model).__name__}"
        )
