"""Joint maximum-likelihood identification of the backlash and the linear parameters,
and the Cramér-Rao bound of the backlash.

:class:`JointIdentifier` fits ``theta`` (backlash **half-width**, rad) together with
the uncertain linear parameters of a :class:`~backlashkit.TwoMassDrive` to every
record and to **both** measured speeds, by weighted nonlinear least squares; with
white Gaussian measurement noise this is maximum likelihood (each channel weighted by
its own noise variance, estimated from the data). A prior enters, when its
uncertainty is given, as the Gaussian penalty

    sum_p ((p - p_prior) / (rel_std_p * p_prior))^2

(a maximum a posteriori estimate); without a stated uncertainty the parameters are
refined from the data alone. :func:`cramer_rao_bound` gives the Cramér-Rao lower bound
on the standard deviation of ``theta`` for a drive, an experiment and a noise level,
with the linear parameters known or estimated jointly.

Units are SI: s, N m, rad, rad/s.

Choices (documented, configurable where it matters)
---------------------------------------------------
* **Parameterisation.** ``theta`` and every estimated linear parameter are optimised
  as logarithms (positivity without bounds); a parameter whose prior value is 0 cannot
  be estimated (it stays fixed).
* **Which parameters.** ``prior_rel_std=None``: all six linear parameters estimated
  without a penalty; a float: all six, each with that relative standard deviation; a
  dict: only the listed parameters, with their relative std (0 = known exactly), the
  others fixed at the prior (as :func:`backlashkit.io.read_uncertainty_toml` reads
  an ``[uncertainty]`` table: "parameters not listed are taken as exact").
* **Model start.** ``start="auto"`` simulates a record from rest (state 0, shaft
  centred in the backlash) when it starts at rest (both measured speeds at the first
  sample within 4 noise standard deviations of 0, or below a quarter of their level
  just before the step-down: filtered noise can fool the first test), otherwise from
  ``pre_window`` seconds before the torque step-down, started at the model's own
  steady state under the torque held there (``w = a / (f_M + f_L)``, twist
  ``theta + f_L w / k_sh``), so that the speed level measured before the step informs
  ``f_M + f_L``. The residuals cover the simulated span (to the end of the record).
* **Noise.** Every record and channel has its own noise level (paper A's two steps
  differ by 30 dB on ``w_L``). It starts from a high-pass estimate (robust MAD of the
  second difference, ``/ sqrt(6)``) and is then re-estimated from the residuals of the
  fit (``sqrt(RSS / N)`` per record and channel), and the fit repeated
  (``noise_iter`` times): at convergence this is the maximum of the likelihood with
  unknown variances. ``noise=(s_M, s_L)`` fixes them instead (for every record).
  Filtered speed measurements have noise correlated from sample to sample, which the
  white-noise likelihood takes for information: ``noise_model=ARNoise(order)`` then
  fits an autoregressive model to the residuals of every record and channel and
  refines the fit on the residuals whitened by it (:mod:`backlashkit.identify.noise`);
  ``residual_lag1_`` shows whether the residuals the likelihood treats as white are.
* **Local minima.** The output error of this lightly damped drive (damping ratio
  about 0.013 for paper A's drive) is multimodal in ``theta`` and in the parameters
  that set the ringing (a 10 % error in ``k_sh`` shifts the phase by half a period
  within ten periods). Hence (i) a grid of ``n_grid`` values over ``(0, theta_max]``
  with the linear parameters at the prior (simulated in parallel by
  :func:`backlashkit.simulate_batch`), its ``n_starts`` best local minima and, when
  it succeeds, paper A's two-step estimate
  (:class:`~backlashkit.identify.TwoStepIdentifier`) as starts; (ii) every start
  refined on a short horizon (``horizons[0]`` = 0.15 s after the record start and
  after every torque jump, a few periods of the ringing); (iii) the ``n_continue``
  best distinct ones continued on growing horizons (0.4, 1, 3 s) and the best one also
  on finer steps (``fine_horizons``: 0.25, 0.4, 0.6, 1, 1.6, 3 s), and the end
  points still competitive there refined on the whole record, the lowest final cost
  kept; (iv) the best
  restarted with the stiffness shifted (``stiffness_restarts``), since the whole record
  is multimodal in the phase of the ringing, and with the friction split shifted
  (``friction_restarts``); (v) a fit whose residuals are correlated beyond
  noise is searched again from its own linear parameters (``misfit_restart``). The
  first horizon pins the sums
  ``J_M + J_L``, ``f_M + f_L`` and the ringing frequency but hardly how the sums split
  (the local minima met away from paper A's drive: ``J_M`` 13-46 % high with ``f_M``
  26-60 % low), so the best first-horizon solution is also restarted from other
  splits (``split_shifts``); and the first-horizon refinements stay within
  ``search_factor`` of the prior (at 20 dB a 0.15 s window is fitted as well by a
  shaft 20 times too soft without backlash).
  Refinement: Levenberg-Marquardt on the normal equations (the residual vector holds
  every sample, the parameters are few), forward-difference Jacobian with relative
  step ``fd_step`` (central differences for the final uncertainty), the perturbed
  models simulated as one batch straight into arrays; steps limited to a factor
  ``e^0.5`` per parameter. On the short horizons a record
  started from rest with its torque held until the step-down is simulated through
  the hold on a coarse grid (the flow is exact for a held torque whatever the step,
  and contact changes are located inside steps), so the windows after the step-down
  do not pay for the 40 s of samples they do not fit. The cost is only
  piecewise smooth in ``theta`` (the number of contact events changes), so the
  difference step is kept small. Near-grazing warnings of the perturbed simulations
  are silenced inside the fit.
* **Uncertainty.** Gauss-Newton / Fisher information at the optimum,
  ``cov(log p) = (J^T W J + P)^-1`` with ``P`` the prior's information; ``std_`` of
  ``theta`` by the delta method. The 95 % interval ``ci95_`` comes from the profile
  likelihood of ``theta`` by default (:class:`~backlashkit.identify.intervals.ProfileLikelihood`):
  where the shaft rattles (light loads: dozens of impacts per record) the likelihood
  is not quadratic at the scale of the standard error, and the Fisher interval
  ``theta_ +- 1.96 std_`` (``interval=FisherInterval()``) covers the truth less often
  (``benchmarks/robustness_joint.py``, README "Away from paper A's drive").
  ``interval=ParametricBootstrap(...)`` takes ``std_`` and ``ci95_`` from refits of
  data simulated from the estimate instead, and ``final_horizon`` fits the final stage
  only on short windows after every torque jump. Calibration is checked by coverage
  on simulated data in ``tests/test_identify_joint.py``.
"""

from __future__ import annotations

import inspect
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from .. import validate as v
from ..errors import (
    CorrelatedResidualsWarning,
    InputError,
    PriorMismatchWarning,
    SensitivityWarning,
)
from ..plants import TwoMassDrive
from ..signals import _noise_hp
from .intervals import (
    FisherInterval,
    ParametricBootstrap,
    ProfileLikelihood,
    profile_crossing,
)
from .noise import (
    ARNoise,
    AutoNoise,
    WhiteNoise,
    _impulse_length,
    fit_ar,
    innovation_ratio,
    whiten,
)
from .record import Record, as_records
from .step import find_step_down, is_far
from .two_step import TwoStepIdentifier

__all__ = [
    "CramerRaoBound",
    "JointIdentifier",
    "LINEAR_PARAMS",
    "cramer_rao_bound",
]

#: Linear parameters of a :class:`~backlashkit.TwoMassDrive`, in the fitted order.
LINEAR_PARAMS = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh")

ArrayLike = Sequence[float] | np.ndarray


def _drive(base: TwoMassDrive, names: Sequence[str], values: np.ndarray) -> TwoMassDrive:
    return replace(base, **{n: float(x) for n, x in zip(names, values, strict=True)})


@dataclass
class _Span:
    """The part of a record the model is fitted to, and how the model starts there."""

    record: Record
    k: int  # index of the record (its noise levels)
    i0: int
    t: np.ndarray
    torque: np.ndarray
    y_m: np.ndarray
    y_l: np.ndarray
    level: float | None  # torque held before the step-down (steady start) or None (rest)
    hold: float | None = None  # start: from rest after `level` held this long (s)


def _starts_at_rest(rec: Record, s_m: float, s_l: float) -> bool:
    """Whether both speeds start at rest (``start="auto"``, module docstring)."""
    if abs(rec.w_motor[0]) <= 4 * s_m + 1e-12 and abs(rec.w_load[0]) <= 4 * s_l + 1e-12:
        return True
    # the high-pass estimate misses most of a filtered (correlated) noise, whose first
    # sample can then exceed 4 of its "standard deviations": a record whose speeds
    # start far below the level they hold before the step-down starts at rest too
    try:
        i_s = find_step_down(rec)[0]
    except InputError:
        return False
    before = slice(max(0, i_s - REST_WINDOW), i_s)
    return all(abs(w[0]) <= REST_FRACTION * abs(float(np.mean(w[before])))
               for w in (rec.w_motor, rec.w_load))


#: A record starts at rest when its first speeds are below this fraction of their mean
#: over the last REST_WINDOW samples before the step-down (or within 4 noise std of 0).
REST_FRACTION = 0.25
REST_WINDOW = 20


def _spans(recs: list[Record], start: str, pre_window: float, sig0) -> list[_Span]:
    out = []
    for k, rec in enumerate(recs):
        s_m, s_l = sig0[k]
        mode = ("rest" if _starts_at_rest(rec, s_m, s_l) else "steady") if start == "auto" \
            else start
        if mode == "rest":
            i0, level = 0, None
        else:
            i_s, t_s, level, _ = find_step_down(rec)
            n_pre = int(round(pre_window / rec.ts))
            if n_pre > i_s:
                raise InputError(
                    f"{rec.name}: the record starts {rec.t[i_s] - rec.t[0]:.6g} s before the "
                    f"step-down at t = {t_s:.6g} s: record at least {pre_window:g} s of the held "
                    "torque before it (start='steady' fits the model from there, "
                    "pre_window)"
                )
            i0 = i_s - n_pre
        sl = slice(i0, None)
        out.append(_Span(rec, k, i0, rec.t[sl], rec.torque[sl], rec.w_motor[sl],
                         rec.w_load[sl], level))
    return out


#: Longest coarse step in s of the exact simulation through a held torque.
HOLD_STEP = 0.02


def _screen_spans(spans: list[_Span]) -> list[_Span]:
    """Cheaper spans for the short-horizon stages of the fit (same model, exactly).

    A record started from rest whose torque is one level held until the step-down
    (paper A's experiment) is fitted there only in short windows after ``t = 0`` and
    after the step-down, yet the model must be simulated through the whole hold to
    reach the second window. The record is split into the rest start up to the
    step-down and a span from the step-down on, whose initial state is simulated
    through the hold on a coarse grid (steps of at most :data:`HOLD_STEP`): the
    engine's flow is exact for a held torque whatever the step, and it locates the
    contact changes inside a step, so only the samples nobody looks at are skipped.
    """
    out = []
    for sp in spans:
        if sp.level is not None:
            out.append(sp)
            continue
        try:
            i_s, _, level, _ = find_step_down(sp.record)
        except InputError:
            out.append(sp)
            continue
        if i_s < 3 or np.any(sp.torque[:i_s] != level):
            out.append(sp)
            continue
        out.append(replace(sp, t=sp.t[:i_s], torque=sp.torque[:i_s], y_m=sp.y_m[:i_s],
                           y_l=sp.y_l[:i_s]))
        out.append(replace(sp, i0=sp.i0 + i_s, t=sp.t[i_s:], torque=sp.torque[i_s:],
                           y_m=sp.y_m[i_s:], y_l=sp.y_l[i_s:], level=level,
                           hold=float(sp.t[i_s] - sp.t[0])))
    return out


