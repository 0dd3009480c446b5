"""Joint maximum-likelihood identification of the backlash and the linear parameters.

:class:`JointIdentifier` fits ``theta`` (backlash **half-width**, rad) together with
the uncertain linear parameters of a :class:`~backlashkit.TwoMassDrive` to every
record and to **both** measured speeds, by weighted nonlinear least squares; with
Gaussian measurement noise this is maximum likelihood (each record and channel
weighted by its own noise level, estimated from the data). A prior enters, when its
uncertainty is given, as the Gaussian penalty
``sum_p ((p - p_prior) / (rel_std_p * p_prior))^2`` (a maximum a posteriori
estimate). Parameters are optimised as logarithms (positivity without bounds; a
parameter whose prior is 0 stays fixed). The uncertainty is the Gauss-Newton / Fisher
information at the optimum, ``cov(log p) = (J^T W J + P)^-1``, and ``ci95_`` comes from
the interval object (:mod:`backlashkit.identify.intervals`). The search is configured
by :class:`~backlashkit.identify.search.JointSearch`; ``docs/design/joint-search.md``
says why it has the stages it has. Where the records show them, the model adds Coulomb
friction and a current loop, each kept by a likelihood-ratio test
(:mod:`backlashkit.identify.terms`, ``docs/design/real-drives.md``). Units are SI: s,
N m, rad, rad/s.

Fitted attributes besides those in the class docstring
-------------------------------------------------------
``choices_`` (list of TermChoice)
    What the likelihood-ratio tests of ``friction`` and ``actuator`` found, and why
    (:mod:`backlashkit.identify.terms`). Where the current loop is dropped, ``ci95_``
    reaches out to span ``theta`` at every lag the data do not rule out
    (``TermChoice.widening`` and ``TermChoice.held_ci95``).
``cost_`` (float)
    Weighted sum of squares (whitened with ``ARNoise``) plus the prior penalty at the
    optimum, over ``final_horizon`` if given.
``ci95_bounded_`` (tuple of bool)
    Whether each end of the profile interval was reached; False where the profile did
    not rise to the 95 % level within ``ProfileLikelihood.max_factor`` of ``theta_``
    (the records hardly bound ``theta`` there). A lower end of 0 is bounded: the
    profile stays below the 95 % level down to ``theta = 0``, so the records are
    consistent with a drive without backlash. ``(True, True)`` for other intervals.
``interval_`` (str)
    ``"profile"``, ``"fisher"`` or ``"bootstrap"``: where ``ci95_`` comes from; or
    ``"quantisation"`` on encoder angles of known step, where ``ci95_`` and ``std_``
    come from the spread of ``theta`` over the encoders' offsets within a count
    (:mod:`backlashkit.identify._quantised`), not from white noise.
``profile_`` (array or None)
    Rows ``(theta, rise)`` where the profile search evaluated the likelihood, sorted,
    ``rise`` in chi-square units above ``cost_``; None for the other intervals.
``rival_basins_`` (int)
    Other minima of the likelihood, in other basins, within 3.84 (chi-square) of the
    estimate's: the profile interval spans their profiles too, so ``ci95_`` can be
    wider than ``std_`` says (0 for the other intervals). Only minima more than 1 up
    the estimate's Fisher quadratic count; those on the floor of its own basin (a flat
    valley's, such as the friction split's of a drive without backlash) do not.
``bootstrap_thetas_`` (array or None)
    The refitted ``theta`` of every bootstrap resample.
``param_std_``, ``covariance_``
    Fisher standard error of every estimated parameter, and their covariance in
    natural units (order ``estimated_``).
``noise_innovation_std_``, ``noise_ar_``
    Std of the noise's white innovation per record and channel (the residuals'
    weight; ``noise_std_`` for white noise), and ``ARNoise``'s coefficients
    ``(n_records, 2, p)`` (None for white noise).
``noise_model_``
    The noise model fitted: ``noise_model``, or what ``AutoNoise`` chose.
``residuals_``
    ``(w_M - w_M_hat, w_L - w_L_hat)`` per record over the simulated span.
``residual_lag1_``
    Lag-1 autocorrelation of the residuals the likelihood treats as white, per record
    and channel; above :data:`CORRELATED_LAG1` :meth:`~JointIdentifier.fit` warns.
``held_noise_lag1_``
    The speeds' own noise colour on the level held before each step-down, model-free
    (:func:`backlashkit.identify.noise.held_noise_lag1`).
``theta_starts_``, ``theta_two_step_``, ``theta_ini_``
    The starting ``theta`` refined; paper A's two-step estimate and its pre-estimate
    when it succeeded (else None).
``model_start_``
    ``"rest"`` or ``"steady"`` per record: how the model was started.
``measured_``
    ``"angles"`` or ``"speeds"`` per record: what the model was fitted to. Records
    of encoder angles (:meth:`Record.from_positions`), or whose two speeds are
    differenced encoder counts (:func:`~backlashkit.identify.noise.encoder_angles`),
    are fitted as angles with white noise (quantisation: ``q^2 / 12``); their
    ``noise_std_`` is then in rad.
``commutations_``, ``t_c_``, ``t_b_``
    ``(t_s, t_c, t_b)`` per record in s: the step-down and, in the identified model,
    its first contact loss after it and the next contact made (None where absent).
``ambiguous_``
    The continuation paths ended in distinct minima of nearly equal cost: the
    likelihood is multimodal on these records (worth a bootstrap or a longer record).
``misfit_restarted_``, ``misfit_restart_won_``
    Whether the residuals triggered the second search (``Restarts.misfit``), and
    whether its fit was kept (every attribute then comes from it).
``prior_pull_``
    Per parameter with a prior std: how far the data pulled its estimate from the
    prior's value, in standard deviations of that pull (``d / sqrt(s^2 - var)``: ``d``
    the move, ``s`` the prior's std, ``var`` the estimate's variance; normal where the
    prior is right). Beyond :data:`PRIOR_CONFLICT_Z` :meth:`fit` warns
    (:class:`~backlashkit.errors.PriorMismatchWarning`): the prior's value or its std
    is likely wrong, and it pulls the other estimates too.
``fixed_tests_``
    Per parameter the user fixed (a known loop's ``tau_i``): ``(fall, value)``, the
    fall of ``-2 log L`` when the estimate is refitted with it free, and its value
    there. A fall beyond the threshold of the terms' likelihood-ratio test warns
    (:class:`~backlashkit.errors.PriorMismatchWarning`).
``far_from_prior_``
    Estimated linear parameters more than
    :data:`~backlashkit.identify.FAR_FROM_PRIOR` times off the prior; :meth:`fit`
    then warns (:class:`~backlashkit.errors.PriorMismatchWarning`).
"""

