"""Backlash identification from a torque step-down (paper A, Ravanbod-Shirazi &
Besançon-Voda, "Backlash identification: a two step approach", IFAC 2002).

Two estimators, in the scikit-learn style (``fit`` returns ``self``; what is learned
ends in ``_``):

* :class:`TwoStepIdentifier` -- paper A's algorithm, Section 4.3 steps 4-8: the
  commutation instants ``t_c`` (shaft leaves the positive flank) and ``t_b`` (it
  meets the negative flank) after the step-down at ``t_s`` are located by the
  piecewise free-decay fits of eq. 9; both speeds are low-pass filtered by FIR
  filters; the backlash is pre-estimated by eq. 6,
  ``theta_ini = -0.5 * integral_{t_c}^{t_b} (w_Mf - w_Lf) dt``; and the final value
  minimises the least-squares criterion ``W_1`` on the motor speed over
  ``[t_s, t_s + dt_4]`` with ``theta`` restricted to ``theta_ini (1 +- n_theta)``.
* :class:`RegressionIdentifier` -- the baseline of paper A's Table 2: the same
  criterion with ``theta`` searched over ``[0, theta_max]`` (15 deg) without the
  pre-estimate.

Every ``theta`` is the backlash **half-width** in rad (dead zone ``[-theta, theta]``,
total gap ``2 theta``). Units are SI: s, N m, rad, rad/s.

Choices the paper leaves open (documented here, configurable where it matters)
-----------------------------------------------------------------------------------
* **Step-down instant.** ``t_s`` is the first sample of the lower torque level: the
  torque record must hold a positive level and then drop (the largest negative jump
  of the torque column), as in paper A's ``C_M = a 1(t) - a 1(t - t_s)``.
* **Windows dt_1 .. dt_3 of eq. 9** (``t_s < t_c < t_s + dt_1 < t_b``,
  ``t_s + dt_2 < t_b < t_s + dt_3 < t_a``) are taken from the data unless given: the
  impact on the negative flank makes the motor speed jump up, so ``t_b`` is located
  roughly at ``t_s + tau``, the minimum of the motor speed (moving average over
  21 ms) that starts its fastest rise over 20 ms (the first rise reaching half the
  largest one within ``search`` seconds after ``t_s``);
  then ``dt_1 = dt_2 = tau / 2`` and ``dt_3 = 1.15 tau`` (the next contact loss comes
  about a quarter of a shaft period after the impact: 1.27 ``t_b`` after ``t_s`` for
  paper A's drive at ``a_1``, 1.74 ``t_b`` at ``a_2``).
* **Eq. 9.** ``W_c`` and ``W_b`` are evaluated on the raw (noisy) load speed, as the
  paper says, with ``alpha = f_L / J_L`` of the prior. The amplitude of the decay
  (``w_L(t_c)`` in ``F_1``, ``w_L(t_b)`` in ``F_2``) is the measured sample at the
  candidate instant (``anchor="sample"``, the paper's text) or its least-squares value
  over the window (``anchor="fit"``, closed form since ``F`` is linear in it).
* **Filters.** Linear-phase FIR low-pass filters (the taps of :func:`scipy.signal.firwin`,
  Hamming window) applied centred, i.e. with their delay of ``(N - 1) / 2`` samples
  removed (zero phase, single pass, so the magnitude response is the designed one).
  A causal filter would shift the speeds against ``t_c`` and ``t_b`` found on the raw
  signal and bias eq. 6; the paper filters recorded data offline. The record is
  padded with its end values. ``N`` is the odd number nearest ``3.3 f_s / f_c``
  (transition band about as wide as the cut-off) unless ``numtaps`` is given.
  Cut-offs are in **rad/s** (paper: 50 rad/s for ``w_M``, 20 rad/s for ``w_L``).
* **Integral of eq. 6.** Trapezoidal rule on the filtered speeds, with the ends at
  ``t_c`` and ``t_b`` (grid instants, as eq. 9 returns them).
* **Model start in W_1.** The model (prior linear parameters, candidate ``theta``) is
  simulated from ``t_s`` on, started at the steady state under the torque held before
  ``t_s``, with the speed level **measured** (mean motor speed over ``level_window``
  seconds before ``t_s``; the paper's step 1 measures the gain ``g_s``): state
  ``[w_0, w_0, theta + f_L w_0 / k_sh]`` with the prior's ``f_L`` and ``k_sh``. The
  prior's own steady state ``a / (f_M + f_L)`` would carry the parameter error into
  every sample of ``W_1``.
* **dt_4** = 1 s (paper A Section 5: "delta t = 1 s").
* **Search.** A grid over the interval (``n_grid`` points, simulated in parallel with
  :func:`backlashkit.simulate_batch`), then grids of 21 points, each ten times finer,
  around the best point until the spacing is below ``1e-6`` of the interval's end (no
  serial scalar minimiser: importing ``scipy.optimize`` alone would take longer than
  the whole search). The regression baseline keeps this search: its wrong local minima come from
  the criterion with an erroneous prior, not from the search.
* **Several records.** The pre-estimate is the mean of the per-record values of
  eq. 6; ``W_1`` is the sum of the per-record criteria. Paper A runs step 1 (small
  step ``a_1``, noisy) for the pre-estimate and step 2 (``a_2 = 0.6 a_max``) for
  ``W_1``: pass the step-2 records as ``final_records``.

Coulomb friction (``friction="coulomb"`` or ``"auto"``)
-------------------------------------------------------
Paper A's drive has viscous friction only; a real one also has Coulomb torques
``fc_M``, ``fc_L`` (N m) against the motion. Relation (4), and so eq. 6, is kinematic
and holds with any friction. Two equations change (:mod:`backlashkit.identify.decay`):

* **Eq. 9.** A freely decaying inertia follows ``J w' = -f w - fc``: after ``t_c``
  (``F_1``) and before ``t_b`` (``F_2``) the load speed is
  ``w_L(t_i) exp(-alpha (t - t_i)) - (fc_L / J_L) (1 - exp(-alpha (t - t_i))) / alpha``
  (a linear fall when ``alpha = 0``), held at 0 once it reaches it (it sticks) instead
  of decaying exponentially towards 0. The onset ``"unloading"`` joins the decay's
  slope ``-(alpha w + fc_L / J_L)``. The windows ``dt_1 .. dt_3`` are the viscous fit's.
* **W_1.** The model is the prior with Coulomb torques ``fc_M, fc_L >= 0``, started
  at the measured steady state with the shaft carrying the load's friction
  (``phi_d = theta + (f_L w_0 + fc_L) / k_sh``); ``W_1`` is minimised over theta and
  both torques (the torques profiled out for every candidate theta,
  :func:`~backlashkit.identify.decay.coulomb_profile_costs`), from the prior's
  torques where it gives them. The viscous model has none, whatever the prior gives
  (as in the joint fit).

The fit runs in two rounds: the viscous pre-estimate bounds a first Coulomb fit of
``W_1``; its ``fc_L`` enters eq. 9, whose new pre-estimate bounds the final fit.
``friction="auto"`` fits both models and keeps the Coulomb one only when the
likelihood ratio of the final least squares (white Gaussian noise of unknown variance),
``N ln(W_1 viscous / W_1 Coulomb)`` over the ``N`` samples of ``W_1``, exceeds
:data:`FRICTION_LR` (the 99.9 % point of chi-square with 2 degrees of freedom, one per
torque); otherwise every result is the viscous fit's. A prior error also lowers
``W_1`` when the torques are freed, so on records without Coulomb friction but with a
wrong prior ``"auto"`` often keeps them (docs/validation/ravanbod2002.md, "Coulomb
friction"): the default stays ``"viscous"``, paper A's model.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError, Option
from ..plants import TwoMassDrive
from .commutation import commutation_instants, fir_lowpass, pre_estimate
from .decay import (
    CriterionWindow,
    coulomb_commutation_instants,
    coulomb_fit,
    criterion_costs,
    criterion_window,
    likelihood_ratio,
    search_edges,
    viscous_fit,
)
from .hyper import _learned_attribute, init_repr
from .record import as_records, check_prior, check_sampling
from .step import check_held_speeds, check_held_steady, check_step_downs, find_step_down

__all__ = [
    "DEFAULT_DT4",
    "FRICTIONS",
    "FRICTION_LR",
    "CriterionWindow",
    "RegressionIdentifier",
    "TwoStepIdentifier",
    "cost_curve",
    "criterion_costs",
    "criterion_window",
    "search_edges",
]

ArrayLike = Sequence[float] | np.ndarray

#: Paper A's identification time dt_4 in s.
DEFAULT_DT4 = 1.0
#: Friction models of the decay after the step-down (module docstring).
FRICTIONS = ("viscous", "coulomb", "auto")
#: ``friction="auto"`` keeps the Coulomb torques when the likelihood ratio of ``W_1``
#: exceeds this: chi-square with 2 degrees of freedom (fc_M, fc_L) at 99.9 %, so
#: white noise alone calls for them in 1 of 1000 fits with a correct prior.
FRICTION_LR = 13.8155


@dataclass
class _Prepared:
    """What both identifiers check and read before fitting."""

    prior: TwoMassDrive  # without Coulomb torques: the viscous model is paper A's
    given_fc: tuple[float, float]  # the prior's Coulomb torques: where the fit starts
    recs: list
    finals: list
    gains: list[float]
    segments: list[CriterionWindow]
    n_grid: int


def _prepare(est: Any, records: Any, final_records: Any = None, *,
             checked: bool = False) -> _Prepared:
    """The shared preamble of the fits: hyperparameters checked, records read, refused
    or warned (step-downs, held speeds), and the windows of ``W_1`` cut. ``checked``:
    ``records`` are Records that :func:`as_records` has checked (the joint estimator's
    start); only their sampling against this prior is checked again."""
    prior = check_prior(est.prior)
    v.flag("allow_far_from_prior", est.allow_far_from_prior)
    dt4 = v.positive("dt4", est.dt4)
    level_window = v.positive("level_window", est.level_window)
    n_grid = v.integer("n_grid", est.n_grid, 2)
    if est.friction not in FRICTIONS:
        raise InputError(f"friction must be one of {', '.join(map(repr, FRICTIONS))}, got "
                         f"{est.friction!r}")
    if checked:
        recs = list(records)
        for rec in recs:
            check_sampling(prior, rec)
    else:
        recs = as_records(records, prior=prior)
    finals = recs if final_records is None else as_records(final_records, "final_records",
                                                            prior=prior)
    every = recs + [f for f in finals if all(f is not r for r in recs)]
    check_step_downs(every, prior, stacklevel=3)
    gains = check_held_speeds(every, prior, allow_far_from_prior=est.allow_far_from_prior,
                              stacklevel=3)
    segments = [criterion_window(r, dt4, level_window) for r in finals]
    if not checked:  # the joint fit's start is only a start: it simulates from rest
        check_held_steady(finals, prior)
    viscous = replace(prior, fc_M=0.0, fc_L=0.0, fs_M=None, fs_L=None)
    return _Prepared(viscous, (prior.fc_M, prior.fc_L), recs, finals, gains, segments,
                     n_grid)


def _keeps_coulomb(friction: str, lr: float) -> bool:
    return friction == "coulomb" or (friction == "auto" and lr > FRICTION_LR)


def _viscous_fit(prep: _Prepared, lo: float, hi: float, workers) -> tuple[float, float]:
    return viscous_fit(prep.prior, prep.segments, lo, hi, prep.n_grid, workers)


def _coulomb_fit(prep: _Prepared, lo: float, hi: float, workers,
                 fc: tuple[float, float] | None = None) -> tuple[float, float, tuple]:
    start = prep.given_fc if fc is None else fc
    return coulomb_fit(prep.prior, prep.segments, lo, hi, prep.n_grid, workers, start)


def _likelihood_ratio(prep: _Prepared, viscous_cost: float, coulomb_cost: float) -> float:
    return likelihood_ratio(prep.segments, viscous_cost, coulomb_cost)



class TwoStepIdentifier:
    """Paper A's two-step backlash identification (Section 4.3, steps 4-8).

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters ``P_hat`` (its ``theta`` is ignored).
    n_theta : float, optional
        Relative half-width of the final search interval around the pre-estimate,
        ``0 < n_theta < 1`` (default 0.1).
    cutoff_motor, cutoff_load : float, optional
        FIR cut-offs in rad/s for the motor and load speeds (default 50 and 20).
    numtaps : int, optional
        FIR length (odd); default per cut-off (see :func:`fir_lowpass`).
    dt1, dt2, dt3 : float, optional
        Windows of eq. 9 in s; default from the data (module docstring).
    dt4 : float, optional
        Span of ``W_1`` after ``t_s`` in s (default 1).
    anchor : {"sample", "fit"}, optional
        Amplitude of the decay in eq. 9 (see :func:`commutation_instants`).
    onset : {"constant", "unloading"}, optional
        Load speed before ``t_c`` in eq. 9: the paper's constant (default) or the
        unloading shaft's cubic fall (see :func:`commutation_instants`).
    level_window : float, optional
        Span in s before ``t_s`` over which the speed level that starts the model is
        averaged (default 1).
    n_grid : int, optional
        Grid points of the final search before refinement (default 21).
    friction : {"viscous", "coulomb", "auto"}, optional
        Friction model of the decay after the step-down (module docstring, "Coulomb
        friction"): paper A's viscous one (default), with Coulomb torques ``fc_M``,
        ``fc_L`` fitted, or the Coulomb one only where the likelihood-ratio test
        (:data:`FRICTION_LR`) calls for it.
    allow_far_from_prior : bool, optional
        Answer even when a record's held speeds are more than
        :data:`~backlashkit.identify.step.REFUSE_FROM_PRIOR` times the prior's (default
        False: refused, a unit mistake being likelier).
    workers : int, optional
        Threads for the simulations (default all cores).

    Attributes
    ----------
    theta_ : float
        Final estimate of the backlash half-width in rad.
    theta_ini_ : float
        Pre-estimate (eq. 6, mean over the records) in rad.
    theta_ini_per_record_ : list of float
        Eq. 6 per record, rad.
    commutations_ : list of Commutation
        ``t_s``, ``t_c``, ``t_b`` and windows per record.
    t_c_, t_b_ : list of float
        Per-record contact-loss and impact instants in s.
    bounds_ : tuple of float
        Final search interval ``theta_ini (1 -+ n_theta)`` in rad.
    cost_ : float
        ``W_1`` at ``theta_`` in (rad/s)^2.
    search_edges_ : list of str
        The ends of ``bounds_`` that ``theta_`` sits on (:func:`search_edges`; each
        warned with a :class:`~backlashkit.errors.SearchEdgeWarning`).
    friction_ : str
        The friction model of the results, ``"viscous"`` or ``"coulomb"``.
    fc_M_, fc_L_ : float
        Motor and load Coulomb torques in N m of that model (0 for ``"viscous"``: the
        prior's own, where it gives them, only start the Coulomb fit).
    friction_lr_ : float
        The likelihood ratio ``N ln(W_1 viscous / W_1 Coulomb)`` that ``"auto"``
        compared with :data:`FRICTION_LR` (NaN for a forced model).
    held_speed_gains_ : list of float
        :func:`held_speed_gain` per record (``records``, then the ``final_records``
        not among them): the held speeds over the prior's; one more than
        :data:`FAR_FROM_PRIOR` times off 1 raises a
        :class:`~backlashkit.errors.PriorMismatchWarning`.
    """

    method = "two-step"

    __getattr__ = _learned_attribute

    def __init__(
        self,
        prior: TwoMassDrive,
        *,
        n_theta: float = 0.1,
        cutoff_motor: float = 50.0,
        cutoff_load: float = 20.0,
        numtaps: int | None = None,
        dt1: float | None = None,
        dt2: float | None = None,
        dt3: float | None = None,
        dt4: float = DEFAULT_DT4,
        anchor: str = "sample",
        onset: str = "constant",
        level_window: float = 1.0,
        n_grid: int = 21,
        friction: str = "viscous",
        allow_far_from_prior: bool = False,
        workers: int | None = None,
    ) -> None:
        self.prior = prior
        self.n_theta = n_theta
        self.cutoff_motor = cutoff_motor
        self.cutoff_load = cutoff_load
        self.numtaps = numtaps
        self.dt1, self.dt2, self.dt3, self.dt4 = dt1, dt2, dt3, dt4
        self.anchor = anchor
        self.onset = onset
        self.level_window = level_window
        self.n_grid = n_grid
        self.friction = friction
        self.allow_far_from_prior = allow_far_from_prior
        self.workers = workers

    def __repr__(self) -> str:
        text = init_repr(self)
        if not hasattr(self, "theta_"):
            return text
        return f"{text}: theta_ = {self.theta_:.4g} rad, friction_ = {self.friction_!r}"

    def fit(self, records, final_records=None) -> TwoStepIdentifier:
        """Identify the backlash.

        Parameters
        ----------
        records : Record, tuple or sequence of them
            Step-down experiments for the pre-estimate (paper A's step 3,
            ``a_1 = 0.1 a_max``); a record may be a tuple ``(t, torque, w_motor,
            w_load)``.
        final_records : Record, tuple or sequence of them, optional
            Step-down experiments for the final least squares (step 7,
            ``a_2 = 0.6 a_max``); default ``records``.

        Returns
        -------
        TwoStepIdentifier
            ``self``, fitted.

        Raises
        ------
        InputError
            If a parameter is invalid, a record is no step-down experiment
            (:func:`~backlashkit.identify.step.check_step_down`), its held speeds are
            more than :data:`~backlashkit.identify.step.REFUSE_FROM_PRIOR` times the
            prior's (unless ``allow_far_from_prior``), the drive is still speeding up at
            a final record's step-down
            (:func:`~backlashkit.identify.step.check_held_steady`), or it has no
            commutation the method can use, or a pre-estimate that is not positive (each
            message names the record).

        Warns
        -----
        PriorMismatchWarning
            If a record's held speeds are more than :data:`FAR_FROM_PRIOR` times off
            the prior's response (:func:`held_speed_gain`).
        StepDownWarning
            If a record steps down more than once (the largest step-down is used).
        SearchEdgeWarning
            If ``theta_`` sits at an end of the search interval.
        """
        self._check()
        return self._fit(_prepare(self, records, final_records))

    def _fit_checked(self, records: list) -> TwoStepIdentifier:
        """:meth:`fit` of Records that :func:`as_records` has checked (the joint
        estimator's start, which would check them again for its own ``fit``)."""
        self._check()
        return self._fit(_prepare(self, records, checked=True))

    def _check(self) -> None:
        """The hyperparameters that :meth:`fit` checks before it reads the records."""
        n_theta = v.positive("n_theta", self.n_theta)
        if not n_theta < 1:
            raise InputError(f"n_theta must be < 1, got {self.n_theta!r}")
        # named here: the filter would only say "cutoff", not which one
        v.positive("cutoff_motor", self.cutoff_motor)
        v.positive("cutoff_load", self.cutoff_load)

    def _fit(self, prep: _Prepared) -> TwoStepIdentifier:
        """:meth:`fit` of the prepared records."""
        n_theta, prior = self.n_theta, prep.prior
        comms, inis = self._pre_estimates(prep, 0.0)
        lo, hi = _interval(inis, n_theta)
        fc = (0.0, 0.0)  # the viscous model's
        lr = math.nan
        if self.friction != "coulomb":
            theta, cost = _viscous_fit(prep, lo, hi, self.workers)
        if self.friction != "viscous":
            # round 1 within the viscous pre-estimate's interval gives fc_L for eq. 9
            _, _, fc_c = _coulomb_fit(prep, lo, hi, self.workers)
            comms_c, inis_c = self._pre_estimates(prep, fc_c[1] / prior.J_L)
            lo_c, hi_c = _interval(inis_c, n_theta)
            theta_c, cost_c, fc_c = _coulomb_fit(prep, lo_c, hi_c, self.workers, fc_c)
            if self.friction == "auto":
                lr = _likelihood_ratio(prep, cost, cost_c)
            if _keeps_coulomb(self.friction, lr):
                comms, inis, lo, hi = comms_c, inis_c, lo_c, hi_c
                theta, cost, fc = theta_c, cost_c, fc_c
        self.theta_, self.cost_ = theta, cost
        self.friction_ = "coulomb" if _keeps_coulomb(self.friction, lr) else "viscous"
        self.fc_M_, self.fc_L_ = float(fc[0]), float(fc[1])
        self.friction_lr_ = lr
        self.search_edges_ = search_edges(self.theta_, lo, hi,
                                          advice=(" (widen ", Option("n_theta", None), ")"),
                                          stacklevel=4)  # fit's caller
        self.theta_ini_ = float(np.mean(inis))
        self.theta_ini_per_record_ = inis
        self.commutations_ = comms
        self.t_c_ = [c.t_c for c in comms]
        self.t_b_ = [c.t_b for c in comms]
        self.bounds_ = (lo, hi)
        self.held_speed_gains_ = prep.gains
        return self

    def _pre_estimates(self, prep: _Prepared, decel: float) -> tuple[list, list[float]]:
        """Eq. 9 and eq. 6 per record, the load's Coulomb deceleration ``decel``
        (rad/s^2) in eq. 9's decay."""
        alpha = prep.prior.f_L / prep.prior.J_L
        comms, inis = [], []
        for rec in prep.recs:
            com = commutation_instants(
                rec, alpha, dt1=self.dt1, dt2=self.dt2, dt3=self.dt3, anchor=self.anchor,
                onset=self.onset,
            )
            com = coulomb_commutation_instants(rec, com, alpha, decel, anchor=self.anchor,
                                               onset=self.onset)
            for name, cut in (("cutoff_motor", self.cutoff_motor),
                              ("cutoff_load", self.cutoff_load)):
                if not cut < math.pi / rec.ts:
                    raise InputError(
                        f"{name} must be below the Nyquist frequency pi/ts = "
                        f"{math.pi / rec.ts:.6g} rad/s of {rec.name}, got {cut!r}"
                    )
            span = (com.i_c, com.i_b + 1)  # eq. 6's integral alone
            wmf = fir_lowpass(rec.w_motor, self.cutoff_motor, rec.ts, numtaps=self.numtaps,
                              span=span)
            wlf = fir_lowpass(rec.w_load, self.cutoff_load, rec.ts, numtaps=self.numtaps,
                              span=span)
            ini = pre_estimate(wmf, wlf, rec.ts, 0, wmf.size - 1)
            if not ini > 0:
                raise InputError(
                    f"{rec.name}: the backlash pre-estimate, half the integral of the "
                    f"load speed minus the motor speed from the contact loss at "
                    f"t = {com.t_c:.6g} s to the impact at t = {com.t_b:.6g} s, is "
                    f"{ini:.3g} rad; it must be positive: the speeds show no usable passage "
                    "through the backlash there (record a step-down to 0 with less noise "
                    "on the load speed, or give the contact instants as ", Option("dt1", None),
                    ", ", Option("dt2", None), ", ", Option("dt3", None), ")")
            comms.append(com)
            inis.append(ini)
        return comms, inis


def _interval(inis: list[float], n_theta: float) -> tuple[float, float]:
    """The final search interval ``theta_ini (1 -+ n_theta)``."""
    theta_ini = float(np.mean(inis))
    return theta_ini * (1 - n_theta), theta_ini * (1 + n_theta)


class RegressionIdentifier:
    """Paper A's baseline (Table 2): least squares on ``w_M`` over ``[0, theta_max]``.

    The criterion is ``W_1`` of :class:`TwoStepIdentifier` (model started at the
    measured steady state at ``t_s``, span ``dt4``) without the pre-estimate: a grid of
    ``n_grid`` points over ``[0, theta_max]`` and a bounded refinement around its best
    point.

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters (its ``theta`` is ignored).
    theta_max : float, optional
        Upper end of the search in rad (default 15 deg).
    dt4 : float, optional
        Span of the criterion after ``t_s`` in s (default 1).
    level_window : float, optional
        Span in s before ``t_s`` for the speed level that starts the model (default 1).
    n_grid : int, optional
        Grid points (default 61, a step of 0.25 deg over 15 deg).
    friction : {"viscous", "coulomb", "auto"}, optional
        Friction model of the decay after the step-down (module docstring, "Coulomb
        friction"): paper A's viscous one (default), with Coulomb torques ``fc_M``,
        ``fc_L`` fitted, or the Coulomb one only where the likelihood-ratio test
        (:data:`FRICTION_LR`) calls for it.
    allow_far_from_prior : bool, optional
        Answer even when a record's held speeds are more than
        :data:`~backlashkit.identify.step.REFUSE_FROM_PRIOR` times the prior's (default
        False: refused, a unit mistake being likelier).
    workers : int, optional
        Threads for the simulations (default all cores).

    Attributes
    ----------
    theta_ : float
        Estimate of the backlash half-width in rad.
    cost_ : float
        Criterion at ``theta_`` in (rad/s)^2.
    t_s_ : list of float
        Step-down instant per record in s.
    search_edges_ : list of str
        The ends of ``[0, theta_max]`` that ``theta_`` sits on (:func:`search_edges`;
        each warned with a :class:`~backlashkit.errors.SearchEdgeWarning`).
    friction_ : str
        The friction model of the results, ``"viscous"`` or ``"coulomb"``.
    fc_M_, fc_L_ : float
        Motor and load Coulomb torques in N m of that model (0 for ``"viscous"``: the
        prior's own, where it gives them, only start the Coulomb fit).
    friction_lr_ : float
        The likelihood ratio ``N ln(W_1 viscous / W_1 Coulomb)`` that ``"auto"``
        compared with :data:`FRICTION_LR` (NaN for a forced model).
    held_speed_gains_ : list of float
        :func:`held_speed_gain` per record: the held speeds over the prior's; one more
        than :data:`FAR_FROM_PRIOR` times off 1 raises a
        :class:`~backlashkit.errors.PriorMismatchWarning`.
    """

    method = "regression"

    __getattr__ = _learned_attribute

    def __init__(
        self,
        prior: TwoMassDrive,
        *,
        theta_max: float = float(np.deg2rad(15.0)),
        dt4: float = DEFAULT_DT4,
        level_window: float = 1.0,
        n_grid: int = 61,
        friction: str = "viscous",
        allow_far_from_prior: bool = False,
        workers: int | None = None,
    ) -> None:
        self.prior = prior
        self.theta_max = theta_max
        self.dt4 = dt4
        self.level_window = level_window
        self.n_grid = n_grid
        self.friction = friction
        self.allow_far_from_prior = allow_far_from_prior
        self.workers = workers

    def __repr__(self) -> str:
        text = init_repr(self)
        if not hasattr(self, "theta_"):
            return text
        return f"{text}: theta_ = {self.theta_:.4g} rad, friction_ = {self.friction_!r}"

    def fit(self, records) -> RegressionIdentifier:
        """Identify the backlash.

        Parameters
        ----------
        records : Record, tuple or sequence of them
            Step-down experiments (paper A: ``a_2 = 0.6 a_max``).

        Returns
        -------
        RegressionIdentifier
            ``self``, fitted.

        Raises
        ------
        InputError
            If a parameter is invalid, a record is no step-down experiment
            (:func:`~backlashkit.identify.step.check_step_down`), its held speeds are
            more than :data:`~backlashkit.identify.step.REFUSE_FROM_PRIOR` times the
            prior's (unless ``allow_far_from_prior``), or the drive is still speeding up
            at its step-down (:func:`~backlashkit.identify.step.check_held_steady`).

        Warns
        -----
        PriorMismatchWarning
            If a record's held speeds are more than :data:`FAR_FROM_PRIOR` times off
            the prior's response (:func:`held_speed_gain`).
        StepDownWarning
            If a record steps down more than once (the largest step-down is used).
        SearchEdgeWarning
            If ``theta_`` sits at an end of the search interval.
        UserWarning
            If ``theta_max`` is over :data:`~backlashkit.validate.THETA_DEGREES_LIKELY`
            rad (degrees written as rad?).
        """
        theta_max = v.positive("theta_max", self.theta_max)
        note = v.degrees_note("theta_max", theta_max)
        if note is not None:
            warnings.warn(note, UserWarning, stacklevel=2)
        prep = _prepare(self, records)
        fc = (0.0, 0.0)  # the viscous model's
        lr = math.nan
        if self.friction != "coulomb":
            theta, cost = _viscous_fit(prep, 0.0, theta_max, self.workers)
        if self.friction != "viscous":
            theta_c, cost_c, fc_c = _coulomb_fit(prep, 0.0, theta_max, self.workers)
            if self.friction == "auto":
                lr = _likelihood_ratio(prep, cost, cost_c)
            if _keeps_coulomb(self.friction, lr):
                theta, cost, fc = theta_c, cost_c, fc_c
        self.theta_, self.cost_ = theta, cost
        self.friction_ = "coulomb" if _keeps_coulomb(self.friction, lr) else "viscous"
        self.fc_M_, self.fc_L_ = float(fc[0]), float(fc[1])
        self.friction_lr_ = lr
        self.held_speed_gains_ = prep.gains
        self.search_edges_ = search_edges(self.theta_, 0.0, theta_max)
        self.t_s_ = [find_step_down(r)[1] for r in prep.recs]
        return self


def cost_curve(
    prior: TwoMassDrive,
    records: Any,
    thetas: Sequence[float] | np.ndarray,
    *,
    dt4: float = DEFAULT_DT4,
    level_window: float = 1.0,
    workers: int | None = None,
) -> np.ndarray:
    """Paper A's criterion ``W_1(theta)`` (sum over records) on a grid of ``theta``.

    The same criterion as the final step of
    :class:`~backlashkit.identify.TwoStepIdentifier`: squared error of the motor speed
    over ``[t_s, t_s + dt4]``, the model ``prior.with_theta(theta)`` started at the
    measured steady state (simulated with :func:`backlashkit.simulate_batch`).

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters.
    records : Record or sequence of Record
        Step-down experiments.
    thetas : array_like
        Backlash half-widths in rad, >= 0.
    dt4 : float, optional
        Span of the criterion after ``t_s`` in s (default 1).
    level_window : float, optional
        Span in s before ``t_s`` over which the starting speed is averaged (default 1).
    workers : int, optional
        Threads for the simulations (default all cores).

    Returns
    -------
    numpy.ndarray
        ``W_1`` in (rad/s)^2 per entry of ``thetas``.
    """
    recs = as_records(records)
    th = np.asarray(thetas, float).reshape(-1)
    if th.size == 0 or not np.isfinite(th).all() or (th < 0).any():
        raise InputError("thetas must be a non-empty array of finite values >= 0 (rad)")
    segments = [criterion_window(r, dt4, level_window) for r in recs]
    return criterion_costs(prior, segments, th, workers)