#: Candidates whose cost (chi-square units) on the last short horizon exceeds the best
#: one's by more than this are not refined on the whole record.
WHOLE_RECORD_MARGIN = 10.0
#: A stiffness restart is refined on the final data only if it beats the best solution
#: by more than this (chi-square units) on the longest short horizon.
RESTART_MARGIN = 1.0
#: A stiffness restart gets this many Levenberg-Marquardt iterations on the longest
#: short horizon and is continued only if it has come below the solution it restarts
#: from: a restart climbing back to the same basin is still thousands of chi-square
#: units above it then (paper A's drive), one falling into a better basin already
#: below (-20 at 0.4 of the true stiffness, ``benchmarks/robustness_joint.py``).
RESTART_SCREEN_ITER = 5
#: First-horizon solutions costing more than this times the best one's are not
#: continued (the right basin was within 1.1 times the best in the failures of
#: ``benchmarks/robustness_joint.py``).
CONTINUE_RATIO = 1.25
#: Candidates closer than this in every log-parameter count as one point.
SAME_POINT = 1e-3
#: End points of the continuation paths within this (chi-square units) of the best on
#: the longest short horizon, and more than :data:`DISTINCT` apart, make the search
#: ambiguous (``ambiguity_starts``).
AMBIGUITY_MARGIN = 30.0
#: Largest log-parameter difference of two end points that count as one basin.
DISTINCT = 1e-2

#: A held-theta refit of the profile search that ends more than this (chi-square units)
#: below the estimate's cost restarts the final refinement from there (at most
#: RECENTRE_MAX times): the likelihood of a rattling shaft is rough at the scale of
#: 1-2 units, and the refinement can stop on a bump next to a lower point.
RECENTRE_MARGIN = 0.5
RECENTRE_MAX = 2

#: Fewest samples after each torque jump that ``final_horizon`` must span.
MIN_FINAL_SAMPLES = 10

#: Lag-1 autocorrelation of a residual above which (in magnitude) the fit warns that its
#: interval is too narrow: white noise filtered to this correlation has an interval too
#: narrow by up to ``sqrt((1 + 0.2) / (1 - 0.2)) = 1.22`` (its spectrum at 0 against its
#: variance); the fits of white noise in the benchmarks stay below 0.01.
CORRELATED_LAG1 = 0.2

#: A fit whose residual (whitened with ``ARNoise``) has a lag-1 autocorrelation above
#: this in magnitude is searched again from its own linear parameters
#: (``misfit_restart``): white noise fitted by the right model gives about
#: ``1 / sqrt(n)`` (0.004 for 80 s at 1 kHz), a model in a wrong basin a correlated
#: residual (0.24-0.25 in the failures that motivated it).
MISFIT_LAG1 = 0.02
#: ... or above this many of its standard deviations under white noise, ``1 / sqrt(n)``
#: for ``n`` fitted samples (short records or ``final_horizon``: 0.16 for 1000 samples).
MISFIT_SIGMAS = 5.0
#: The second search's fit replaces the first only if its -2 log likelihood is lower
#: by more than this (chi-square units).
MISFIT_MARGIN = 1.0
#: Seconds (at most half of it) of the level held before each step-down whose speeds
#: show the noise's own colour, model-free (``held_noise_lag1_``), and the fewest
#: samples that tell it.
HELD_NOISE_SECONDS = 5.0
HELD_NOISE_MIN = 200
#: Degree of the polynomial trend removed there first (a speed still settling).
HELD_TREND_DEGREE = 3
#: The window starts this many time constants of the prior's shaft ringing
#: (``2 J_M J_L / ((J_M + J_L) f_sh)``) after the last torque change before the
#: step-down: ringing left there reads as coloured noise (e^-12: below 1e-5 of it).
HELD_RINGING_DECAYS = 12.0

#: The default interval and noise model (frozen, so one instance serves every identifier).
_PROFILE = ProfileLikelihood()
_AUTO = AutoNoise()

#: Order of a two-mass drive's values in a packed kernel parameter row
#: (:class:`~backlashkit.DriveChain` fields ``J, f, k, d, theta``).
PACKED = ("J_M", "J_L", "f_M", "f_L", "k_sh", "f_sh", "theta")


def _x0(p: np.ndarray, level: float | None) -> np.ndarray:
    """Initial states for packed parameter rows ``p``: rest, or steady under ``level``."""
    if level is None:
        return np.zeros((p.shape[0], 3))
    fs = p[:, 2] + p[:, 3]
    if not np.all(fs > 0):
        raise InputError(
            "start='steady' needs f_M + f_L > 0 (a finite steady state), got "
            f"f_M + f_L = {float(np.min(fs))!r}"
        )
    w = level / fs
    twist = p[:, 3] * w / p[:, 4]
    return np.column_stack([w, w, np.where(w >= 0, p[:, 6], -p[:, 6]) + twist])


def _simulate(p: np.ndarray, span: _Span, law, workers, end: int | None = None) -> np.ndarray:
    """States ``(len(p), end, 3)`` of packed parameter rows ``p`` over a span.

    What the compiled core refuses (contact chatter, a mode too fast for the sample
    time) becomes an :class:`InputError` naming the record; the searches catch it as
    the ``ValueError`` it still is.
    """
    try:
        return _simulate_span(p, span, law, workers, end)
    except InputError:
        raise
    except ValueError as exc:
        text = " ".join(str(exc).split())
        raise InputError(f"{span.record.name}: cannot simulate the drive on this record: "
                         f"{text}") from exc


def _simulate_span(p: np.ndarray, span: _Span, law, workers, end: int | None) -> np.ndarray:
    from ..simulate import _simulate_packed

    if span.hold is not None:  # from rest through the held torque, on a coarse grid
        n = max(2, math.ceil(span.hold / HOLD_STEP))
        held = _simulate_packed(2, p, 0.0, span.hold / n, np.full((1, n + 1), span.level),
                                np.zeros((p.shape[0], 3)), law=law, workers=workers)
        x0 = held[:, -1, :]
    else:
        x0 = _x0(p, span.level)
    end = span.t.size if end is None else max(end, 2)
    return _simulate_packed(2, p, span.t[0], span.record.ts, span.torque[np.newaxis, :end], x0,
                            law=law, workers=workers)


def _rel_std(prior_rel_std, names: Sequence[str]) -> dict[str, float | None]:
    """Parameter -> relative std (None: estimated without penalty); absent = fixed."""
    if prior_rel_std is None:
        return {n: None for n in names}
    if isinstance(prior_rel_std, Mapping):
        out: dict[str, float | None] = {}
        for key, val in prior_rel_std.items():
            if key == "theta":
                continue  # theta is always estimated, without a prior
            if key not in names:
                raise InputError(
                    f"prior_rel_std has unknown parameter {key!r}; allowed: {', '.join(names)}"
                )
            x = v.nonnegative(f"prior_rel_std[{key!r}]", val)
            if x > 0:
                out[key] = x
        return out
    x = v.nonnegative("prior_rel_std", prior_rel_std)
    return {n: x for n in names} if x > 0 else {}


def _basins(ends: list[_LMState]) -> int:
    """Distinct end points (:data:`DISTINCT`) within :data:`AMBIGUITY_MARGIN` of the best."""
    best = min(st.cost for st in ends)
    found: list[np.ndarray] = []
    for st in sorted(ends, key=lambda st_: st_.cost):
        if st.cost <= best + AMBIGUITY_MARGIN and all(
                np.max(np.abs(st.z - z)) > DISTINCT for z in found):
            found.append(st.z)
    return len(found)


def _residuals_and_fit(spans: list[_Span], sims: list[np.ndarray]):
    """Residuals ``(w_M, w_L)`` per span and the NRMSE fit % array ``(n_spans, 2)``."""
    residuals, fits = [], []
    for sp, x in zip(spans, sims, strict=True):
        em, el = sp.y_m - x[0, :, 0], sp.y_l - x[0, :, 1]
        residuals.append((em, el))
        fits.append([
            100.0 * (1.0 - np.linalg.norm(e) / max(np.linalg.norm(y - y.mean()), 1e-300))
            for e, y in ((em, sp.y_m), (el, sp.y_l))
        ])
    return residuals, np.array(fits)


def _refuse_unexplained(recs: list[Record], fits: np.ndarray) -> None:
    """Raise when the model explains a speed worse than its mean (fit % <= 0)."""
    worst = np.unravel_index(int(np.argmin(fits)), fits.shape)
    if not fits[worst] > 0:
        raise InputError(
            f"{recs[worst[0]].name}: the identified model does not explain "
            f"{('w_motor', 'w_load')[worst[1]]} (fit {fits[worst]:.3g} %, worse than its "
            "mean): these speeds do not show a two-mass drive responding to this torque; "
            "check the columns, units and the prior"
        )


def _beyond_noise(lag1: np.ndarray, white_std: np.ndarray) -> bool:
    """Whether any lag-1 autocorrelation exceeds both :data:`MISFIT_LAG1` and
    :data:`MISFIT_SIGMAS` times its std under white noise."""
    return bool(np.any(np.abs(lag1) > np.maximum(MISFIT_LAG1, MISFIT_SIGMAS * white_std)))