from __future__ import annotations

import inspect
import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from .. import validate as v
from ..actuator import CurrentLoop
from ..errors import (
    CorrelatedResidualsWarning,
    InputError,
    NoiseLevelWarning,
    Option,
    PriorMismatchWarning,
    QuantisedSpeedsWarning,
    SensitivityWarning,
)
from ..parallel import reporter
from ..plants import TwoMassDrive
from . import _search
from ._model import (
    LINEAR_PARAMS,
    PACKED_LONG,
    TAU_COL,
    drive_with,
    model_commutation,
    rel_std,
)
from ._problem import Problem, build_problem
from .hyper import _learned_attribute, init_repr
from .intervals import FisherInterval, ParametricBootstrap, ProfileLikelihood, check_interval
from .noise import (
    ARNoise,
    AutoNoise,
    WhiteNoise,
    beyond_noise,
    check_noise_model,
    encoder_angles,
    held_noise_lag1,
    lag1,
    noise_coloured,
)
from .record import as_records, check_prior
from .search import JointSearch
from .step import (
    check_fit_near_prior,
    check_held_units,
    check_step_downs,
    held_speed_gain,
    too_far,
)
from .terms import (
    KEEP_LEVEL,
    PRIOR_PARAMS,
    Term,
    actuator_term,
    check_known_loop,
    friction_term,
)

__all__ = ["JointIdentifier", "LINEAR_PARAMS", "check_estimated_nonzero"]

#: A residual spread this many times the noise level given (``noise=``), or a fraction
#: as small, warns: the standard error scales with the level given, so a level off by
#: 2 gives an interval that holds the truth about 67 % or over 99.99 % of the time
#: where it says 95 %.
NOISE_GIVEN_FACTOR = 2.0
#: Lag-1 autocorrelation of a residual above which (in magnitude) the fit warns that its
#: interval is too narrow: white noise filtered to this correlation has an interval too
#: narrow by up to ``sqrt((1 + 0.2) / (1 - 0.2)) = 1.22`` (its spectrum at 0 against its
#: variance); the fits of white noise in the benchmarks stay below 0.01.
CORRELATED_LAG1 = 0.2
#: The second search's fit (``Restarts.misfit``) replaces the first only if its -2 log
#: likelihood is lower by more than this (chi-square units).
MISFIT_MARGIN = 1.0
#: A fit this close to 100 % (rms residual over the speed's spread) leaves no noise to
#: model: a measured speed has noise far above it (a 16-bit encoder: about 1e-5).
NOISE_FREE = 1e-7
#: Fewest samples after each torque jump that ``final_horizon`` must span.
MIN_FINAL_SAMPLES = 10
#: A parameter with a prior std whose estimate the data pull this many standard
#: deviations from the prior's value (``prior_pull_``) warns of a prior-data conflict:
#: the two-sided 0.1 % point of the normal, so a right prior warns in 1 fit of 1000 per
#: parameter.
PRIOR_CONFLICT_Z = 3.29

#: The defaults (frozen, so one instance serves every identifier).
_SEARCH = JointSearch()
_PROFILE = ProfileLikelihood()
_AUTO = AutoNoise()


