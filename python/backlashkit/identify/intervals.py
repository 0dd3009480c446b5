"""Where the joint estimator's 95 % interval of ``theta`` comes from.

Configuration objects for ``JointIdentifier(interval=...)``:

* :class:`ProfileLikelihood` (the default) -- the profile-likelihood interval: every
  ``theta`` whose best fit, the other parameters re-optimised with ``theta`` held,
  costs at most ``chi2_1(0.95) = 3.84`` more than the estimate (Wilks). It follows the
  likelihood where it is not quadratic (a backlash of a few standard errors, a
  rattling shaft), so it may be asymmetric.
* :class:`FisherInterval` -- ``theta_ -+ 1.96 std_`` from the Gauss-Newton / Fisher
  information at the optimum (the quadratic approximation of the same likelihood).
* :class:`ParametricBootstrap` -- refits of records simulated from the estimate.

On encoder angles of known step, the profile and Fisher intervals assume a white noise
that quantisation is not; the fit replaces them by the spread of ``theta`` over the
encoders' offsets within a count (kind ``"quantisation"``:
:mod:`backlashkit.identify._quantised`), and the bootstrap reads its resamples through
the encoders.

Each object computes its own interval from what the fit hands it
(:class:`IntervalInputs`); the search for the profile's crossings
(:func:`profile_crossing`) is here too. The fit itself lives in
:mod:`backlashkit.identify.joint`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError
from ..parallel import map_tasks, reporter, root_seed
from ._lm import LMState, lm

__all__ = ["FisherInterval", "ParametricBootstrap", "ProfileLikelihood", "profile_crossing",
           "reaches_zero"]

#: ``progress(done, total)``: a report of the refits done.
Progress = Callable[[int, int], None]

#: chi-square quantile with one degree of freedom at 95 % (1.959964 ** 2).
CHI2_95 = 3.841458820694124
#: Normal 97.5 % quantile rounded as the Fisher interval has always used it.
Z_95 = 1.96
#: First distance (log theta) of the profile search when the Fisher error is 0.
PROFILE_FIRST_STEP = 0.05
#: Where a profile may fall again past its first crossing (``IntervalInputs.look_past``),
#: it is looked at this fraction of the end's distance further out. On the second drive
#: of ``benchmarks/real_drive.py`` with friction and a current loop (``--trial 18``),
#: the profile of ``theta`` rose to 3.79 at its first crossing and fell to 2.65 a
#: quarter further out; the truth lay beyond.
LOOK_PAST = 0.25
#: Largest upper end (rad) of a profile followed in rad of theta: a backlash half-width
#: of half a turn is no gear's, and records that do not bound theta below it do not
#: bound it at all.
MAX_HALF_WIDTH = math.pi
#: Looks past an end at most, per side.
LOOKS_PAST = 2
#: Iterations of an end's refit from the prior's point before it must be below the
#: refit continued from the estimate: one climbing back to the same basin is still
#: far above it then (paper A's records from a prior 30 % off), one falling into a
#: lower basin already below (as the search's restarts, ``_search.RESTART_SCREEN_ITER``).
RECHECK_SCREEN_ITER = 5
#: An end is refitted from the prior's point only where that point's cost exceeds the
#: estimate's by at most this times the estimate's own (chi-square units: its errors
#: then hardly exceed the noise). Farther, its model is out of phase with the
#: records' ringing, and a refit from there climbs back through the ringing's basins.
#: On paper A's records from a prior 30 % off, the 20 such refits of seeds 0-9 started
#: 3.0 to 59 times the estimate's cost above it and none lowered an end; on the second
#: drive of ``benchmarks/real_drive.py`` with Coulomb friction at 30 dB and a prior at
#: the truth, the 204 of trials 0-99 started within 0.11 times it, and the 3 that
#: lowered an end within 0.026 (``benchmarks/screen_iterations.py --no-far``).
RECHECK_FAR = 1.0
#: A held-theta refit stops once a step lowers its cost by less than this (chi-square
#: units; the fit's own refinements go on to ``_lm.FINAL_ATOL``): the rise is wanted to within
#: ``tol`` (0.25) of 3.84, and the last steps of a slow valley (a Coulomb torque
#: trading against viscous friction) gain hundredths each.
PROFILE_ATOL = 0.01


def reaches_zero(theta: float, std: float) -> bool:
    """Whether the Fisher interval ``theta -+ 1.96 std`` of ``theta`` (rad) reaches 0:
    there the profile is followed in rad of ``theta``, not its logarithm
    (:class:`ProfileLikelihood`).

    Parameters
    ----------
    theta : float
        The estimate in rad.
    std : float
        Its Fisher standard error in rad.

    Returns
    -------
    bool
        True where ``theta <= 1.96 std``.
    """
    return theta <= Z_95 * std


@dataclass
class IntervalInputs:
    """What a fit hands its interval object.

    ``z`` are the log-parameters at the estimate (``theta`` first), ``cov_z`` their
    Fisher covariance, ``cost`` the cost there (chi-square units), ``residual`` the
    weighted residual rows of log-parameter rows, ``resample(rng)`` one record set
    simulated from the estimate with noise drawn from ``rng``, and ``refit(records)``
    the ``theta`` of the same fit on it (a picklable callable, so that the refits can
    run in other processes). ``jacobian(z)``, where given, is the exact Jacobian of
    ``residual`` at one point in the log-parameters other than ``theta``'s, which a
    profile refit holds (rows by log-parameter, from the compiled sensitivities), or
    None where it does not exist there; the profile's refits then difference
    ``residual`` instead. ``look_past``: whether the profile may rise and fall again
    past its first crossing (a current loop's lag, fitted after the search, trading
    against the linear parameters along a curved valley), so that its ends are looked
    past (:data:`LOOK_PAST`). ``anchor``, where given, is a second start of the
    other log-parameters for the refits at the profile's ends (the prior's linear
    parameters, the added terms as estimated): the refits continued from the estimate
    keep to its basin, and another basin can lie lower there. ``rivals``: other minima
    of the cost, as ``(z, cost)``, within ``CHI2_95`` of the estimate's and in other
    basins (the search's restarts found them); the profile is the lowest over all
    basins, so its interval spans theirs too.
    """

    theta: float
    std: float
    z: np.ndarray
    cov_z: np.ndarray
    cost: float
    residual: Callable[[np.ndarray], np.ndarray]
    fd_step: float
    resample: Callable[[np.random.Generator], list]
    refit: Callable[[list], float]
    jacobian: Callable[[np.ndarray], np.ndarray | None] | None = None
    look_past: bool = False
    anchor: np.ndarray | None = None
    rivals: list[tuple[np.ndarray, float]] = field(default_factory=list)


@dataclass
class ThetaInterval:
    """An interval of ``theta`` and what its computation found on the way.

    ``lowest_rise`` below 0: a held-theta refit (at log-parameters ``lowest_z``) ended
    below the estimate's cost, so the estimate was not the nearby minimum. ``rivals``:
    the other basins whose profiles the interval spans (:attr:`IntervalInputs.rivals`;
    the joint search counts only those off the floor of the estimate's own basin).
    """

    kind: str
    ci95: tuple[float, float]
    bounded: tuple[bool, bool] = (True, True)
    std: float | None = None  # replaces the Fisher standard error (bootstrap)
    profile: np.ndarray | None = None
    bootstrap_thetas: np.ndarray | None = None
    lowest_rise: float = 0.0
    lowest_z: np.ndarray | None = field(default=None, repr=False)
    rivals: int = 0


@dataclass(frozen=True)
class FisherInterval:
    """95 % interval ``theta_ -+ 1.96 std_`` from the Fisher information.

    ``std_`` is the Gauss-Newton standard error at the optimum (delta method from the
    log-parameters). Cheapest (no extra fit), symmetric, and exact only where the
    likelihood is quadratic over the interval.
    """

    def _interval(self, fit: IntervalInputs) -> ThetaInterval:
        # a half-width is >= 0: the symmetric interval is cut there
        return ThetaInterval("fisher", (max(0.0, fit.theta - Z_95 * fit.std),
                                        fit.theta + Z_95 * fit.std))

    def _quantised(self, found: ThetaInterval, theta: float, errors: np.ndarray
                   ) -> ThetaInterval:
        return quantisation_interval(theta, errors)


@dataclass(frozen=True)
class ProfileLikelihood:
    """95 % interval of ``theta`` from its profile likelihood.

    For a held ``theta`` the other estimated parameters are refitted
    (Levenberg-Marquardt from the estimate shifted along the Fisher covariance, its
    Jacobians from the compiled sensitivities where they cover the model); the
    interval ends are the ``theta`` on either side where that refit costs
    ``3.84`` (chi-square units, i.e. ``-2 log`` likelihood ratio) more than the
    estimate. The search starts at the Fisher ends ``theta_ exp(-+1.96 s)`` (``s`` the
    Fisher standard error of ``log theta``) and moves by the square-root law
    ``sqrt(cost rise)`` proportional to the distance (secant steps once bracketed),
    until the rise is within ``tol`` of 3.84. ``std_`` stays the Fisher standard error.
    Where the fit keeps a current loop's lag found after the search, the profile can
    fall again past a crossing (along the lag's curved valley): each end is then
    looked past by a quarter of its distance (``LOOK_PAST``, at most twice), and the
    search goes on outwards where the rise there is still below 3.84. Each end is also
    refitted from the prior's point (the linear parameters at the prior's, the added
    terms as estimated; ``Restarts(prior=True)``, the default), unless that point
    costs more than twice the estimate's cost (``RECHECK_FAR``: a prior too far off
    to be near any basin of these records): the refits continued
    from the estimate keep to its basin, and where the other basin is lower there the
    search goes on outwards from it (on the second drive of
    ``benchmarks/real_drive.py`` with Coulomb friction at 30 dB, several
    intervals left out the truth that way; docs/validation/real-drives.md). Where the
    search found other minima within 3.84 above the estimate in other basins
    (``IntervalInputs.rivals``), the profile follows each one's too, outwards on its
    side away from the estimate, and the interval spans them all.

    Where the shaft rattles the profile is rough at the scale of a chi-square unit: a
    refit held at ``theta`` can end below the estimate's cost. The rise is then taken
    as 0 and the search goes on outwards; and when the lowest refit is more than 0.5
    below, the estimate itself was not the nearby minimum: the joint fit refines all
    parameters again from that refit and searches the profile around the new estimate
    (at most twice; ``RECENTRE_MARGIN``, ``RECENTRE_MAX`` in
    :mod:`backlashkit.identify._search`). An end that does not reach 3.84 within a
    factor ``max_factor`` of ``theta_`` is reported at that factor: the records do not
    bound ``theta`` there.

    Where the Fisher interval reaches 0 (``theta_ <= 1.96 std_``: a drive with no
    backlash, or less than the records resolve), the logarithm's distances cannot reach
    it: the profile is followed in rad of ``theta`` instead, from the estimate down to
    ``theta = 0`` (the other parameters refitted there) and up to ``max_factor`` times
    the larger of ``theta_`` and ``1.96 std_`` (at most :data:`MAX_HALF_WIDTH`). The
    lower end is 0, bounded, where the profile at ``theta = 0`` stays below 3.84: the
    records are consistent with a drive without backlash, and the upper end is the
    largest backlash they allow. The lower side of any other profile that does not
    reach 3.84 within ``max_factor`` is followed down to 0 the same way.

    Parameters
    ----------
    tol : float, optional
        Accepted distance of the cost rise from 3.84 in chi-square units (default
        0.25: about 3 % of the half-width).
    max_evaluations : int, optional
        Refits per side at most (default 6); the last bracket is then interpolated.
    max_iter : int, optional
        Levenberg-Marquardt iterations per refit (default 20).
    max_factor : float, optional
        Widest interval searched: ``[theta_ / max_factor, theta_ max_factor]``
        (default 10).
    """

    tol: float = 0.25
    max_evaluations: int = 6
    max_iter: int = 20
    max_factor: float = 10.0

    def __post_init__(self) -> None:
        if not (isinstance(self.tol, (int, float)) and 0.0 < self.tol < CHI2_95):
            raise InputError(f"tol must be in (0, {CHI2_95:.3f}) (chi-square units), "
                             f"got {self.tol!r}")
        v.integer("max_evaluations", self.max_evaluations, 1)
        v.integer("max_iter", self.max_iter, 1)
        if not (isinstance(self.max_factor, (int, float)) and self.max_factor > 1.0
                and math.isfinite(self.max_factor)):
            raise InputError(f"max_factor must be a finite number > 1, got {self.max_factor!r}")

    def _interval(self, fit: IntervalInputs) -> ThetaInterval:
        cov_z = fit.cov_z
        s_z = math.sqrt(cov_z[0, 0]) if cov_z[0, 0] > 0 else 0.0
        first = Z_95 * s_z if s_z > 0 else PROFILE_FIRST_STEP
        recheck = fit.anchor is not None and bool(fit.anchor.size)
        # where theta's Fisher interval reaches 0, the logarithm's distances cannot reach
        # it: the profile is followed in rad of theta, down to no backlash at all
        near_zero = reaches_zero(fit.theta, fit.std)
        # the widest upper end
        top = min(self.max_factor * max(fit.theta, Z_95 * fit.std), MAX_HALF_WIDTH)
        searches = [_HeldTheta(fit, self.max_iter, natural=near_zero)]
        if near_zero:
            ends = [self._natural_end(searches[0], sign, Z_95 * fit.std, fit.look_past,
                                      recheck, top) for sign in (-1.0, 1.0)]
        else:
            ends = self._ends(searches[0], first, fit.look_past, recheck)
            if not ends[0][1]:  # not bounded within max_factor below: on down to 0
                searches.append(_HeldTheta(fit, self.max_iter, natural=True))
                ends[0] = self._natural_end(searches[1], -1.0, Z_95 * fit.std,
                                            fit.look_past, recheck, top)
        for z_r, cost_r in fit.rivals:  # the profile is the lowest over every basin
            side = 1.0 if z_r[0] > fit.z[0] else -1.0  # the side the rival's end is on
            found = self._rival_end(fit, z_r, cost_r, side, first, near_zero, top)
            if found is None:
                continue
            end, other = found
            k = int(side > 0)
            if (end[0] - ends[k][0]) * side > 0:
                ends[k] = end
            searches.append(other)
        evaluated = [e for search in searches for e in search.evaluated]
        # a refit at theta = 0 (log theta -inf) is no point to refine the estimate from
        lowest = min((e for e in evaluated if math.isfinite(e[1][0])), key=lambda e: e[0])
        points = np.array(sorted((math.exp(zz[0]), r) for r, zz in evaluated))
        return ThetaInterval("profile", (ends[0][0], ends[1][0]), (ends[0][1], ends[1][1]),
                             profile=points, lowest_rise=float(lowest[0]),
                             lowest_z=lowest[1], rivals=len(fit.rivals))

    def _rival_end(self, fit: IntervalInputs, z_r: np.ndarray, cost_r: float, side: float,
                   first: float, near_zero: bool, top: float
                   ) -> tuple[tuple[float, bool], _HeldTheta] | None:
        """The end of a rival basin's profile (at ``z_r``, ``cost_r``) on its ``side``
        away from the estimate, and its search; None where it lies beyond the estimate's
        own search (``top``, or ``max_factor`` in log theta). Between the two lies the
        estimate's basin."""
        other = _HeldTheta(replace(fit, z=z_r, anchor=None), self.max_iter,
                           cost_r - fit.cost, natural=near_zero)
        if near_zero:
            if side > 0 and other.theta0 >= top:
                return None
            return self._natural_end(other, side, Z_95 * fit.std, fit.look_past, False,
                                     top), other
        room = math.log(self.max_factor) - abs(z_r[0] - fit.z[0])
        if room <= 0.0:
            return None
        (end,) = self._ends(other, first, fit.look_past, False, (side,), room)
        return end, other

    def _natural_end(self, search: _HeldTheta, sign: float, first: float, look_past: bool,
                     recheck: bool, top: float) -> tuple[float, bool]:
        """One end ``(theta, bounded)`` of a basin's profile followed in rad of theta
        (``search.natural``): on the lower side (``sign`` -1) 0, bounded, where the
        profile at ``theta = 0`` (refitted from the fit's anchor too, with ``recheck``)
        stays below 3.84 (the records allow no backlash), else its crossing above 0; on
        the upper side its crossing up to ``top`` (rad)."""
        memo: dict[float, np.ndarray] = {}
        rise = partial(search.rise, sign, memo)
        largest = search.theta0 if sign < 0 else top - search.theta0
        if sign < 0 and (rise(largest) < CHI2_95 or (
                recheck and search.recheck(sign, memo, largest) < CHI2_95)):
            return 0.0, True
        d, ok = self._end(rise, min(first, largest), look_past,
                          partial(search.recheck, sign, memo) if recheck else None, largest)
        if sign < 0 and not ok:  # a refit from the anchor lowered it below 3.84 down to 0
            return 0.0, True
        return search.theta0 + sign * d, ok

    def _ends(self, search: _HeldTheta, first: float, look_past: bool, recheck: bool,
              signs: tuple[float, ...] = (-1.0, 1.0), largest: float | None = None
              ) -> list[tuple[float, bool]]:
        """The ends (``theta`` in rad, whether bounded) of one basin's profile
        (``search``) on the sides ``signs`` (-1 lower, +1 upper), each refitted from the
        fit's anchor too (``recheck``), at most ``largest`` (log theta; default
        ``log(max_factor)``) from the basin's ``theta``."""
        out = []
        for sign in signs:
            memo: dict[float, np.ndarray] = {}
            d, ok = self._end(partial(search.rise, sign, memo), first, look_past,
                              partial(search.recheck, sign, memo) if recheck else None,
                              math.log(self.max_factor) if largest is None else largest)
            out.append((math.exp(search.fit.z[0] + sign * d), ok))
        return out

    def _end(self, rise: Callable[[float], float], first: float, look_past: bool,
             recheck: Callable[[float], float] | None = None,
             largest: float | None = None) -> tuple[float, bool]:
        """One side's end: its distance (log theta, at most ``largest``, default
        ``log(max_factor)``) and whether it is bounded. ``recheck(d)``: the rise at
        ``d`` refitted from a second start too."""
        largest = math.log(self.max_factor) if largest is None else largest
        search = partial(profile_crossing, rise, tol=self.tol,
                         max_evaluations=self.max_evaluations, largest=largest)
        d, ok = search(first)
        if ok and recheck is not None and recheck(d) < CHI2_95 - self.tol:
            d, ok = search(d)  # a lower basin at the end: on outwards from there
        for _ in range(LOOKS_PAST if look_past else 0):
            past = d * (1.0 + LOOK_PAST)
            if not ok or past >= largest or rise(past) > CHI2_95 + self.tol:
                break
            d, ok = search(past)  # the profile fell again: on outwards from there
        return d, ok

    def _quantised(self, found: ThetaInterval, theta: float, errors: np.ndarray
                   ) -> ThetaInterval:
        return quantisation_interval(theta, errors)


class _HeldTheta:
    """Refits of a fit's other log-parameters with ``theta`` held: its profile."""

    def __init__(self, fit: IntervalInputs, max_iter: int, rise0: float = 0.0, *,
                 natural: bool = False) -> None:
        """``fit.z``: the basin's minimum, ``rise0`` above ``fit.cost`` (a rival's).
        Distances are in log theta, or with ``natural`` in rad of theta (down to
        ``theta = 0``, which a logarithm only approaches)."""
        self.fit, self.max_iter, self.natural = fit, max_iter, natural
        z, cov_z = fit.z, fit.cov_z
        # the other log-parameters move with theta along the Fisher covariance: the
        # start of every held-theta refit (its exact optimum where the cost is quadratic)
        self.slope = cov_z[1:, 0] / cov_z[0, 0] if cov_z[0, 0] > 0 else np.zeros(z.size - 1)
        self.theta0 = math.exp(z[0])  # the basin's theta, rad
        if natural:  # d log theta = d theta / theta at the basin's minimum
            self.slope = (self.slope / self.theta0 if self.theta0 > 0.0
                          else np.zeros_like(self.slope))
        #: every refit: cost rise and log-parameters (the estimate first)
        self.evaluated: list[tuple[float, np.ndarray]] = [(rise0, z)]
        self._rises: dict[tuple[float, float], float] = {}  # (sign, d) -> rise

    def _residual(self, zt: float, w: np.ndarray) -> np.ndarray:
        try:
            return self.fit.residual(np.r_[zt, w][np.newaxis, :])[0]
        except ValueError:  # a step to a mode too fast for the sample time
            return np.full(1, np.inf)

    def _jacobian(self, zt: float, w: np.ndarray, r: np.ndarray) -> np.ndarray:
        """The other log-parameters' columns: exact where the fit gives them (one
        sensitivity run against ``w.size`` simulations), else forward differences."""
        if self.fit.jacobian is not None:
            exact = self.fit.jacobian(np.r_[zt, w])
            if exact is not None:
                return exact
        m, h = w.size, self.fit.fd_step
        ww = np.repeat(np.r_[zt, w][np.newaxis, :], m, axis=0)
        ww[:, 1:] += h * np.eye(m)
        return ((self.fit.residual(ww) - r) / h).T

    def held(self, sign: float, d: float) -> float:
        """The log theta held at distance ``d`` on the side ``sign`` (``-inf``: theta
        = 0, the end of the natural distances' lower side)."""
        if not self.natural:
            return float(self.fit.z[0] + sign * d)
        theta = self.theta0 + sign * d
        return math.log(theta) if theta > 0.0 else -math.inf

    def rise(self, sign: float, memo: dict[float, np.ndarray], d: float) -> float:
        """Cost rise of the profile at distance ``d`` (log theta, or rad where
        :attr:`natural`) on the side ``sign``; ``memo`` holds that side's refits
        (distance -> other log-parameters)."""
        if (sign, d) in self._rises:  # a look past an end is where the search goes on
            return self._rises[sign, d]
        self._rises[sign, d] = self._rise(sign, memo, d)
        return self._rises[sign, d]

    def recheck(self, sign: float, memo: dict[float, np.ndarray], d: float) -> float:
        """The rise at an end ``d`` already refitted, refitted again from the fit's
        ``anchor``; the lower refit is kept (in ``memo`` too, so that the search
        continues from it)."""
        zt = self.held(sign, d)
        fun, jac = partial(self._residual, zt), partial(self._jacobian, zt)
        r0 = fun(self.fit.anchor)
        start = LMState(np.array(self.fit.anchor, float), r0, float(r0 @ r0), None)
        if not start.cost - self.fit.cost <= RECHECK_FAR * self.fit.cost:
            return self.rise(sign, memo, d)  # out of phase with the records: no basin near
        st = lm(fun, jac, start.z, max_iter=min(RECHECK_SCREEN_ITER, self.max_iter),
                atol=PROFILE_ATOL, state=start)
        rise = st.cost - self.fit.cost
        if not rise < self.rise(sign, memo, d):  # climbing back: the same basin
            return self._rises[sign, d]
        if not st.done and self.max_iter > RECHECK_SCREEN_ITER:
            st = lm(fun, jac, st.z, max_iter=self.max_iter - RECHECK_SCREEN_ITER, state=st,
                    atol=PROFILE_ATOL)
            rise = st.cost - self.fit.cost
        if rise < self.rise(sign, memo, d):
            memo[d] = st.z
            self._rises[sign, d] = rise
            # one point per theta in the profile: the lower refit
            self.evaluated = [e for e in self.evaluated if e[1][0] != zt]
            self.evaluated.append((rise, np.r_[zt, st.z]))
        return self._rises[sign, d]

    def _rise(self, sign: float, memo: dict[float, np.ndarray], d: float) -> float:
        z, cost = self.fit.z, self.fit.cost
        zt = self.held(sign, d)
        if z.size == 1:  # theta alone is estimated: the profile is the cost itself
            r = self._residual(zt, np.empty(0))
            self.evaluated.append((float(r @ r) - cost, np.array([zt])))
            return self.evaluated[-1][0]
        # continue from the nearest refit on this side, moved along the slope
        d0 = min(memo, key=lambda x: abs(x - d)) if memo else 0.0
        w_near = memo[d0] if memo else z[1:]
        w0 = w_near + self.slope * sign * (d - d0)
        fun = partial(self._residual, zt)
        start = None
        if self.natural:
            # near theta = 0 the Fisher slope is the tangent of a curved valley (the
            # friction's split is hardly determined without backlash): where it leads
            # higher than the nearest refit itself, start there
            start = min((LMState(w, r, float(r @ r), None) for w in (w0, w_near)
                         for r in (fun(w),)), key=lambda st_: st_.cost)
        st = lm(fun, partial(self._jacobian, zt), w0, max_iter=self.max_iter,
                atol=PROFILE_ATOL, state=start)
        memo[d] = st.z
        self.evaluated.append((st.cost - cost, np.r_[zt, st.z]))
        return self.evaluated[-1][0]


@dataclass(frozen=True)
class ParametricBootstrap:
    """Standard error and 95 % interval of ``theta`` by parametric bootstrap.

    The identified model is simulated on every record (its own start, the measured
    torque), white Gaussian noise at the estimated levels is added, and the whole fit
    (multi-start included, same options) is repeated ``n_resamples`` times;
    ``std_`` is the standard deviation of the refitted ``theta`` and ``ci95_`` is
    ``theta_ -+ q std_`` with ``q`` Student's 97.5 % quantile for ``n_resamples - 1``
    degrees of freedom (2.05 for 30 refits: the std is itself estimated). It costs
    ``n_resamples`` fits. It is meant for a rattling shaft (light loads, dozens of
    impacts per record) at 20-30 dB, where the estimates scatter more than the Fisher
    standard error says (``benchmarks/robustness_joint.py --bootstrap``; README,
    "Away from paper A's drive").

    Parameters
    ----------
    n_resamples : int, optional
        Refits (default 30; the standard error is then known to about 13 %).
    seed : int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Root of the resamples' noise (default 0): resample ``i`` uses
        ``SeedSequence(seed).spawn(n_resamples)[i]`` (a generator's own SeedSequence:
        :func:`~backlashkit.parallel.root_seed`).
    progress : bool or callable, optional
        Progress of the refits (each takes about as long as the fit itself): True draws
        a :class:`~backlashkit.parallel.ProgressBar` on stderr, which shows nothing
        when stderr is not a terminal; a callable is called ``progress(done,
        n_resamples)`` before the first refit and after every one (e.g. a
        :class:`~backlashkit.parallel.ProgressBar` of the caller, ``quiet`` or not).
        Default False: nothing. Not part of the configuration's equality.
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Where the refits run (:func:`backlashkit.parallel.map_tasks`); default serial.
        The resamples are drawn here, in order, so ``std_`` and ``ci95_`` are the same
        bit for bit whatever runs them. All ``n_resamples`` record sets are held in
        memory at once when the refits run elsewhere. Not part of the equality.
    jobs : int, optional
        Instead of ``executor``: refits on a local pool of this many processes.
    """

    n_resamples: int = 30
    seed: int | np.random.SeedSequence | np.random.Generator = 0
    progress: bool | Progress = field(default=False, compare=False, kw_only=True)
    executor: Any = field(default=None, compare=False, kw_only=True, repr=False)
    jobs: int | None = field(default=None, compare=False, kw_only=True)

    def __post_init__(self) -> None:
        v.integer("n_resamples", self.n_resamples, 2)
        root_seed(self.seed)
        if not (isinstance(self.progress, bool) or callable(self.progress)):
            raise InputError("progress must be True, False or a callable "
                             f"progress(done, total), got {self.progress!r}")
        if self.jobs is not None:
            v.integer("jobs", self.jobs, 1)
            if self.executor is not None:
                raise InputError("give executor or jobs, not both")

    def _interval(self, fit: IntervalInputs) -> ThetaInterval:
        children = root_seed(self.seed).spawn(self.n_resamples)
        with reporter(self.progress, "bootstrap", unit="refit") as bar:
            if self.executor is None and self.jobs in (None, 1):  # one resample at a time
                bar(0, self.n_resamples)
                refitted: list[float] = []
                for child in children:
                    refitted.append(fit.refit(fit.resample(np.random.default_rng(child))))
                    bar(len(refitted), self.n_resamples)
            else:
                samples = [fit.resample(np.random.default_rng(c)) for c in children]
                refitted = map_tasks(fit.refit, samples, executor=self.executor,
                                     jobs=self.jobs, progress=bar)
        thetas = np.array(refitted)
        std = float(np.std(thetas, ddof=1))
        # the std is itself estimated from n_resamples refits: Student's quantile with
        # n_resamples - 1 degrees of freedom, not 1.96 (2.05 for 30 refits, 2.57 for 6)
        from scipy.stats import t as student_t

        half = float(student_t.ppf(0.975, self.n_resamples - 1)) * std
        return ThetaInterval("bootstrap", (max(0.0, fit.theta - half), fit.theta + half),
                             std=std, bootstrap_thetas=thetas)

    def _quantised(self, found: ThetaInterval, theta: float, errors: np.ndarray
                   ) -> ThetaInterval:
        return found  # its resamples are read by encoders like the records


def quantisation_interval(theta: float, errors: np.ndarray) -> ThetaInterval:
    """The 95 % interval and standard error of an estimate ``theta`` whose errors are
    distributed as the draws ``errors`` (the encoders' quantisation:
    :mod:`backlashkit.identify._quantised`): the truth is ``theta`` less an error."""
    lo, hi = np.quantile(errors, [0.025, 0.975])
    return ThetaInterval("quantisation", (max(0.0, theta - hi), theta - lo),
                         std=float(np.std(errors, ddof=1)))


def profile_crossing(rise: Callable[[float], float], first: float, *, level: float = CHI2_95,
                     tol: float = 0.25, max_evaluations: int = 6,
                     largest: float = math.inf) -> tuple[float, bool]:
    """Distance ``d > 0`` at which a profile's cost rise reaches ``level``.

    Parameters
    ----------
    rise : callable
        ``rise(d)``: cost rise (chi-square units) of the profile at distance ``d`` from
        the estimate (on one side, in any coordinate); negative values count as 0.
    first : float
        First distance tried (> 0), e.g. the Fisher half-width.
    level : float, optional
        Target rise (default 3.84, 95 %).
    tol : float, optional
        Accepted ``|rise - level|``.
    max_evaluations : int, optional
        Calls of ``rise`` at most.
    largest : float, optional
        Largest distance searched.

    Returns
    -------
    d : float
        The crossing (or the bracket's interpolation after ``max_evaluations``, or
        ``largest``).
    bounded : bool
        False when the rise stayed below ``level`` up to ``largest`` (or in every
        evaluation): the end is open.

    Notes
    -----
    Near the optimum ``sqrt(rise)`` grows linearly with ``d``, so the steps solve that
    line: through the origin while the crossing is not bracketed (growth at most 4
    times per step), the secant of the bracket once it is.
    """
    target = math.sqrt(level)
    lo, r_lo = 0.0, 0.0  # below the level
    hi = r_hi = None  # above it
    d = min(first, largest)
    for _ in range(max_evaluations):
        value = max(float(rise(d)), 0.0)
        r = math.sqrt(value) if math.isfinite(value) else math.inf
        if abs(value - level) <= tol:
            return d, True
        if r < target:
            lo, r_lo = d, r
            if d >= largest:
                return largest, False
        else:
            hi, r_hi = d, r
        if hi is None:
            d = min(largest, 4.0 * d if r < 0.25 * target else d * target / r)
        elif math.isinf(r_hi):
            d = 0.5 * (lo + hi)
        else:
            d = lo + (target - r_lo) * (hi - lo) / (r_hi - r_lo)
    if hi is None:
        return lo, False
    if math.isinf(r_hi):
        return 0.5 * (lo + hi), True
    return lo + (target - r_lo) * (hi - lo) / (r_hi - r_lo), True


def check_interval(interval) -> None:
    """Refuse what is not one of this module's interval configurations."""
    if not isinstance(interval, (ProfileLikelihood, FisherInterval, ParametricBootstrap)):
        raise InputError(
            "interval must be a ProfileLikelihood, FisherInterval or ParametricBootstrap "
            f"(backlashkit.identify.intervals), got {type(interval).__name__}"
        )