def _held_noise_lag1(recs: list[Record], prior: TwoMassDrive
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Lag-1 autocorrelation of each record's speed noise on the level held before its
    step-down, ``(n_records, 2)`` (NaN without :data:`HELD_NOISE_MIN` samples there),
    and the samples used per record.

    Model-free: from the first differences of the speeds less a cubic trend (the
    level, and a speed still settling); noise ``e_t = rho e_(t-1) + w_t`` gives their
    lag-1 autocorrelation ``(rho - 1) / 2``, so ``rho = 1 + 2 r_1`` (white noise: 0,
    with std about ``1.4 / sqrt(n)``; noise averaged over a few samples, by an observer,
    about 1). The window starts :data:`HELD_RINGING_DECAYS` time constants of the
    prior's shaft ringing after the last torque change (ringing reads as coloured
    noise); above 2 (the differences follow the speed's own motion, e.g. on a
    noise-free record) NaN, between 1 and 2 (noise averaged over samples) 1.
    """
    out = np.full((len(recs), 2), np.nan)
    samples = np.ones(len(recs))
    j_eff = prior.J_M * prior.J_L / (prior.J_M + prior.J_L)
    tau = 2.0 * j_eff / prior.f_sh if prior.f_sh > 0 else math.inf
    for k, rec in enumerate(recs):
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
        for c, w in enumerate((rec.w_motor, rec.w_load)):
            y = w[i_s - m : i_s]
            y = y - np.polynomial.polynomial.polyval(  # a speed still settling: its trend
                x, np.polynomial.polynomial.polyfit(x, y, HELD_TREND_DEGREE))
            rho = 1.0 + 2.0 * _lag1(np.diff(y))
            # above 2 no noise: the speed's own motion dominates the differences; up to
            # 2 noise averaged over samples (an observer's), whose differences have
            # r_1 about 0
            out[k, c] = min(rho, 1.0) if rho <= 2.0 else np.nan
    return out, samples


def _lag1(e: np.ndarray) -> float:
    """Lag-1 autocorrelation of a residual (mean removed; 0 for a constant one)."""
    x = e - e.mean()
    den = float(x @ x)
    return float(x[1:] @ x[:-1]) / den if den > 0 else 0.0


def _check_positive_sequence(name: str, value) -> None:
    """Raise unless ``value`` is a sequence of finite numbers > 0 (log-space shifts)."""
    try:
        items = [float(x) for x in value]
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a sequence of numbers > 0, got {value!r}") from None
    for x in items:
        v.positive(f"{name}[...]", x)


def _resplit(z: np.ndarray, free: Sequence[str], pair: tuple[str, str],
             shift: float) -> np.ndarray | None:
    """Log-parameters ``z`` (theta first) with the ratio of a pair of parameters
    multiplied by ``e^shift``, their sum kept, and ``k_sh`` moved so that the ringing
    frequency ``k_sh (1/J_M + 1/J_L)`` is kept; None if the pair is not estimated."""
    if pair[0] not in free or pair[1] not in free:
        return None
    z = z.copy()
    ia, ib = 1 + free.index(pair[0]), 1 + free.index(pair[1])
    omega2 = None
    if "k_sh" in free and {"J_M", "J_L"} <= set(free):
        jm, jl = math.exp(z[1 + free.index("J_M")]), math.exp(z[1 + free.index("J_L")])
        omega2 = math.exp(z[1 + free.index("k_sh")]) * (1 / jm + 1 / jl)
    total = math.exp(z[ia]) + math.exp(z[ib])
    xa = total / (1.0 + math.exp(-(z[ia] - z[ib] + shift)))
    if not (0.0 < xa < total and math.isfinite(total)):  # one of the pair dwarfs the other
        return None
    z[ia], z[ib] = math.log(xa), math.log(total - xa)
    if omega2 is not None:
        jm, jl = math.exp(z[1 + free.index("J_M")]), math.exp(z[1 + free.index("J_L")])
        z[1 + free.index("k_sh")] = math.log(omega2 / (1 / jm + 1 / jl))
    return z


@dataclass
class _Profiled:
    """What the profile-likelihood search found (:meth:`JointIdentifier._profile`)."""

    ci95: tuple[float, float]
    bounded: tuple[bool, bool]
    points: np.ndarray  # rows (theta, cost rise), sorted
    lowest_rise: float  # the lowest refit's cost rise (< 0: below the estimate's cost)
    lowest_z: np.ndarray  # its log-parameters


@dataclass
class _LMState:
    """Levenberg-Marquardt iterate: point, residual, cost, Jacobian at the point."""

    z: np.ndarray
    r: np.ndarray
    cost: float
    jac: np.ndarray | None
    mu: float = 1e-3
    done: bool = False


def _lm(fun, jac, z0: np.ndarray, *, max_iter: int, state: _LMState | None = None,
        rtol: float = 1e-10, atol: float = 1e-3, max_step: float = 0.5,
        bounds: tuple[np.ndarray, np.ndarray] | None = None) -> _LMState:
    """Levenberg-Marquardt on the normal equations (Marquardt scaling).

    The residual vector is long (every sample of both speeds) and the parameters few,
    so the step is solved from ``J^T J`` (n x n) rather than by an SVD of ``J``.
    Stops after ``max_iter`` Jacobians, or when an accepted step lowers the cost by
    less than ``rtol`` relative or ``atol`` absolute (the cost is in chi-square units:
    1e-3 is a parameter change of about 0.03 standard errors), or when no step lowers
    it. An accepted step is extrapolated (doubled while the cost keeps falling); no
    step changes a log-parameter by more than ``max_step``.
    """
    if state is None or state.done:
        r0 = fun(z0)
        state = _LMState(np.array(z0, float), r0, float(r0 @ r0), None)
        # a start the model cannot simulate (e.g. a parameter overflowing) has no
        # Jacobian; its cost stays inf (a profile refit far out: an unbounded rise)
        state.done = not math.isfinite(state.cost)
        if state.done:
            return state
    for _ in range(max_iter):
        if state.jac is None:
            try:
                state.jac = jac(state.z, state.r)
            except ValueError:  # a neighbour the model cannot simulate: stop here
                state.done = True
                break
        jz = state.jac
        g = jz.T @ state.r
        a = jz.T @ jz
        d = np.maximum(np.diag(a), 1e-12 * max(float(np.max(np.diag(a))), 1e-300))
        improved = False
        for _ in range(12):
            try:
                step = -np.linalg.solve(a + state.mu * np.diag(d), g)
            except np.linalg.LinAlgError:
                state.mu *= 10.0
                continue
            big = float(np.max(np.abs(step)))
            if big > max_step:  # at most a factor e^max_step per parameter and step
                step *= max_step / big
            z_new = state.z + step
            if bounds is not None:
                z_new = np.clip(z_new, *bounds)
                step = z_new - state.z
            r_new = fun(z_new)
            c_new = float(r_new @ r_new)
            if math.isfinite(c_new) and c_new < state.cost:
                while True:  # extrapolate along a good step (slow valleys, e.g. f_sh)
                    if 2.0 * float(np.max(np.abs(step))) > max_step:
                        break
                    step = 2.0 * step
                    z_try = state.z + step
                    if bounds is not None:
                        z_try = np.clip(z_try, *bounds)
                    r_try = fun(z_try)
                    c_try = float(r_try @ r_try)
                    if not (math.isfinite(c_try) and c_try < c_new):
                        break
                    z_new, r_new, c_new = z_try, r_try, c_try
                gain = state.cost - c_new
                state.z, state.r, state.jac = z_new, r_new, None
                old, state.cost = state.cost, c_new
                state.mu = max(state.mu / 5.0, 1e-12)
                improved = True
                if gain <= rtol * old or gain < atol:
                    state.done = True
                break
            state.mu *= 8.0
        if not improved:
            state.done = True
        if state.done:
            break
    return state


class JointIdentifier:
    """Joint ML / MAP identification of ``theta`` and the linear parameters.

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters (its ``theta`` is ignored).
    prior_rel_std : None, float or dict, optional
        Relative standard deviation of the prior per linear parameter (module
        docstring): ``None`` (default) estimates all six without a penalty, a float
        gives all six that uncertainty, a dict (e.g. from
        :func:`backlashkit.io.read_uncertainty_toml`) estimates only the listed
        parameters with a value > 0.
    noise : tuple of float, optional
        Noise standard deviations ``(s_M, s_L)`` in rad/s; default estimated from
        the data (module docstring).
    start : {"auto", "rest", "steady"}, optional
        How the model starts on each record (module docstring); default ``"auto"``.
    pre_window : float, optional
        ``start="steady"``: span in s before the step-down included in the fit
        (default 2).
    law : {"paper", "no-pull"}, optional
        Contact law of the model (default ``"paper"``).
    theta_max : float, optional
        Upper end of the initial grid in rad (default 15 deg).
    n_grid : int, optional
        Points of the initial grid (default 61).
    n_starts : int, optional
        Grid local minima refined (default 3), besides the two-step estimate.
    two_step_start : bool, optional
        Also start from paper A's two-step estimate when it succeeds (default True).
    noise_iter : int, optional
        Re-estimations of the noise levels from the residuals (default 1).
    fd_step : float, optional
        Relative finite-difference step (default 1e-6).
    screen_iter : int, optional
        Levenberg-Marquardt iterations from every start on the first horizon
        (default 10).
    horizons : sequence of float, optional
        Growing fit horizons in s after the start of each record and after every
        torque jump (default ``(0.15, 0.4, 1.0, 3.0)``, then ``final_horizon``): the
        multi-start runs on the first, the best solutions are continued on the next.
    fine_horizons : sequence of float, optional
        Horizons in s inserted between the first and the last of ``horizons`` for a
        second continuation path from the best first-horizon solution (default
        ``(0.25, 0.6, 1.6)``; ``()`` for one path). The end points of both paths
        compete on the whole record like the candidates of one path (identical ones
        are refined once). On a rattling light load a long step of the horizon can
        land in the wrong basin (``theta`` 15 % off at 5 deg, 20 dB, where the CRB is
        1.1 %) and a short one elsewhere; the lower final cost decides. It costs
        0.1-0.2 s per fit on paper A's drive (README, "Speed").
    n_continue : int, optional
        Distinct solutions of the first horizon, with a cost within 1.25 times the
        best one's, continued on the growing horizons (default at most 3); those still
        within 10 (chi-square units) of the best after the last short horizon are
        refined on the whole record (or ``final_horizon``), the lowest final cost kept.
    ambiguity_starts : int, optional
        When the continuation paths end at distinct points within
        :data:`AMBIGUITY_MARGIN` of each other on the longest short horizon (the
        landscape is multimodal there: a rattling light load at 20 dB), up to this many
        more distinct first-horizon solutions (from the starts above and from as many
        more local minima of the initial grid) are continued on the usual horizons
        and compete on the whole record with the others (default 4; 0: off). It never
        triggered on paper A's protocol (``benchmarks/joint_vs_crb.py --runs 10``: the
        40 fits of ``reproduce ravanbod2002``, 0 ``ambiguous_``); on
        ``benchmarks/robustness_joint.py --trials 20 --seed 5`` it raised the coverage
        of the Fisher intervals from 504 to 507 of 540 trials and removed the 54 %
        error at 0.5 deg, 20 dB (README, "Away from paper A's drive").
    max_iter : int, optional
        Maximum Levenberg-Marquardt iterations (Jacobians) of the final refinement
        and of each refit after a noise re-estimation (default 40).
    stiffness_grid : int, optional
        Values of ``k_sh`` in the initial grid, geometric over
        ``k_prior * [1 / stiffness_span, stiffness_span]`` (default 1: the prior's
        only). A wrong prior stiffness shifts the phase of the ringing within the first
        horizon. On ``benchmarks/robustness_joint.py`` 9 values moved the failures to
        other scenarios rather than removing them and made one fit about 7 times
        slower, so it is not the default.
    stiffness_span : float, optional
        Largest factor between the gridded and the prior ``k_sh``, > 1 (default 1.6).
    split_shifts : sequence of float, optional
        Restarts of the best first-horizon solution with the ratios ``J_M / J_L`` and
        ``f_M / f_L`` multiplied by ``e^{+-x}`` for every ``x`` given (sums and the
        ringing frequency kept), refined on the first horizon like the other starts
        (default ``(0.5,)``: four restarts; ``()`` for none).
    search_factor : float or None, optional
        The first-horizon refinements keep every linear parameter within this factor
        of the prior and ``theta`` within ``[theta_max / 1000, theta_max]`` (default
        3; None: unbounded). Later stages are unbounded.
    stiffness_restarts : sequence of float, optional
        After the final refinement, restarts of the best solution with ``k_sh``
        multiplied by ``e^{+-x}`` for every ``x`` given, refined on the longest short
        horizon (``RESTART_SCREEN_ITER`` iterations first; continued only if below the
        best solution's cost there) and, if they beat the best solution there, on the
        final data; kept if they lower the final cost (default ``(0.15, 0.4, 0.8)``: six
        restarts; ``()`` for none). The final cost is multimodal in the phase of the
        ringing: at 20 dB on a light load a fit from a 40 % prior error settled 22 %
        below the true stiffness, in a minimum the true parameters beat, and a 16 %
        higher stiffness leads to the one near the truth
        (``benchmarks/robustness_joint.py --trials 6 --seed 4``; the trial is a test);
        another settled at 0.47 of it, and only the restart at ``e^0.4`` found the
        truth's basin (seed 5; also a test).
    friction_restarts : sequence of float, optional
        Restarts of the same kind, with the ratio ``f_M / f_L`` multiplied by
        ``e^{+-x}`` (the sum kept) for every ``x`` given (default ``(1.0,)``: two
        restarts; ``()`` for none). The sum of the frictions shows on the whole record,
        their split only while the shaft crosses the backlash: at 40 dB on a light load
        a fit settled with ``f_M : f_L`` at 0.58 : 1.42 of the truth's, 9 standard errors
        off in ``theta`` and above the minimum near the truth (by more than 10 000
        chi-square units, the trial's test), behind a ridge that no local step crosses;
        the restart at ``e^1`` reaches it (``benchmarks/robustness_joint.py --trials 30
        --seed 11``).
    misfit_restart : bool, optional
        When a residual of the fit (whitened, with ``ARNoise``) is correlated beyond
        noise, its lag-1 autocorrelation above both :data:`MISFIT_LAG1` = 0.02 and
        :data:`MISFIT_SIGMAS` = 5 times ``1 / sqrt(n)`` (its std under white noise), run
        the whole search once more from the fitted linear parameters instead of the
        prior (the prior penalty, if any, stays at the prior) and keep the fit of
        higher likelihood, the noise levels profiled out (default True). A prior 40 %
        off can leave every start of the ``theta`` grid in the basin of a shaft too stiff
        with almost no backlash: at 40 dB on a light load two of 40 fits ended at 3.5 %
        and 6.3 % of the true ``theta``, their residuals' lag-1 autocorrelation 0.24;
        from their own linear parameters the grid finds the truth's basin (``theta``
        within 0.2 %; ``benchmarks/robustness_joint.py --trials 40 --seed 21
        --scenarios 4,5,7,8``; one trial is a test). Costs nothing where the model
        fits. Not run when, with white noise modelled, the noise itself is
        coloured (``held_noise_lag1_`` beyond the same limits): the second search
        cannot whiten it (the :class:`~backlashkit.errors.CorrelatedResidualsWarning`
        then says to use ``ARNoise``).
    interval : ProfileLikelihood, FisherInterval or ParametricBootstrap, optional
        Where ``ci95_`` (and, for the bootstrap, ``std_``) comes from (module
        :mod:`backlashkit.identify.intervals`; default ``ProfileLikelihood()``). The profile
        search can move the estimate: a held-theta refit more than
        :data:`RECENTRE_MARGIN` below the estimate's cost restarts the final
        refinement from there.
    noise_model : WhiteNoise, ARNoise or AutoNoise, optional
        The measurement noise (module :mod:`backlashkit.identify.noise`; default
        ``AutoNoise()``: ``ARNoise(2)`` where the speeds' own noise is coloured on the
        level held before the step-down, ``WhiteNoise()`` otherwise; ``noise_model_``
        says which). ``ARNoise(order)`` whitens the residuals by an
        autoregressive model fitted to them: for filtered speed measurements, whose
        noise is correlated from sample to sample and makes the white-noise interval
        too narrow (``benchmarks/colored_noise.py``; README, "Coloured noise"). It
        needs the whole records (``final_horizon=None``) and estimated noise levels
        (``noise=None``).
    final_horizon : float or None, optional
        Horizon in s of the final refinement, the noise re-estimation and the
        uncertainty, after the start of each record and after every torque jump
        (default None: the whole record). Where the shaft rattles (light loads, dozens
        of impacts per record) the whole-record likelihood is not regular at the scale
        of the standard error and its Fisher interval is too narrow; a short final
        horizon keeps it closer to regular, at the price of a larger standard error
        (95 % coverage 92.9 % against 89.8 % over 324 simulated trials, README, "Away
        from paper A's drive"; ``benchmarks/robustness_joint.py --final-horizon``).
    workers : int, optional
        Threads for the simulations (default all cores).

    Attributes
    ----------
    theta_ : float
        Estimate of the backlash half-width in rad.
    params_ : dict of str to float
        The six linear parameters after refinement (fixed ones at the prior).
    drive_ : TwoMassDrive
        The identified drive (``params_`` with ``theta_``).
    estimated_ : tuple of str
        Names of the estimated parameters, ``theta`` first.
    std_ : float
        Standard error of ``theta_`` in rad: Gauss-Newton / Fisher information, or the
        parametric bootstrap's with ``interval=ParametricBootstrap(...)``.
    ci95_ : tuple of float
        95 % interval of ``theta`` in rad: the profile-likelihood interval (possibly
        asymmetric), ``theta_ -+ 1.96 std_`` (Fisher), or ``theta_ -+ q std_`` with
        Student's ``q`` for the bootstrap's ``n_resamples - 1`` degrees of freedom (the
        last two cut at 0: ``theta`` is a half-width).
    ci95_bounded_ : tuple of bool
        Whether each end of the profile interval was reached: False for an end the
        profile did not rise to the 95 % level within ``max_factor`` of ``theta_``
        (the end is then the last point searched; the records hardly bound ``theta``
        on that side). Always ``(True, True)`` for the other intervals.
    interval_ : str
        ``"profile"``, ``"fisher"`` or ``"bootstrap"``: where ``ci95_`` comes from.
    profile_ : numpy.ndarray or None
        The profile likelihood where the interval search evaluated it: rows
        ``(theta, rise)`` sorted by ``theta``, ``rise`` the refit's cost minus
        ``cost_`` in chi-square units (``(theta_, 0)`` included); None for the other
        intervals. The report plots it.
    bootstrap_thetas_ : numpy.ndarray or None
        The refitted ``theta`` of every bootstrap resample (None without bootstrap).
    param_std_ : dict of str to float
        Fisher standard error of every estimated parameter (``theta`` included).
    covariance_ : numpy.ndarray
        Covariance of the estimated parameters (natural units, order ``estimated_``).
    noise_std_ : numpy.ndarray
        Noise standard deviation per record and channel ``(w_M, w_L)`` in rad/s,
        shape ``(n_records, 2)`` (with ``ARNoise``: of the noise, not of its
        innovation).
    noise_innovation_std_ : numpy.ndarray
        Standard deviation of the white innovation of the noise per record and channel
        in rad/s, the weight of the residuals (equal to ``noise_std_`` for white
        noise).
    noise_ar_ : numpy.ndarray or None
        ``ARNoise``: coefficients ``a_1 .. a_p`` of ``A(q)`` per record and channel,
        shape ``(n_records, 2, p)``; None for white noise.
    residual_lag1_ : numpy.ndarray
        Lag-1 autocorrelation of the residuals the likelihood treats as white (whitened
        by ``A(q)`` with ``ARNoise``) per record and channel, shape ``(n_records, 2)``:
        about 0 (within a few ``1 / sqrt(N)``) when the noise model fits; above
        :data:`CORRELATED_LAG1` in magnitude :meth:`fit` warns
        (:meth:`correlation_message`).
    fit_percent_ : numpy.ndarray
        NRMSE fit ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` per record and channel,
        shape ``(n_records, 2)``.
    residuals_ : list of tuple of numpy.ndarray
        ``(w_M - w_M_hat, w_L - w_L_hat)`` per record over the simulated span (to the
        end of the record, also with ``final_horizon``).
    cost_ : float
        Weighted sum of squared residuals (over ``final_horizon``, if given; whitened
        with ``ARNoise``) plus the prior penalty at the optimum.
    theta_starts_ : list of float
        The starting values of ``theta`` refined.
    theta_two_step_ : float or None
        Paper A's two-step estimate when it succeeded.
    theta_ini_ : float or None
        Its pre-estimate (eq. 6, mean over the records) when it succeeded.
    model_start_ : list of str
        ``"rest"`` or ``"steady"`` per record: how the model was started.
    commutations_ : list of tuple
        ``(t_s, t_c, t_b)`` per record in s: the torque step-down and, in the
        **identified model** simulated over the fitted span, its first contact loss
        after ``t_s`` and the next contact made (the instants eq. 9 of paper A looks
        for, located by the model's event detection between samples rather than on
        the sampled load speed); ``None`` for an instant that does not occur (or
        every entry when the record has no step-down).
    ambiguous_ : bool
        True when the continuation paths ended in distinct minima of nearly equal cost
        (``ambiguity_starts``): the likelihood is multimodal on these records, and the
        estimate deserves a second look (e.g. a parametric bootstrap or a longer
        record). It is no general warning of a miss: in ``benchmarks/robustness_joint.py
        --trials 20 --seed 5``, 18 of 540 fits were ambiguous and 3 of the 28 intervals
        that missed the truth were among them.
    t_c_, t_b_ : list of float or None
        The ``t_c`` and ``t_b`` of ``commutations_``.
    misfit_restarted_ : bool
        Whether the first fit's residuals triggered the second search
        (``misfit_restart``).
    misfit_restart_won_ : bool
        Whether the second search's fit was kept (every fitted attribute then comes
        from it, ``theta_starts_`` and the two-step estimates included).
    held_noise_lag1_ : numpy.ndarray
        Lag-1 autocorrelation of each record's speed noise ``(n_records, 2)``
        (``w_M``, ``w_L``) on the last :data:`HELD_NOISE_SECONDS` of the level held
        before the step-down (from :data:`HELD_RINGING_DECAYS` ringing time constants
        after its start: 7 s on paper A's drive), from the speeds alone (their first
        differences' lag-1 autocorrelation ``r_1`` gives ``1 + 2 r_1``; white noise
        about 0 within ``1.4 / sqrt(n)``): whether the noise itself is coloured,
        whatever the model (a speed still ringing there reads high; NaN above 2).
        NaN where the record holds no level of :data:`HELD_NOISE_MIN` samples.
    noise_model_ : WhiteNoise or ARNoise
        The noise model fitted: ``noise_model``, or what ``AutoNoise`` chose.
    far_from_prior_ : list of str
        The estimated linear parameters more than
        :data:`~backlashkit.identify.FAR_FROM_PRIOR` times off the prior (either way);
        when any, :meth:`fit` emits a
        :class:`~backlashkit.errors.PriorMismatchWarning` (wrong units or columns
        are far likelier than a prior that wrong).
    """

    method = "joint"

    def __init__(
        self,
        prior: TwoMassDrive,
        *,
        prior_rel_std: None | float | Mapping[str, float] = None,
        noise: tuple[float, float] | None = None,
        start: str = "auto",
        pre_window: float = 2.0,
        law: str = "paper",
        theta_max: float = float(np.deg2rad(15.0)),
        n_grid: int = 61,
        n_starts: int = 3,
        two_step_start: bool = True,
        noise_iter: int = 1,
        fd_step: float = 1e-6,
        screen_iter: int = 10,
        horizons: Sequence[float] = (0.15, 0.4, 1.0, 3.0),
        fine_horizons: Sequence[float] = (0.25, 0.6, 1.6),
        n_continue: int = 3,
        ambiguity_starts: int = 4,
        max_iter: int = 40,
        stiffness_grid: int = 1,
        stiffness_span: float = 1.6,
        split_shifts: Sequence[float] = (0.5,),
        search_factor: float | None = 3.0,
        stiffness_restarts: Sequence[float] = (0.15, 0.4, 0.8),
        friction_restarts: Sequence[float] = (1.0,),
        misfit_restart: bool = True,
        interval: ProfileLikelihood | FisherInterval | ParametricBootstrap = _PROFILE,
        noise_model: WhiteNoise | ARNoise | AutoNoise = _AUTO,
        final_horizon: float | None = None,
        workers: int | None = None,
    ) -> None:
        self.prior = prior
        self.prior_rel_std = prior_rel_std
        self.noise = noise
        self.start = start
        self.pre_window = pre_window
        self.law = law
        self.theta_max = theta_max
        self.n_grid = n_grid
        self.n_starts = n_starts
        self.two_step_start = two_step_start
        self.noise_iter = noise_iter
        self.fd_step = fd_step
        self.screen_iter = screen_iter
        self.horizons = horizons
        self.fine_horizons = fine_horizons
        self.n_continue = n_continue
        self.ambiguity_starts = ambiguity_starts
        self.max_iter = max_iter
        self.stiffness_grid = stiffness_grid
        self.stiffness_span = stiffness_span
        self.split_shifts = split_shifts
        self.search_factor = search_factor
        self.stiffness_restarts = stiffness_restarts
        self.friction_restarts = friction_restarts
        self.misfit_restart = misfit_restart
        self.final_horizon = final_horizon
        self.interval = interval
        self.noise_model = noise_model
        self.workers = workers

    # -- validation ------------------------------------------------------------------
    def _check(self) -> None:
        from .record import check_prior

        check_prior(self.prior)
        if self.start not in ("auto", "rest", "steady"):
            raise InputError(f"start must be 'auto', 'rest' or 'steady', got {self.start!r}")
        v.positive("pre_window", self.pre_window)
        v.positive("theta_max", self.theta_max)
        v.integer("n_grid", self.n_grid, 2)
        for name in ("two_step_start", "misfit_restart"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InputError(f"{name} must be True or False, got {getattr(self, name)!r}")
        v.integer("n_starts", self.n_starts, 1)
        v.integer("n_continue", self.n_continue, 1)
        v.integer("ambiguity_starts", self.ambiguity_starts, 0)
        v.integer("noise_iter", self.noise_iter, 0)
        v.integer("screen_iter", self.screen_iter, 1)
        v.integer("max_iter", self.max_iter, 1)
        v.integer("stiffness_grid", self.stiffness_grid, 1)
        if not v.positive("stiffness_span", self.stiffness_span) > 1.0:
            raise InputError(
                f"stiffness_span must be > 1 (a factor), got {self.stiffness_span!r}"
            )
        _check_positive_sequence("split_shifts", self.split_shifts)
        _check_positive_sequence("stiffness_restarts", self.stiffness_restarts)
        _check_positive_sequence("friction_restarts", self.friction_restarts)
        _check_positive_sequence("fine_horizons", self.fine_horizons)
        if not isinstance(self.interval, (ProfileLikelihood, FisherInterval,
                                          ParametricBootstrap)):
            raise InputError(
                "interval must be a ProfileLikelihood, FisherInterval or ParametricBootstrap "
                f"(backlashkit.identify.intervals), got {type(self.interval).__name__}"
            )
        if not isinstance(self.noise_model, (WhiteNoise, ARNoise, AutoNoise)):
            raise InputError(
                "noise_model must be a WhiteNoise, ARNoise or AutoNoise "
                f"(backlashkit.identify.noise), got {type(self.noise_model).__name__}"
            )
        if isinstance(self.noise_model, ARNoise):
            if self.noise is not None:
                raise InputError(
                    "noise=(s_M, s_L) fixes white noise levels; with noise_model=ARNoise(...) "
                    "the noise is estimated from the residuals: give one or the other"
                )
            if self.final_horizon is not None:
                raise InputError(
                    "noise_model=ARNoise(...) whitens the residuals of whole records; it "
                    f"cannot be combined with final_horizon (got {self.final_horizon!r})"
                )
        if self.search_factor is not None and not (
            v.positive("search_factor", self.search_factor) > 1.0
        ):
            raise InputError(
                f"search_factor must be > 1 (a factor) or None, got {self.search_factor!r}"
            )
        if self.final_horizon is not None:
            v.positive("final_horizon", self.final_horizon)
        step = v.positive("fd_step", self.fd_step)
        if not step < 0.1:
            raise InputError(f"fd_step must be < 0.1 (a relative step), got {self.fd_step!r}")
        if self.noise is not None:
            try:
                s_m, s_l = self.noise
            except (TypeError, ValueError):
                raise InputError(
                    f"noise must be a pair (s_M, s_L) of noise std in rad/s, got {self.noise!r}"
                ) from None
            v.positive("noise[0] (s_M)", s_m)
            v.positive("noise[1] (s_L)", s_l)

    # -- fit -------------------------------------------------------------------------
    def fit(self, records) -> JointIdentifier:
        """Identify ``theta`` and the uncertain linear parameters.

        Parameters
        ----------
        records : Record, tuple or sequence of them
            Experiments (each a :class:`~backlashkit.identify.Record` or a tuple
            ``(t, torque, w_motor, w_load)``); all are fitted jointly, e.g. paper A's
            step 1 and step 2 records together.

        Returns
        -------
        JointIdentifier
            ``self``, fitted.

        Raises
        ------
        InputError
            If a parameter is invalid or a record cannot be used (message names it).

        Warns
        -----
        CorrelatedResidualsWarning
            If a residual is too correlated for the interval
            (:meth:`correlation_message`).
        PriorMismatchWarning
            If a linear parameter ends far from the prior (``far_from_prior_``).
        """
        self._check()
        # one BLAS thread: the products J^T J (n_samples x 7) gain nothing from more,
        # and their rounding then does not depend on the machine's core count (the
        # multimodal fits of a rattling load can follow a different path on it)
        # overflowing trial points cost inf and are rejected by the search: no warning
        with warnings.catch_warnings(), threadpool_limits(limits=1, user_api="blas"), \
                np.errstate(over="ignore", invalid="ignore"):
            warnings.simplefilter("ignore", SensitivityWarning)
            self._fit(records)
            self.misfit_restarted_ = False
            self.misfit_restart_won_ = False
            if self.misfit_restart and self._misfit():
                self._search_again(records)
        message = self.correlation_message()
        if message is not None:
            warnings.warn(message, CorrelatedResidualsWarning, stacklevel=2)
        self.far_from_prior_ = [name for name in self.estimated_[1:]
                                if is_far(self.params_[name] / getattr(self.prior, name))]
        if self.far_from_prior_:
            ratios = ", ".join(f"{name} x{self.params_[name] / getattr(self.prior, name):.3g}"
                               for name in self.far_from_prior_)
            warnings.warn(
                f"the fit moved {ratios} from the prior: check the units of the speeds "
                "(rpm read as rad/s?) and of the time, the columns (w_motor and w_load "
                "swapped?) and the prior", PriorMismatchWarning, stacklevel=2)
        return self

    def _misfit(self) -> bool:
        """Whether a residual is too correlated for noise (:data:`MISFIT_LAG1`,
        :data:`MISFIT_SIGMAS`)."""
        if not _beyond_noise(self.residual_lag1_, 1.0 / np.sqrt(self._lag1_samples)):
            return False
        return self.noise_ar_ is not None or not self._noise_coloured()

    def _noise_coloured(self) -> bool:
        """Whether the speeds' own noise (``held_noise_lag1_``) is correlated beyond
        :data:`MISFIT_LAG1` and ``MISFIT_SIGMAS`` of its std under white noise."""
        return _beyond_noise(np.nan_to_num(self.held_noise_lag1_),
                             1.4 / np.sqrt(self._held_samples)[:, np.newaxis])

    def _search_again(self, records) -> None:
        """The whole search once more from the fitted linear parameters; the fit of
        higher likelihood is kept (``misfit_restart``)."""
        first = dict(self.__dict__)
        try:
            self._fit(records, anchor=self.drive_)
        except InputError:  # e.g. a model that explains nothing from there
            won = False
        else:
            won = self._neg2_loglik < first["_neg2_loglik"] - MISFIT_MARGIN
        if not won:
            self.__dict__.update(first)
        self.misfit_restarted_ = True
        self.misfit_restart_won_ = won

    def correlation_message(self) -> str | None:
        """Say whether the residuals of the fit are too correlated for its interval.

        Returns
        -------
        str or None
            A sentence naming the record and speed whose residual (whitened, with
            :class:`~backlashkit.identify.noise.ARNoise`) has the largest lag-1
            autocorrelation, when it exceeds :data:`CORRELATED_LAG1` in magnitude
            (then the standard error and interval of ``theta`` are too narrow), and
            whether the noise or the model is to blame (``held_noise_lag1_``); None
            otherwise. :meth:`fit` emits it as a
            :class:`~backlashkit.errors.CorrelatedResidualsWarning`.
        """
        lag1 = self.residual_lag1_
        k, c = np.unravel_index(int(np.argmax(np.abs(lag1))), lag1.shape)
        rho = float(lag1[k, c])
        if not abs(rho) > CORRELATED_LAG1:
            return None
        what = ("the noise is not white" if self.noise_ar_ is None else
                f"ARNoise(order={self.noise_ar_.shape[-1]}) does not whiten the noise")
        fix = ("fit with noise_model=ARNoise()" if self.noise_ar_ is None else
               "raise the order")
        held = self.held_noise_lag1_[k, c]
        if self.noise_ar_ is None and np.isfinite(held) and not self._noise_coloured():
            # the speeds' own noise is white: the residual's correlation is the model's
            what = (f"the model misfits, since the noise itself is white (lag-1 {held:.2f} "
                    "on the level held before the step-down)")
            fix = ("check the prior (a wrong basin of the fit) and whether a two-mass drive "
                   "with backlash describes the record; ARNoise would hide the misfit")
        return (f"the residual of {('w_M', 'w_L')[c]} in {self._record_names[k]} (record "
                f"{k + 1}) has lag-1 "
                f"autocorrelation {rho:.2f} (white noise: about 0): {what}, so the standard "
                f"error and interval of theta are too narrow; {fix}")

    def _fit(self, records, anchor: TwoMassDrive | None = None) -> JointIdentifier:
        """One search and refinement; ``anchor`` replaces the prior as the search's
        starting point (grid, box, two-step start), not in the penalty."""
        prior = self.prior.with_theta(None)
        recs = as_records(records, prior=prior)
        ts_max = max(r.ts for r in recs)
        if self.final_horizon is not None and self.final_horizon < MIN_FINAL_SAMPLES * ts_max:
            raise InputError(
                f"final_horizon must span at least {MIN_FINAL_SAMPLES} samples "
                f"({MIN_FINAL_SAMPLES * ts_max:.3g} s at Ts = {ts_max:.3g} s), got "
                f"{self.final_horizon!r}"
            )
        # the speeds' own noise, before any model: AutoNoise chooses from it
        self.held_noise_lag1_, self._held_samples = _held_noise_lag1(recs, prior)
        self.noise_model_ = self.noise_model
        if isinstance(self.noise_model, AutoNoise):
            coloured = (self.noise is None and self.final_horizon is None
                        and self._noise_coloured())
            self.noise_model_ = ARNoise(self.noise_model.order) if coloured else WhiteNoise()
        rel = _rel_std(self.prior_rel_std, LINEAR_PARAMS)
        free = [n for n in LINEAR_PARAMS if n in rel and getattr(prior, n) > 0]
        names = ("theta", *free)
        if self.noise is not None:
            fixed_noise = np.array(self.noise, float)
            sig0 = [fixed_noise] * len(recs)
        else:
            fixed_noise = None
            sig0 = [np.array([_noise_hp(r.w_motor), _noise_hp(r.w_load)]) for r in recs]
        spans = _spans(recs, self.start, float(self.pre_window), sig0)
        # one noise level per record and channel (the records may differ in SNR)
        sigma = np.array(sig0, float).reshape(len(recs), 2)
        scale = [max(float(np.max(np.abs(r.w_motor))), float(np.max(np.abs(r.w_load))))
                 for r in recs]
        sigma = np.maximum(sigma, 1e-9 * np.array(scale)[:, np.newaxis] + 1e-300)
        p_prior = np.array([getattr(prior, n) for n in free])
        pen = np.array([rel[n] if rel[n] is not None else np.inf for n in free])

        screen = _screen_spans(spans)

        base = np.array([getattr(prior, n) for n in PACKED[:-1]] + [0.0])
        cols = [PACKED.index(n) for n in names]

        def model(z_rows: np.ndarray, spans_: list[_Span],
                  ends: list[int] | None = None) -> list[np.ndarray]:
            p = np.repeat(base[np.newaxis, :], len(z_rows), axis=0)
            p[:, cols] = np.exp(z_rows)
            return [_simulate(p, sp, self.law, self.workers, None if ends is None else ends[k])
                    for k, sp in enumerate(spans_)]

        def selection(spans_: list[_Span], horizon: float | None) -> list[np.ndarray]:
            """Samples within ``horizon`` s after the span start and every torque jump."""
            out = []
            for sp in spans_:
                if horizon is None:  # a slice: views, not copies, of the long arrays
                    out.append(slice(0, sp.t.size))
                    continue
                u = sp.torque
                scale = max(float(np.max(np.abs(u))), 1e-300)
                jumps = np.r_[0, 1 + np.flatnonzero(np.abs(np.diff(u)) > 1e-9 * scale)]
                keep = np.zeros(sp.t.size, bool)
                width = max(2, int(round(horizon / sp.record.ts)))
                for j in jumps:
                    keep[j : j + width] = True
                out.append(np.flatnonzero(keep))
            return out

        def make_residual(spans_: list[_Span], horizon: float | None, sig: np.ndarray,
                          ar: np.ndarray | None = None):
            """Weighted residual rows; with ``ar`` (record, channel, lag) each channel's
            residual is whitened by ``A(q)`` first (``sig``: innovation std then)."""
            sels = selection(spans_, horizon)
            sizes = [s_.stop if isinstance(s_, slice) else s_.size for s_ in sels]
            ends = [s_.stop if isinstance(s_, slice) else int(s_[-1]) + 1 for s_ in sels]
            lag = 0 if ar is None else ar.shape[-1]  # samples without a past, dropped
            n_res = 2 * sum(m - lag for m in sizes) + len(free)
            ys = [(sp.y_m[s_], sp.y_l[s_]) for sp, s_ in zip(spans_, sels, strict=True)]

            def rows(z_rows: np.ndarray) -> np.ndarray:
                sims = model(z_rows, spans_, ends)
                out = np.empty((len(z_rows), n_res))
                pos = 0
                for sp, y2, s_, x, m in zip(spans_, ys, sels, sims, sizes, strict=True):
                    for c, y in enumerate(y2):  # w_M, then w_L
                        block = out[:, pos : pos + m - lag]
                        if ar is None:
                            np.subtract(y, x[:, s_, c], out=block)
                        else:
                            block[:] = whiten(y - x[:, s_, c], ar[sp.k, c])
                        block /= sig[sp.k, c]
                        pos += m - lag
                p = np.exp(z_rows[:, 1:])
                out[:, pos:] = (p - p_prior) / (pen * p_prior)  # 0 where no penalty
                return out

            return rows

        h = float(self.fd_step)
        n = len(names)

        def lm_on(rows, z0: np.ndarray, max_iter: int, bounds=None,
                  state: _LMState | None = None) -> _LMState:
            def fun(z: np.ndarray) -> np.ndarray:
                try:
                    return rows(z[np.newaxis, :])[0]
                except ValueError:  # e.g. a step to a mode too fast for the sample time
                    return np.full(1, np.inf)

            def jac(z: np.ndarray, r: np.ndarray) -> np.ndarray:
                # forward differences while iterating (half the simulations of central
                # ones); the uncertainty uses central differences (below)
                zz = np.repeat(z[np.newaxis, :], n, axis=0) + h * np.eye(n)
                return ((rows(zz) - r) / h).T

            return _lm(fun, jac, z0, max_iter=max_iter, bounds=bounds, state=state)

        def central_jacobian(rows, z: np.ndarray) -> np.ndarray:
            zz = np.repeat(z[np.newaxis, :], 2 * n, axis=0)
            for i in range(n):
                zz[2 * i, i] += h
                zz[2 * i + 1, i] -= h
            rr = rows(zz)
            return ((rr[0::2] - rr[1::2]) / (2 * h)).T

        horizons = [None if x is None else float(x) for x in self.horizons]
        if not horizons or horizons[-1] is not None:
            horizons.append(None)
        # 1. coarse grid in theta on the first horizon, linear parameters at the prior
        rows0 = make_residual(screen, horizons[0], sigma)
        grid = np.linspace(self.theta_max / self.n_grid, self.theta_max, self.n_grid)
        z_prior = np.log(p_prior if anchor is None
                         else np.array([getattr(anchor, n_) for n_ in free]))
        start_drive = prior if anchor is None else anchor.with_theta(None)
        # the stiffness sets the ringing frequency: a wrong prior k_sh shifts its phase
        # by periods within the first horizon, so k_sh is gridded too (rows)
        k_scales = [1.0]
        if "k_sh" in free and self.stiffness_grid > 1:
            k_scales = np.geomspace(1.0 / self.stiffness_span, self.stiffness_span,
                                    self.stiffness_grid)
        blocks = []
        for ks in k_scales:
            zk = z_prior.copy()
            if "k_sh" in free:
                zk[free.index("k_sh")] += math.log(ks)
            blocks.append(np.column_stack([np.log(grid), np.tile(zk, (grid.size, 1))]))
        zg = np.concatenate(blocks)
        costs = np.sum(rows0(zg) ** 2, axis=1).reshape(len(k_scales), grid.size)
        pad = np.pad(costs, 1, constant_values=np.inf)
        is_min = ((costs <= pad[1:-1, :-2]) & (costs <= pad[1:-1, 2:])
                  & (costs <= pad[:-2, 1:-1]) & (costs <= pad[2:, 1:-1]))
        minima = np.flatnonzero(is_min.ravel())
        minima = minima[np.argsort(costs.ravel()[minima])][: self.n_starts]
        z_starts = [zg[i] for i in minima]
        starts = [float(math.exp(z[0])) for z in z_starts]
        self.theta_two_step_ = None
        self.theta_ini_ = None
        if self.two_step_start:
            try:
                with warnings.catch_warnings():  # a start only; far_from_prior_ says it
                    warnings.simplefilter("ignore", PriorMismatchWarning)
                    ts_est = TwoStepIdentifier(start_drive, workers=self.workers).fit(recs)
                self.theta_two_step_ = float(ts_est.theta_)
                self.theta_ini_ = float(ts_est.theta_ini_)
                starts.append(self.theta_two_step_)
                z_starts.append(np.concatenate([[math.log(self.theta_two_step_)], z_prior]))
            except InputError:
                pass
        # 2. every start refined on the first horizon; the best continued on growing
        #    horizons (the lightly damped ringing makes long windows multimodal)
        box = None  # the screening stays within search_factor of the prior
        if self.search_factor is not None:
            fb = math.log(float(self.search_factor))
            box = (np.r_[math.log(self.theta_max * 1e-3), z_prior - fb],
                   np.r_[math.log(self.theta_max), z_prior + fb])
        states = [lm_on(rows0, z0, self.screen_iter, box) for z0 in z_starts]
        states.sort(key=lambda st: st.cost)
        # the short horizons fix the sums J_M + J_L, f_M + f_L and the ringing frequency
        # well but not how they split: restart the best start from other splits
        variants = [_resplit(states[0].z, free, pair, d)
                    for pair in (("J_M", "J_L"), ("f_M", "f_L"))
                    for x in self.split_shifts for d in (-x, x)]
        variants = [z for z in variants if z is not None]
        if variants:
            states += [lm_on(rows0, z, self.screen_iter, box) for z in variants]
            states.sort(key=lambda st: st.cost)
        sig_now = sigma
        # continue up to n_continue distinct solutions whose first-horizon cost is
        # within CONTINUE_RATIO of the best one (the others are hopeless, and several
        # starts often converge to one point)
        cands: list[_LMState] = []
        for st in states:
            if len(cands) == self.n_continue or st.cost > CONTINUE_RATIO * states[0].cost:
                break
            if all(np.max(np.abs(st.z - c_.z)) > SAME_POINT for c_ in cands):
                cands.append(st)
        # two continuation paths, the second with finer steps and from the best
        # candidate only (the cost of all of them did not pay): a long step can jump to
        # the wrong basin where the ringing is rich (a light load), a short one
        # elsewhere; their end points compete below (on the same last horizon)
        short = horizons[:-1]
        paths = [short[1:]]
        if len(short) > 1:
            fine = sorted(set(short[1:]) | {float(x) for x in self.fine_horizons
                                            if short[0] < x < short[-1]})
            if fine != short[1:]:
                paths.append(fine)
        rows_at: dict = {}

        def continued(path: list[float], states_: list[_LMState]) -> list[_LMState]:
            for hz in path:
                if hz not in rows_at:
                    rows_at[hz] = make_residual(screen, hz, sig_now)
                states_ = [lm_on(rows_at[hz], st.z, self.max_iter) for st in states_]
            return states_

        ends: list[_LMState] = []
        for k_path, path in enumerate(paths):
            ends += continued(path, cands if k_path == 0 else cands[:1])
        # distinct end points of nearly equal cost: the landscape is multimodal here, so
        # continue more first-horizon solutions (more grid minima among their starts)
        self.ambiguous_ = bool(len(paths[0]) and _basins(ends) > 1)
        if self.ambiguity_starts and self.ambiguous_:
            more = np.flatnonzero(is_min.ravel())
            more = more[np.argsort(costs.ravel()[more])]
            more = more[self.n_starts : self.n_starts + self.ambiguity_starts]
            states += [lm_on(rows0, zg[i], self.screen_iter, box) for i in more]
            states.sort(key=lambda st: st.cost)
            extra: list[_LMState] = []
            for st in states:
                if len(extra) == self.ambiguity_starts:
                    break
                if all(np.max(np.abs(st.z - c_.z)) > SAME_POINT for c_ in cands + extra):
                    extra.append(st)
            ends += continued(paths[0], extra)
        cands = ends
        # the whole record (the expensive stage) only for distinct candidates whose cost
        # on the longest short horizon is within WHOLE_RECORD_MARGIN of the best: that
        # cost ranks the candidates as the whole record does (differences of 79, 130 and
        # 5179 became 79, 126 and 5202 in the robustness study's failures)
        cands.sort(key=lambda st: st.cost)
        kept: list[_LMState] = []
        for st in cands:
            if st.cost > cands[0].cost + WHOLE_RECORD_MARGIN:
                break
            if all(np.max(np.abs(st.z - k_.z)) > SAME_POINT for k_ in kept):
                kept.append(st)
        final_h = None if self.final_horizon is None else float(self.final_horizon)
        final_spans = spans if final_h is None else screen  # screen: skips the holds
        rows_full = make_residual(final_spans, final_h, sig_now)
        finals = [lm_on(rows_full, st.z, self.max_iter) for st in kept]
        best = min(finals, key=lambda st: st.cost)
        # the final cost is multimodal in the phase of the ringing: restart the best
        # solution with the stiffness shifted, on the longest short horizon (cheap, and
        # it ranks solutions as the final data do); a few iterations tell a restart
        # falling into a better basin from one climbing back; refine on the final data
        # only the restarts that beat the best there, keep what lowers the final cost
        # (and with the friction split shifted: f_M + f_L is pinned by the whole record,
        # f_M : f_L only by the passages through the backlash)
        restarts = [("k_sh", d_) for x in self.stiffness_restarts for d_ in (-x, x)
                    if "k_sh" in free]
        restarts += [("f_M:f_L", d_) for x in self.friction_restarts for d_ in (-x, x)]
        if restarts and len(horizons) > 1:
            rows_short = make_residual(screen, horizons[-2], sig_now)
            ref = lm_on(rows_short, best.z, self.max_iter)
            for kind, d_ in restarts:  # each from the best solution so far
                if kind == "k_sh":
                    z0 = best.z.copy()
                    z0[1 + free.index("k_sh")] += d_
                else:
                    z0 = _resplit(best.z, free, ("f_M", "f_L"), d_)
                    if z0 is None:
                        continue
                st = lm_on(rows_short, z0, min(RESTART_SCREEN_ITER, self.max_iter))
                if not st.cost < ref.cost:
                    continue
                if not st.done:
                    st = lm_on(rows_short, st.z, self.max_iter - RESTART_SCREEN_ITER,
                               state=st)
                if st.cost < ref.cost - RESTART_MARGIN:
                    st = lm_on(rows_full, st.z, self.max_iter)
                    if st.cost < best.cost:
                        best = st
        for _ in range(self.noise_iter if fixed_noise is None else 0):
            r = best.r
            sq, count, pos = np.zeros_like(sig_now), np.zeros(len(recs)), 0
            for sp, s_ in zip(final_spans, selection(final_spans, final_h), strict=True):
                m = s_.stop if isinstance(s_, slice) else s_.size
                sq[sp.k] += (np.sum(r[pos : pos + m] ** 2), np.sum(r[pos + m : pos + 2 * m] ** 2))
                count[sp.k] += m
                pos += 2 * m
            sig_now = np.maximum(sig_now * np.sqrt(sq / count[:, np.newaxis]), 1e-300)
            best = lm_on(make_residual(final_spans, final_h, sig_now), best.z, self.max_iter)
        ar = None
        if isinstance(self.noise_model_, ARNoise):
            # whiten by A(q) fitted to the residuals, refit; repeated noise_iter times
            sig_now = sig_now.copy()  # the earlier stages' residual functions keep theirs
            for _ in range(max(1, self.noise_iter)):
                sims_f = model(best.z[np.newaxis, :], final_spans)
                ar = np.empty((len(recs), 2, self.noise_model_.order))
                for sp, x in zip(final_spans, sims_f, strict=True):
                    for c, y in enumerate((sp.y_m, sp.y_l)):
                        ar[sp.k, c], var = fit_ar(y - x[0, :, c], self.noise_model_.order)
                        sig_now[sp.k, c] = math.sqrt(max(var, 1e-300))
                best = lm_on(make_residual(final_spans, final_h, sig_now, ar), best.z,
                             self.max_iter)
        # a model that explains a speed worse than its mean has fitted nothing: say so
        # before the uncertainty (whose refits at such a point can take minutes)
        checked_z, sims = best.z, model(best.z[np.newaxis, :], spans)
        _refuse_unexplained(recs, _residuals_and_fit(spans, sims)[1])
        sigma = sig_now
        rows_unc = make_residual(final_spans, final_h, sig_now, ar)
        profiled = None
        for k_centre in range(RECENTRE_MAX + 1):
            z = best.z
            # uncertainty: Gauss-Newton information (the prior's rows are in the residual)
            jz = central_jacobian(rows_unc, z)
            info = jz.T @ jz
            try:
                cov_z = np.linalg.inv(info)
            except np.linalg.LinAlgError:
                cov_z = np.linalg.pinv(info)
            if not isinstance(self.interval, ProfileLikelihood):
                break
            profiled = self._profile(rows_unc, z, cov_z, float(best.cost))
            if k_centre == RECENTRE_MAX or profiled.lowest_rise > -RECENTRE_MARGIN:
                break
            # a held-theta refit ended below the estimate's cost: the refinement had
            # stopped on a bump of a rough likelihood; continue from that refit
            st = lm_on(rows_unc, profiled.lowest_z, self.max_iter)
            if st.cost > best.cost - RECENTRE_MARGIN:
                break
            best = st
        values = np.exp(z)
        cov = cov_z * np.outer(values, values)  # delta method: dp = p dz
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        drive = _drive(prior, names, values)
        if z is not checked_z:  # the profile search re-centred the estimate
            sims = model(z[np.newaxis, :], spans)
        self.residuals_, fits = _residuals_and_fit(spans, sims)
        self.theta_ = float(values[0])
        self.std_ = float(std[0])
        # a half-width is >= 0: Fisher's symmetric interval is cut there
        self.ci95_ = (max(0.0, self.theta_ - 1.96 * self.std_), self.theta_ + 1.96 * self.std_)
        self.ci95_bounded_ = (True, True)
        self.params_ = {n_: float(getattr(drive, n_)) for n_ in LINEAR_PARAMS}
        self.drive_ = drive
        self.estimated_ = names
        self.param_std_ = dict(zip(names, (float(s) for s in std), strict=True))
        self.covariance_ = cov
        self.noise_innovation_std_ = np.asarray(sigma, float)
        self.noise_ar_ = ar
        self.noise_std_ = self.noise_innovation_std_
        self._record_names = [r.name for r in recs]
        # the residuals the likelihood treats as white, on the fitted samples only
        blocks: dict[tuple[int, int], list[np.ndarray]] = {}
        pos, lag = 0, 0 if ar is None else ar.shape[-1]
        for sp, s_ in zip(final_spans, selection(final_spans, final_h), strict=True):
            m = (s_.stop if isinstance(s_, slice) else s_.size) - lag
            for c in (0, 1):
                blocks.setdefault((sp.k, c), []).append(best.r[pos : pos + m])
                pos += m
        self.residual_lag1_ = np.zeros((len(recs), 2))
        self._lag1_samples = np.ones((len(recs), 2))
        # -2 log likelihood with the noise variances profiled out (up to a constant):
        # comparable between fits whose noise levels differ (misfit_restart)
        self._neg2_loglik = float(np.sum(best.r[pos:] ** 2))  # the prior's rows
        for (k, c), parts in blocks.items():
            e = np.concatenate(parts)
            self.residual_lag1_[k, c] = _lag1(e)
            self._lag1_samples[k, c] = max(e.size, 1)
            self._neg2_loglik += e.size * math.log(
                max(float(sigma[k, c]) ** 2 * float(np.mean(e**2)), 1e-300))
        if ar is not None:  # the noise's own std, not its innovation's
            self.noise_std_ = np.array([[float(np.std(e)) for e in pair]
                                        for pair in self.residuals_])
        self.fit_percent_ = fits
        self.cost_ = float(best.cost)
        self.theta_starts_ = starts
        self.model_start_ = ["rest" if sp.level is None else "steady" for sp in spans]
        self.commutations_ = [_model_commutation(drive, sp, self.law) for sp in spans]
        self.t_c_ = [c[1] for c in self.commutations_]
        self.t_b_ = [c[2] for c in self.commutations_]
        self.interval_ = "fisher"
        self.bootstrap_thetas_ = None
        self.profile_ = None
        if profiled is not None:
            self.ci95_, self.ci95_bounded_ = profiled.ci95, profiled.bounded
            self.profile_ = profiled.points
            self.interval_ = "profile"
        elif isinstance(self.interval, ParametricBootstrap):
            self._bootstrap(spans, [x[0] for x in sims])
        return self

    def _profile(self, rows, z: np.ndarray, cov_z: np.ndarray, cost: float) -> _Profiled:
        """Profile-likelihood interval of ``theta`` (:class:`ProfileLikelihood`)."""
        prof = self.interval
        assert isinstance(prof, ProfileLikelihood)
        n, h = z.size, float(self.fd_step)
        s_z = math.sqrt(cov_z[0, 0]) if cov_z[0, 0] > 0 else 0.0
        # the other log-parameters move with theta along the Fisher covariance: the
        # start of every held-theta refit (its exact optimum where the cost is quadratic)
        slope = cov_z[1:, 0] / cov_z[0, 0] if cov_z[0, 0] > 0 else np.zeros(n - 1)

        evaluated = [(0.0, z)]  # every refit: cost rise and log-parameters (estimate first)

        def side(sign: float):
            """The cost rise of the profile at distance ``d`` (log theta) on one side."""
            memo: dict[float, np.ndarray] = {}  # distance -> refitted other parameters

            def rise(d: float) -> float:
                zt = z[0] + sign * d

                def fun(w: np.ndarray) -> np.ndarray:
                    try:
                        return rows(np.r_[zt, w][np.newaxis, :])[0]
                    except ValueError:  # a step to a mode too fast for the sample time
                        return np.full(1, np.inf)

                if n == 1:  # theta alone is estimated: the profile is the cost itself
                    r = fun(np.empty(0))
                    evaluated.append((float(r @ r) - cost, np.array([zt])))
                    return evaluated[-1][0]

                def jac(w: np.ndarray, r: np.ndarray) -> np.ndarray:
                    ww = np.repeat(np.r_[zt, w][np.newaxis, :], n - 1, axis=0)
                    ww[:, 1:] += h * np.eye(n - 1)
                    return ((rows(ww) - r) / h).T

                if memo:  # continue from the nearest refit on this side
                    d0 = min(memo, key=lambda x: abs(x - d))
                    w0 = memo[d0] + slope * sign * (d - d0)
                else:
                    w0 = z[1:] + slope * sign * d
                st = _lm(fun, jac, w0, max_iter=prof.max_iter)
                memo[d] = st.z
                evaluated.append((st.cost - cost, np.r_[zt, st.z]))
                return evaluated[-1][0]

            return rise

        ends, bounded = [], []
        for sign in (-1.0, 1.0):
            d, ok = profile_crossing(side(sign), 1.96 * s_z if s_z > 0 else 0.05,
                                     tol=prof.tol, max_evaluations=prof.max_evaluations,
                                     largest=math.log(prof.max_factor))
            ends.append(math.exp(z[0] + sign * d))
            bounded.append(ok)
        lowest = min(evaluated, key=lambda e: e[0])
        points = np.array(sorted((math.exp(zz[0]), r) for r, zz in evaluated))
        return _Profiled((ends[0], ends[1]), (bounded[0], bounded[1]), points,
                         float(lowest[0]), lowest[1])

    def _bootstrap(self, spans: list[_Span], sims: list[np.ndarray]) -> None:
        """Refit ``interval.n_resamples`` records simulated from the estimate."""
        boot = self.interval
        assert isinstance(boot, ParametricBootstrap)
        root = boot.seed if isinstance(boot.seed, np.random.SeedSequence) else (
            np.random.SeedSequence(boot.seed))
        params = {name: getattr(self, name) for name in _INIT_NAMES}
        refit = JointIdentifier(**{**params, "interval": FisherInterval()})
        thetas = []
        for child in root.spawn(boot.n_resamples):
            rng = np.random.default_rng(child)
            records = []
            for sp, x in zip(spans, sims, strict=True):
                w_m, w_l = (x[:, c] + self._noise_sample(rng, sp.k, c, sp.t.size)
                            for c in (0, 1))
                records.append(Record(sp.t, sp.torque, w_m, w_l,
                                      name=f"{sp.record.name} (bootstrap)"))
            thetas.append(refit._fit(records).theta_)
        self.bootstrap_thetas_ = np.array(thetas)
        self.std_ = float(np.std(self.bootstrap_thetas_, ddof=1))
        # the std is itself estimated from n_resamples refits: Student's quantile with
        # n_resamples - 1 degrees of freedom, not 1.96 (2.05 for 30 refits, 2.57 for 6)
        from scipy.stats import t as student_t

        half = float(student_t.ppf(0.975, boot.n_resamples - 1)) * self.std_
        self.ci95_ = (max(0.0, self.theta_ - half), self.theta_ + half)
        self.interval_ = "bootstrap"


    def _noise_sample(self, rng: np.random.Generator, k: int, c: int, n: int) -> np.ndarray:
        """``n`` samples of the fitted noise of record ``k``, channel ``c``."""
        s = self.noise_innovation_std_[k, c]
        if self.noise_ar_ is None:
            return rng.normal(0.0, s, n)
        from scipy.signal import lfilter

        # start in the stationary regime: run in until the slowest pole decayed 1e-6
        a = self.noise_ar_[k, c]
        burn = _impulse_length(a, 1e-6)
        eps = rng.normal(0.0, s, n + burn)
        return lfilter([1.0], np.r_[1.0, a], eps)[burn:]


#: Names of :class:`JointIdentifier`'s hyperparameters (its ``__init__`` keywords).
_INIT_NAMES = tuple(n for n in inspect.signature(JointIdentifier.__init__).parameters
                    if n != "self")


def _model_commutation(drive: TwoMassDrive, span: _Span, law: str):
    """``(t_s, t_c, t_b)`` of the identified model on a span: the step-down and its first
    contact loss and the next contact made (``None`` for what does not happen)."""
    try:
        _, t_s, _, _ = find_step_down(span.record)
    except InputError:
        return (None, None, None)
    p = np.array([[getattr(drive, n) for n in PACKED]])
    x0 = _x0(p, span.level)[0]
    res = drive.simulate(span.t, span.torque, law=law, initial_state=x0)
    lost = next((e.time for e in res.events if e.time >= t_s and e.kind == "contact_lost"), None)
    made = None
    if lost is not None:
        made = next((e.time for e in res.events if e.time > lost and e.kind == "contact_made"),
                    None)
    return (float(t_s), None if lost is None else float(lost),
            None if made is None else float(made))


# --- Cramér-Rao bound ----------------------------------------------------------------


@dataclass(frozen=True)
class CramerRaoBound:
    """Cramér-Rao bound of an experiment.

    Parameters
    ----------
    names : tuple of str
        Estimated parameters, ``"theta"`` first.
    values : numpy.ndarray
        Their true values.
    fisher : numpy.ndarray
        Fisher information matrix in natural units (order ``names``), including the
        prior's information when one was given.
    noise_std : tuple of float
        White-noise standard deviations ``(s_M, s_L)`` in rad/s used.
    n_samples : int
        Samples per channel.

    Notes
    -----
    Fisher information of independent experiments adds: ``crb_a + crb_b`` is the bound
    for both experiments together (same parameter names).
    """

    names: tuple[str, ...]
    values: np.ndarray
    fisher: np.ndarray
    noise_std: tuple[float, float]
    n_samples: int

    @property
    def covariance(self) -> np.ndarray:
        """Inverse of the Fisher matrix: the bound on the covariance."""
        return np.linalg.inv(self.fisher)

    @property
    def std(self) -> dict[str, float]:
        """Bound on the standard deviation of every parameter."""
        d = np.sqrt(np.diag(self.covariance))
        return dict(zip(self.names, (float(x) for x in d), strict=True))

    @property
    def theta_std(self) -> float:
        """Bound on the standard deviation of ``theta`` in rad."""
        return self.std["theta"]

    def __add__(self, other: CramerRaoBound) -> CramerRaoBound:
        if not isinstance(other, CramerRaoBound) or other.names != self.names:
            raise InputError("only bounds over the same parameter names can be combined")
        return CramerRaoBound(self.names, self.values, self.fisher + other.fisher,
                              self.noise_std, self.n_samples + other.n_samples)


def cramer_rao_bound(
    drive: TwoMassDrive,
    t: ArrayLike,
    torque: ArrayLike,
    *,
    noise_std: tuple[float, float] | None = None,
    snr_db: float | tuple[float, float] | None = None,
    estimate: Sequence[str] | str = ("theta",),
    prior_rel_std: None | float | Mapping[str, float] = None,
    law: str = "paper",
    initial_state: ArrayLike | None = None,
    fd_step: float = 1e-6,
    noise_ar: ArrayLike | None = None,
) -> CramerRaoBound:
    """Cramér-Rao bound of ``theta`` from both measured speeds with white or AR noise.

    ``F = sum_c S_c^T S_c / s_c^2`` with ``S_c`` the central-difference sensitivity of
    speed ``c`` (motor, load) to the estimated parameters; with autoregressive noise
    (``noise_ar``) the sensitivities are whitened by ``A(q)`` first and ``s_c`` is the
    innovation's standard deviation (the likelihood of
    :class:`~backlashkit.identify.noise.ARNoise`, conditional on the first ``p`` samples).

    Parameters
    ----------
    drive : TwoMassDrive
        The true drive (with ``theta``).
    t, torque : array_like
        Uniform time grid in s and motor torque in N m of the experiment.
    noise_std : tuple of float, optional
        Noise standard deviations ``(s_M, s_L)`` in rad/s.
    snr_db : float or tuple of float, optional
        Instead of ``noise_std``: SNR in dB of ``(w_M, w_L)`` (one value for both),
        ``10 log10(mean(w^2) / noise_variance)`` over the record as in
        :func:`backlashkit.signals.add_noise`.
    estimate : sequence of str or "all", optional
        Parameters estimated: ``("theta",)`` (default, linear parameters known) or
        ``"all"`` (theta and the six linear parameters) or any list with ``"theta"``.
    prior_rel_std : None, float or dict, optional
        Relative std of a Gaussian prior on the linear parameters, added to the
        information as ``1 / (rel_std p)^2`` (as in :class:`JointIdentifier`).
    law : {"paper", "no-pull"}, optional
        Contact law (default ``"paper"``).
    initial_state : array_like, optional
        State at ``t[0]`` (default rest), known.
    fd_step : float, optional
        Relative central-difference step (default 1e-6).
    noise_ar : array_like, optional
        Coefficients ``a_1 .. a_p`` of ``A(q)`` of autoregressive noise (as
        :class:`~backlashkit.identify.noise.ARNoise` fits them, ``JointIdentifier.noise_ar_``):
        one row for both speeds or rows ``(w_M, w_L)``. ``noise_std`` and ``snr_db``
        then give the noise's own level, not its innovation's. Default: white noise.

    Returns
    -------
    CramerRaoBound
        The bound (``.theta_std``, ``.fisher``, ``.names``).

    Raises
    ------
    InputError
        If the drive has no ``theta``, no or both noise levels are given, a name is
        unknown, a parameter to estimate is 0, or ``noise_ar`` is not a stationary
        autoregression.
    """
    from ..simulate import simulate_batch

    if not isinstance(drive, TwoMassDrive):
        raise InputError(f"drive must be a TwoMassDrive, got {type(drive).__name__}")
    theta = drive._require_theta()
    if (noise_std is None) == (snr_db is None):
        raise InputError("give exactly one of noise_std=(s_M, s_L) and snr_db")
    all_names = ("theta", *LINEAR_PARAMS)
    if isinstance(estimate, str):
        if estimate != "all":
            raise InputError(f"estimate must be 'all' or a sequence of names, got {estimate!r}")
        names = all_names
    else:
        names = tuple(estimate)
        bad = [n for n in names if n not in all_names]
        if bad or "theta" not in names or len(set(names)) != len(names):
            raise InputError(
                f"estimate must list distinct names among {', '.join(all_names)} including "
                f"'theta', got {estimate!r}"
            )
        names = ("theta", *[n for n in LINEAR_PARAMS if n in names])
    values = np.array([getattr(drive, n) for n in names], float)
    zero = [n for n, x in zip(names, values, strict=True) if not x > 0]
    if zero:
        raise InputError(f"cannot estimate parameter(s) {zero} at value 0 (e.g. theta = {theta!r})")
    h = v.positive("fd_step", fd_step)
    n = len(names)
    drives = []
    for i in range(n):
        for sgn in (1.0, -1.0):
            x = values.copy()
            x[i] *= 1.0 + sgn * h
            drives.append(_drive(drive, names, x))
    runs = simulate_batch([drive, *drives], t, torque, law=law, initial_state=initial_state)
    nominal = runs[0]
    if noise_std is not None:
        try:
            s_m, s_l = noise_std
        except (TypeError, ValueError):
            raise InputError(f"noise_std must be a pair (s_M, s_L), got {noise_std!r}") from None
        sig = (v.positive("noise_std[0] (s_M)", s_m), v.positive("noise_std[1] (s_L)", s_l))
    else:
        snr = (snr_db, snr_db) if np.ndim(snr_db) == 0 else tuple(snr_db)
        if len(snr) != 2:
            raise InputError(f"snr_db must be a number or a pair (w_M, w_L), got {snr_db!r}")
        sig = tuple(
            math.sqrt(float(np.mean(w**2)) / 10.0 ** (v.finite_scalar("snr_db", s) / 10.0))
            for w, s in ((nominal.w_motor, snr[0]), (nominal.w_load, snr[1]))
        )
    ar = None
    if noise_ar is not None:
        ar = np.atleast_2d(np.asarray(noise_ar, float))
        if ar.shape[0] == 1:
            ar = np.repeat(ar, 2, axis=0)
        if ar.ndim != 2 or ar.shape[0] != 2 or ar.shape[1] < 1 or not np.isfinite(ar).all():
            raise InputError(
                "noise_ar must be the coefficients a_1 .. a_p of A(q), one row for both "
                f"speeds or two rows (w_M, w_L), got {noise_ar!r}"
            )
        try:
            ratios = [innovation_ratio(row) for row in ar]
        except InputError as exc:
            raise InputError(f"noise_ar: {exc}") from None
    fisher = np.zeros((n, n))
    for c, (ch, s) in enumerate((("w_motor", sig[0]), ("w_load", sig[1]))):
        sens = np.column_stack([
            (getattr(runs[1 + 2 * i], ch) - getattr(runs[2 + 2 * i], ch)) / (2 * h * values[i])
            for i in range(n)
        ])
        if ar is not None:  # whitened sensitivities, weighted by the innovation
            s = s * math.sqrt(ratios[c])
            sens = whiten(sens.T, ar[c]).T
        fisher += sens.T @ sens / s**2
    if prior_rel_std is not None:
        rel = _rel_std(prior_rel_std, LINEAR_PARAMS)
        for i, name in enumerate(names[1:], start=1):
            r = rel.get(name)
            if r is not None and r > 0:
                fisher[i, i] += 1.0 / (r * values[i]) ** 2
    return CramerRaoBound(names, values, fisher, (float(sig[0]), float(sig[1])),
                          int(np.size(nominal.t)))