class JointIdentifier:
    """Joint ML / MAP fit of the backlash half-width ``theta`` (rad) and the drive (SI).

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters (its ``theta`` is ignored).
    prior_rel_std : None, float or dict, optional
        None (default): the six linear parameters free; a float: their relative prior std;
        a dict without ``theta``: those with a std > 0 (``fc_M``, ``fc_L``, ``tau_i`` too).
    noise : tuple of float, optional
        Noise std ``(s_M, s_L)`` of every record, rad/s (rad: angles); default estimated.
    search : JointSearch, optional
        The search (:mod:`backlashkit.identify.search`); the default is the tested one.
    interval : ProfileLikelihood, FisherInterval or ParametricBootstrap, optional
        Where ``ci95_`` comes from (default the profile likelihood).
    noise_model : AutoNoise, WhiteNoise or ARNoise, optional
        The measurement noise (default: AR where the speeds' noise is coloured).
    friction : {"auto", "viscous", "coulomb"}, optional
        Coulomb torques fitted where the data call for them (default), never, always.
    actuator : "auto", None or CurrentLoop, optional
        Current loop fitted where the data call for it (default), none, or known.
    law : {"paper", "no-pull", "modelica"}, optional
        Contact law of the model (default ``"paper"``).
    allow_far_from_prior : bool, optional
        Answer even where a parameter ends over 5 times off the prior (default False).
    workers, progress : int; bool or callable, optional
        Threads for the simulations (default all cores); the stages on a ProgressBar
        (True) or as ``progress(done, total)`` (default none).

    Attributes
    ----------
    theta_, std_, ci95_ : float, float, tuple of float
        Estimate of ``theta``, its standard error and 95 % interval (``interval_``), rad.
    params_, param_std_, drive_, estimated_ : dict, dict, TwoMassDrive, tuple of str
        Linear parameters, standard errors of all estimates (SI), drive, names (theta first).
    noise_std_, fit_percent_ : numpy.ndarray
        Noise std (rad/s; rad: angles), speeds' NRMSE fit % per record and ``(w_M, w_L)``.
    friction_, fc_M_, fc_L_, tau_i_, choices_ : str, float, list of TermChoice
        ``"viscous"`` or ``"coulomb"``, Coulomb torques (N m), loop lag (s; 0: none);
        why each ``"auto"`` term was kept or dropped (``choice.reason()``).

    Examples
    --------
    >>> import backlashkit as bk
    >>> signals = bk.signals
    >>> truth = bk.TwoMassDrive(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=5e-3,
    ...                         f_L=5e-3, f_sh=1.575e-2, theta=0.0349)
    >>> t = signals.time_grid(4.0, 1e-3)
    >>> r = truth.simulate(t, signals.step_down(t, 0.942, t_s=2.0))
    >>> rec = bk.Record(t, r.torque, signals.add_noise(r.w_motor, 30, rng=1),
    ...                 signals.add_noise(r.w_load, 30, rng=2))
    >>> fit = bk.JointIdentifier(truth.with_theta(None), workers=1).fit(rec)
    >>> print(f"{fit.theta_:.4f} rad, 95 % in [{fit.ci95_[0]:.4f}, {fit.ci95_[1]:.4f}]")
    0.0348 rad, 95 % in [0.0341, 0.0353]
    """

    method = "joint"

    __getattr__ = _learned_attribute

    def __init__(
        self,
        prior: TwoMassDrive,
        *,
        prior_rel_std: None | float | Mapping[str, float] = None,
        noise: tuple[float, float] | None = None,
        search: JointSearch = _SEARCH,
        interval: ProfileLikelihood | FisherInterval | ParametricBootstrap = _PROFILE,
        noise_model: AutoNoise | WhiteNoise | ARNoise = _AUTO,
        friction: str = "auto",
        actuator: str | CurrentLoop | None = "auto",
        law: str = "paper",
        allow_far_from_prior: bool = False,
        workers: int | None = None,
        progress: bool | Callable[[int, int], None] = False,
    ) -> None:
        self.prior = prior
        self.prior_rel_std = prior_rel_std
        self.noise = noise
        self.search = search
        self.interval = interval
        self.noise_model = noise_model
        self.friction = friction
        self.actuator = actuator
        self.law = law
        self.allow_far_from_prior = allow_far_from_prior
        self.workers = workers
        self.progress = progress

    def __repr__(self) -> str:
        text = init_repr(self)
        if not hasattr(self, "theta_"):
            return text
        lo, hi = self.ci95_
        loop = f", tau_i_ = {self.tau_i_:.3g} s" if self.tau_i_ > 0 else ""
        return (f"{text}: theta_ = {self.theta_:.4g} rad, std_ = {self.std_:.3g} rad, "
                f"ci95_ = ({lo:.4g}, {hi:.4g}) rad [{self.interval_}], "
                f"friction_ = {self.friction_!r}{loop}")

    def _check(self) -> None:
        check_prior(self.prior)
        if not isinstance(self.search, JointSearch):
            raise InputError("search must be a JointSearch (backlashkit.identify.search), "
                             f"got {type(self.search).__name__}")
        check_interval(self.interval)
        check_noise_model(self.noise_model)
        if self.workers is not None:
            v.integer("workers", self.workers, 1)
        v.flag("allow_far_from_prior", self.allow_far_from_prior)
        if not (isinstance(self.progress, bool) or callable(self.progress)):
            raise InputError("progress must be True, False or a callable "
                             f"progress(done, total), got {self.progress!r}")
        check_known_loop(self._terms()[1], self.prior)
        check_estimated_nonzero(self.prior,
                                rel_std(self.prior_rel_std, LINEAR_PARAMS, PRIOR_PARAMS))
        self.noise_model._check_with(self.noise, self.search.final_horizon)
        if self.noise is not None:
            try:
                s_m, s_l = self.noise
            except (TypeError, ValueError):
                raise InputError(
                    f"noise must be a pair (s_M, s_L) of noise std in rad/s, got {self.noise!r}"
                ) from None
            v.positive("noise[0] (s_M)", s_m)
            v.positive("noise[1] (s_L)", s_l)

    def fit(self, records) -> JointIdentifier:
        """Identify ``theta`` and the drive; warn of correlated residuals, of a far prior.

        Parameters
        ----------
        records : Record, tuple or sequence of them
            Experiments (Records or tuples ``(t, torque, w_motor, w_load)``), fitted jointly.

        Returns
        -------
        JointIdentifier
            ``self``, fitted.

        Raises
        ------
        InputError
            If a parameter is invalid or a record cannot be used (message names it).
        """
        self._check()
        prior = self.prior.with_theta(None)
        records = as_records(records, prior=prior)
        check_step_downs(records, prior)
        gains = check_held_units(records, prior,
                                 allow_far_from_prior=self.allow_far_from_prior)
        quanta = [(0.0, 0.0) if r.has_positions  # fitted as the angles they hold
                  else r.speed_quanta for r in records]
        records = [encoder_angles(r, quanta=q) for r, q in zip(records, quanta, strict=True)]
        # one BLAS thread: the products J^T J (n_samples x 7) gain nothing from more,
        # and their rounding then does not depend on the machine's core count (the
        # multimodal fits of a rattling load can follow a different path on it);
        # overflowing trial points cost inf and are rejected by the search: no warning
        with warnings.catch_warnings(), threadpool_limits(limits=1, user_api="blas"), \
                np.errstate(over="ignore", invalid="ignore"):
            warnings.simplefilter("ignore", SensitivityWarning)
            # a second search (Restarts.misfit) runs the stages again
            labels = (*_search.STAGE_NAMES, *(f"{n}, again" for n in _search.STAGE_NAMES))
            with reporter(self.progress, "identify", unit="stage", labels=labels) as bar:
                fitted, restarted, won = self._fit_and_restart(records, bar)
        far = self._far_from_prior(_linear(fitted), records, gains, fitted["_prior_rise"],
                                   _linear_log_std(fitted))
        _warn_prior_conflicts(fitted["prior_pull_"],
                              rel_std(self.prior_rel_std, LINEAR_PARAMS, PRIOR_PARAMS))
        _warn_fixed_loop(fitted["fixed_tests_"], self._terms()[1])
        self.__dict__.update(fitted, misfit_restarted_=restarted, misfit_restart_won_=won,
                             far_from_prior_=far)
        self.measured_ = ["angles" if r.has_positions else "speeds" for r in records]
        parts = self._correlation_parts()
        if parts is not None:
            warnings.warn(CorrelatedResidualsWarning(*parts), stacklevel=2)
        _warn_quantised(records, quanta)
        if self.interval != _PROFILE and self.interval_ == "quantisation":
            warnings.warn(QuantisedSpeedsWarning(
                "the records are encoder angles: the 95 % interval is the spread of theta "
                "over the encoders' offsets within a count, not the one asked for "
                f"({self.interval!r}), which assumes a white noise that quantisation is "
                "not"), stacklevel=2)
        if self.noise is not None:
            _warn_noise_given(self.noise, self.residuals_, records)
        return self

    def _fit_and_restart(self, records, bar) -> tuple[dict[str, Any], bool, bool]:
        """The search, and again from its answer where its residuals say it missed."""
        fitted = self._fit(records, stage=lambda k: bar(k, _search.STAGES))
        restarted = won = False
        # an encoder's angle errors are constant while a shaft stands still, so its
        # residual's correlation says nothing of the basin: no restart on them
        if (self.search.restarts.misfit and not any(r.has_positions for r in records)
                and _misfits(fitted)):
            restarted = True
            try:  # the whole search again, from the fitted linear parameters
                again = self._fit(records, anchor=fitted["drive_"],
                                  anchor_extra=fitted["params_"],
                                  stage=lambda k: bar(_search.STAGES + k,
                                                      2 * _search.STAGES))
            except InputError:  # e.g. a model that explains nothing from there
                again = None
            won = again is not None and (
                again["_neg2_loglik"] < fitted["_neg2_loglik"] - MISFIT_MARGIN)
            fitted = again if won else fitted
        return fitted, restarted, won

    def _far_from_prior(self, linear: dict[str, float], records, gains: list[float],
                        prior_rise: float, log_std: dict[str, float]):
        """Refuse the fitted linear parameters ``linear`` beyond REFUSE_FROM_PRIOR before
        the estimator holds the answer; warn of those beyond FAR_FROM_PRIOR (``gains``:
        the records' :func:`held_speed_gain`); neither where the prior's own parameters
        fit the records within FAR_RISE of the estimate (``prior_rise``), nor for a
        move within FAR_Z of its standard errors (``log_std``, of the logarithms)."""
        return check_fit_near_prior(
            linear, self.prior, allow_far_from_prior=self.allow_far_from_prior,
            stacklevel=3, held_gains=gains,
            missing=self._missing_terms(), names=[r.name for r in records],
            angles=any(r.has_positions for r in records), prior_rise=prior_rise,
            log_std=log_std)

    def _refuse_far(self, records, prior, linear: dict[str, float], rise: float,
                    log_std: dict[str, float]) -> None:
        """Refuse the search's point now where :meth:`_far_from_prior` would refuse its
        answer (``linear``: its linear parameters; ``rise``: how much worse the prior's
        fit the records, :func:`~backlashkit.identify._search.prior_rise`; ``log_std``:
        the standard errors of their logarithms), before the uncertainty and the
        second search (``Restarts.misfit``), whose refits from such a point can take far
        longer than a fit (a viscous model of a drive with Coulomb friction drives ``J_M``
        towards 0, where the simulations chatter); warn of nothing (the answer's check
        does)."""
        if not self.allow_far_from_prior and too_far(linear, self.prior, prior_rise=rise,
                                                     log_std=log_std):
            self._far_from_prior(linear, records,
                                 [held_speed_gain(r, prior) for r in records], rise, log_std)

    def correlation_message(self) -> str | None:
        """Say whether the residuals of the fit are too correlated for its interval.

        Returns
        -------
        str or None
            Where a residual's lag-1 autocorrelation exceeds :data:`CORRELATED_LAG1`
            (a too narrow interval) or is numerical error (:data:`NOISE_FREE`); else None.
        """
        parts = self._correlation_parts()
        return None if parts is None else "".join(map(str, parts))

    def _correlation_parts(self) -> tuple[str | Option, ...] | None:
        """:meth:`correlation_message` with its remedy as an :class:`Option` (the
        command line words it as a flag)."""
        misfit = 1.0 - float(np.min(self.fit_percent_)) / 100.0  # rms residual / spread
        if misfit < NOISE_FREE:  # a residual this small is no noise, white or coloured
            return (f"the model reproduces every speed to {max(misfit, 1e-16):.1g} of its "
                    "spread (noise-free, simulated records?): the residual is numerical "
                    "error, so std and interval only say that theta is determined to that "
                    "precision",)
        lag = self.residual_lag1_
        k, c = np.unravel_index(int(np.argmax(np.abs(lag))), lag.shape)
        rho = float(lag[k, c])
        if not abs(rho) > CORRELATED_LAG1:
            return None
        ar = Option("noise_model", "ar", python="noise_model=ARNoise()")
        if self.noise_ar_ is None:
            what, fix = "the noise is not white", ("try ", ar)
        else:
            what = f"ARNoise(order={self.noise_ar_.shape[-1]}) does not whiten the noise"
            fix = ("raise ", Option("order", None, python="the order"))
        held = self.held_noise_lag1_[k, c]
        angles = self.measured_[k] == "angles"
        if angles:  # no noise model of the speeds applies to the angles fitted
            what = ("the errors of the encoder angles are not white (a misfit, or the "
                    "quantisation while a shaft stands still)")
            fix = ("check the prior, the encoders' counts per revolution (",
                   Option("counts_per_rev", None), ") and whether a two-mass drive with "
                   "backlash describes the record")
        elif (self.noise_ar_ is None and np.isfinite(held)
                and not noise_coloured(self.held_noise_lag1_, self._held_samples)):
            # the speeds' own noise is white: the residual's correlation is the model's
            what = (f"the model misfits, since the noise itself is white (lag-1 {held:.2f} "
                    "on the level held before the step-down)")
            fix = ("check the prior (a wrong basin of the fit) and whether a two-mass drive "
                   "with backlash describes the record; ",
                   Option("noise_model", "ar", python="ARNoise"), " would hide the misfit")
        missing = self._missing_terms()  # a term the drive has may be what misfits
        lacks = (("; or the model lacks a term of the drive, or fixes it wrongly: try ",
                  *missing) if missing else ())
        signal = (("phi_M", "phi_L") if angles else ("w_M", "w_L"))[c]
        return (f"the residual of {signal} in {self._record_names[k]} (record "
                f"{k + 1}) has lag-1 "
                f"autocorrelation {rho:.2f} (white noise: about 0): {what}, so the standard "
                "error and interval of theta are too narrow; ", *fix, *lacks)

    def _fit(self, records, anchor: TwoMassDrive | None = None,
             anchor_extra: Mapping[str, float] | None = None,
             stage: Callable[[int], None] = lambda done: None) -> dict[str, Any]:
        """One search; ``anchor`` (and ``anchor_extra``, values of the added terms)
        replaces the prior as its starting point (grid, box, two-step start), not in
        the penalty. ``stage(k)``: the search's progress. Returns the fitted
        attributes."""
        prior = self.prior.with_theta(None)
        recs = list(records)  # checked by fit
        search = self.search
        ts_max = max(r.ts for r in recs)
        if (search.final_horizon is not None
                and search.final_horizon < MIN_FINAL_SAMPLES * ts_max):
            raise InputError(
                f"final_horizon must span at least {MIN_FINAL_SAMPLES} samples "
                f"({MIN_FINAL_SAMPLES * ts_max:.3g} s at Ts = {ts_max:.3g} s), got "
                f"{search.final_horizon!r}"
            )
        # the speeds' own noise, before any model: AutoNoise chooses from it
        held, held_samples = held_noise_lag1(recs, prior)
        noise_model = self.noise_model._resolve(held, held_samples,
                                                fixed_noise=self.noise is not None,
                                                final_horizon=search.final_horizon)
        rel = rel_std(self.prior_rel_std, LINEAR_PARAMS, PRIOR_PARAMS)
        terms = self._terms()
        for term in terms:
            term.check_prior(rel, prior)
        pb, sigma = build_problem(prior, recs, rel, self.noise, search, self.law,
                                  self.workers, terms)
        start = prior if anchor is None else anchor
        extra = {n: x for term in terms if term.fitted
                 for n, x in term.starts(recs, prior).items()}
        if anchor_extra:
            extra.update({n: x for n, x in anchor_extra.items() if n in extra and x > 0})
        # a friction that a first fit drove to 0 (its logarithm underflowed) starts the
        # misfit's search again from the prior's value: the search runs in logarithms
        linear = {n: getattr(start, n) if getattr(start, n) > 0 else getattr(prior, n)
                  for n in LINEAR_PARAMS}
        z_anchor = pb.z_of(pb.free, [linear[n] if n in LINEAR_PARAMS else extra[n]
                                     for n in pb.free])
        out = _search.run(
            pb, search, sigma, recs, start_drive=start.with_theta(None), z_anchor=z_anchor,
            fixed_noise=self.noise is not None, noise_model=noise_model,
            interval=self.interval, refit=_BootstrapRefit(self._refit_params()), terms=terms,
            refuse_far=partial(self._refuse_far, recs, prior), stage=stage)
        return {**_published(out, prior, self.law), "held_noise_lag1_": held,
                "_held_samples": held_samples, "noise_model_": noise_model,
                "_record_names": [r.name for r in recs]}

    def _missing_terms(self) -> tuple[str | Option, ...]:
        """How to fit the terms the model leaves out or fixes, as message parts."""
        parts: list[str | Option] = []
        for term in self._terms():  # a term left out, or fixed (maybe wrongly)
            if term.mode in ("off", "fixed"):
                parts += [" or ", Option(term.name, "auto")] if parts else [
                    Option(term.name, "auto")]
        return tuple(parts)

    def _terms(self) -> tuple[Term, Term]:
        """The friction and actuator terms of the model (checked)."""
        rel = rel_std(self.prior_rel_std, LINEAR_PARAMS, PRIOR_PARAMS)
        return friction_term(self.friction), actuator_term(self.actuator, rel.get("tau_i"))

    def _refit_params(self) -> dict[str, Any]:
        """The hyperparameters of a bootstrap refit: these, with Fisher's interval; a
        refit answers wherever it ends (the check against the prior is the fit's)."""
        params = {name: getattr(self, name) for name in _INIT_NAMES}
        return {**params, "interval": FisherInterval(), "progress": False,
                "allow_far_from_prior": True}


def _warn_noise_given(noise: tuple[float, float], residuals, records) -> None:
    """Warn where a speed's residual spread is over :data:`NOISE_GIVEN_FACTOR` times
    the noise level given, either way (the first such record and speed)."""
    for rec, pair in zip(records, residuals, strict=True):
        for name, res, given in zip(("w_M", "w_L"), pair, noise, strict=True):
            spread = float(np.sqrt(np.mean(np.square(res))))
            ratio = spread / float(given)
            if not 1.0 / NOISE_GIVEN_FACTOR <= ratio <= NOISE_GIVEN_FACTOR:
                warnings.warn(NoiseLevelWarning(
                    f"the residual of {name} in {rec.name} spreads {spread:.3g} (rms), "
                    f"{ratio:.3g} times the noise level given ({given:.3g}): the standard "
                    "error and interval of theta scale with that level; check it, or leave ",
                    Option("noise", None, python="noise=None"), " to estimate it"),
                    stacklevel=3)
                return


def check_estimated_nonzero(prior: TwoMassDrive, rel: Mapping[str, float | None]) -> None:
    """Refuse a linear parameter that the fit would estimate from a prior value of 0.

    The fit estimates each linear parameter on a log scale from the prior's value: from
    0 it could never move, and the fit would hold it at 0 unsaid, with theta and the
    other parameters taking up the friction left out (a friction written 0 for
    "unknown"). A friction that is truly 0 is held there by leaving it out of the
    relative stds.

    Parameters
    ----------
    prior : TwoMassDrive
        The prior drive.
    rel : mapping of str to float or None
        The parameters estimated and their relative prior std (``rel_std``; None: no
        penalty).

    Raises
    ------
    InputError
        For the first such parameter: its name and both remedies.
    """
    for name in LINEAR_PARAMS:
        if name in rel and getattr(prior, name) == 0.0:
            raise InputError(
                f"the prior's {name} is 0, but the fit estimates it, on a log scale from "
                "the prior's value, so it would stay at 0: give a first guess > 0 (",
                Option("prior_value", name, python=f"TwoMassDrive({name}=...)"),
                "; its order of magnitude is enough), or hold it at 0 with a relative "
                "std for each other linear parameter alone (",
                Option("hold_at_prior", name,
                       python=f"prior_rel_std={{...}} without {name!r}"), ")")


@dataclass(frozen=True)
class _BootstrapRefit:
    """``theta`` of the same search on a bootstrap resample; picklable (no executor or
    progress bar inside), so the refits can run in other processes or on Dask."""

    params: dict[str, Any]

    def __call__(self, records) -> float:
        return JointIdentifier(**self.params)._fit(records)["theta_"]


#: Names of :class:`JointIdentifier`'s hyperparameters (its ``__init__`` arguments).
_INIT_NAMES = tuple(n for n in inspect.signature(JointIdentifier.__init__).parameters
                    if n != "self")


def _warn_quantised(records, quanta: list[tuple[float, float]]) -> None:
    """Warn where one speed of a record is an encoder's differenced counts and the
    other is not (:class:`~backlashkit.errors.QuantisedSpeedsWarning`); records with
    both are fitted as angles (:func:`~backlashkit.identify.noise.encoder_angles`).
    ``quanta``: the steps of each record's two speeds (:func:`speed_quantum`)."""
    for rec, steps in zip(records, quanta, strict=True):
        if rec.has_positions:
            continue
        for name, q in zip(("w_motor", "w_load"), steps, strict=True):
            if q > 0:
                counts = 2 * math.pi / (q * rec.ts)
                warnings.warn(QuantisedSpeedsWarning(
                    f"{rec.name}: {name} is quantised to steps of {q:.3g} rad/s (an encoder "
                    f"of about {counts:.0f} counts per revolution differenced over "
                    f"Ts = {rec.ts:.3g} s) but the other speed is not: the model takes it "
                    "as the speed at each sample with white noise, so theta may be off by "
                    "about a percent and its interval too narrow; give both encoders' "
                    "angles (Record.from_positions) to have them fitted as angles"),
                    stacklevel=3)
                break


def _linear(fitted: dict[str, Any]) -> dict[str, float]:
    """The estimated linear parameters of a fit, by name."""
    return {n: fitted["params_"][n] for n in fitted["estimated_"][1:] if n in LINEAR_PARAMS}


def _linear_log_std(fitted: dict[str, Any]) -> dict[str, float]:
    """The standard errors of the logarithms of a fit's estimated linear parameters."""
    return {n: fitted["param_std_"][n] / fitted["params_"][n]
            for n in fitted["estimated_"][1:] if n in LINEAR_PARAMS}


def _misfits(fitted: dict[str, Any]) -> bool:
    """Whether a residual is correlated beyond noise while the noise itself is not (or
    is modelled): a wrong basin (``Restarts.misfit``)."""
    if not beyond_noise(fitted["residual_lag1_"], 1.0 / np.sqrt(fitted["_lag1_samples"])):
        return False
    return fitted["noise_ar_"] is not None or not noise_coloured(
        fitted["held_noise_lag1_"], fitted["_held_samples"])


def _whiteness(out: _search.Outcome, n_recs: int) -> dict[str, Any]:
    """Lag-1 autocorrelation of the residuals the likelihood treats as white (fitted
    samples only), and -2 log likelihood with the noise variances profiled out (up to
    a constant): comparable between fits whose noise levels differ."""
    best, sigma = out.unc.best, out.sigma
    parts: dict[tuple[int, int], list[np.ndarray]] = {}
    for k, c, part in out.rows_unc.channels(best.r):
        parts.setdefault((k, c), []).append(part)
    lag, samples = np.zeros((n_recs, 2)), np.ones((n_recs, 2))
    neg2 = float(np.sum(out.rows_unc.prior_rows(best.r) ** 2))
    for (k, c), chunks in parts.items():
        e = np.concatenate(chunks)
        lag[k, c] = lag1(e)
        samples[k, c] = max(e.size, 1)
        neg2 += e.size * math.log(max(float(sigma[k, c]) ** 2 * float(np.mean(e**2)), 1e-300))
    return {"residual_lag1_": lag, "_lag1_samples": samples, "_neg2_loglik": neg2}


def _published(out: _search.Outcome, prior: TwoMassDrive, law: str) -> dict[str, Any]:
    """The fitted attributes of one search."""
    pb, unc = out.problem, out.unc
    fitted = dict(zip(pb.names, (float(x) for x in unc.values), strict=True))
    for n in ("fc_M", "fc_L"):
        # estimated in natural units: below 0 the model has 0; not estimated, what the
        # model simulated (0 without friction), not the prior's starting value
        fitted[n] = max(fitted[n], 0.0) if n in fitted else (
            float(pb.base[PACKED_LONG.index(n)]) if pb.base.size > PACKED_LONG.index(n)
            else 0.0)
    on_drive = [*(n for n in pb.names if n in LINEAR_PARAMS or n == "theta"), "fc_M", "fc_L"]
    # the breakaway torques are tied to the Coulomb torques (None), as simulated
    drive = replace(drive_with(prior, on_drive, np.array([fitted[n] for n in on_drive])),
                    fs_M=None, fs_L=None)
    tau_i = fitted.get("tau_i", float(pb.base[TAU_COL]) if pb.base.size > TAU_COL else 0.0)
    residuals, fits = _search.residuals_and_fit(pb.spans, out.sims)
    theta = float(unc.values[0])
    found = unc.interval
    innovation = np.asarray(out.sigma, float)
    noise_std = innovation
    if out.ar is not None:  # the noise's own std, not its innovation's
        noise_std = np.array([[float(np.std(e)) for e in pair] for pair in residuals])
    commutations = [model_commutation(drive, sp, law, tau_i) for sp in pb.spans]
    return {
        "theta_": theta,
        "std_": float(unc.std[0]) if found.std is None else found.std,
        "ci95_": found.ci95, "ci95_bounded_": found.bounded, "interval_": found.kind,
        "profile_": found.profile, "bootstrap_thetas_": found.bootstrap_thetas,
        "rival_basins_": found.rivals,
        "params_": {**{n: float(getattr(drive, n)) for n in (*LINEAR_PARAMS, "fc_M", "fc_L")},
                    "tau_i": tau_i},
        "drive_": drive, "estimated_": pb.names,
        # Coulomb torques fitted to 0 (friction="coulomb" on a drive without) are still
        # the model's: the model line and the JSON say so beside their values
        "friction_": ("coulomb" if {"fc_M", "fc_L"} & set(pb.names) or drive.fc_M > 0
                      or drive.fc_L > 0 else "viscous"),
        "fc_M_": float(drive.fc_M), "fc_L_": float(drive.fc_L), "tau_i_": tau_i,
        "choices_": out.choices,
        "param_std_": dict(zip(pb.names, (float(s) for s in unc.std), strict=True)),
        "covariance_": unc.cov,
        "noise_innovation_std_": innovation, "noise_ar_": out.ar, "noise_std_": noise_std,
        "residuals_": residuals, "fit_percent_": fits, "cost_": float(unc.best.cost),
        **_whiteness(out, len(out.sigma)),
        "theta_starts_": out.starts,
        "theta_two_step_": None if out.two_step is None else out.two_step[0],
        "theta_ini_": None if out.two_step is None else out.two_step[1],
        "model_start_": ["rest" if sp.level is None else "steady" for sp in pb.spans],
        "commutations_": commutations,
        "t_c_": [c[1] for c in commutations], "t_b_": [c[2] for c in commutations],
        "ambiguous_": out.ambiguous, "_prior_rise": out.prior_rise,
        "prior_pull_": _prior_pulls(pb, unc),
        "fixed_tests_": {n: (f.fall, f.value) for n, f in out.fixed.items()},
    }


def _prior_pulls(pb: Problem, unc: _search.Uncertain) -> dict[str, float]:
    """``prior_pull_``: where the prior is right, the move from its value has the
    variance of the prior less that of the estimate (a Gaussian update)."""
    out = {}
    for i, name in enumerate(pb.names[1:], start=1):
        prior_std = pb.pen[i - 1] * pb.p_prior[i - 1]
        if not np.isfinite(prior_std):
            continue
        var = prior_std**2 - unc.cov[i, i]
        move = float(unc.values[i]) - pb.p_prior[i - 1]
        out[name] = float(move / math.sqrt(var)) if var > 0 else 0.0
    return out


def _warn_fixed_loop(tests: dict[str, tuple[float, float]], term: Term) -> None:
    """Warn where the data call for another lag than a known loop's: the refit with it
    free falls beyond the terms' likelihood-ratio threshold (:data:`~.terms.KEEP_LEVEL`)."""
    if "tau_i" not in tests or not tests["tau_i"][0] > term.threshold:
        return
    fall, value = tests["tau_i"]
    warnings.warn(PriorMismatchWarning(
        f"the data call for another current loop than the one given (tau_i "
        f"{term.fixed[0] * 1e3:.3g} ms): refitted with its lag free, the model moves it to "
        f"{value * 1e3:.2g} ms and lowers -2 log L by {fall:.3g} (the terms' test: "
        f"{term.threshold:.3g} at {KEEP_LEVEL:.0%}); check it, or fit it with ",
        Option("actuator", "auto")),
        stacklevel=3)


def _warn_prior_conflicts(pulls: dict[str, float], rel: dict) -> None:
    far = {n: z for n, z in pulls.items() if abs(z) > PRIOR_CONFLICT_Z}
    if far:
        named = ", ".join(f"{n} {abs(z):.1f}" for n, z in far.items())
        stds = ", ".join(f"{n} {rel[n]:g}" for n in far)
        warnings.warn(PriorMismatchWarning(
            f"the data pull {named} standard deviations from the prior's values (relative "
            f"stds {stds}): a prior-data conflict; a value or its std is likely wrong, and "
            "it pulls the other estimates too: correct it, or widen its std"),
            stacklevel=3)
