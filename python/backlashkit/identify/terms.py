"""The terms a real drive adds to paper A's model: Coulomb friction and a current loop.

Paper A's drive has viscous friction only and applies its torque exactly. A real drive
has Coulomb friction on motor and load (``fc_M``, ``fc_L`` in N m: a slipping inertia
feels ``-fc sign(w)`` and sticks where its speed reaches 0 under a smaller torque) and
a current loop between the torque set-point and the motor torque (first order, time
constant ``tau_i`` in s). The joint estimator can fit both beside ``theta`` and the
linear parameters. Each is chosen by a :class:`Term` setting:

* ``friction``: ``"viscous"`` (none), ``"coulomb"`` (``fc_M``, ``fc_L`` fitted) or
  ``"auto"`` (fitted, then kept only where the data call for it);
* ``actuator``: ``None`` (the set-point applied exactly), a
  :class:`~backlashkit.CurrentLoop` (its ``tau_i`` fixed, or fitted about it where
  ``prior_rel_std`` gives ``tau_i`` a std), or ``"auto"`` (``tau_i`` fitted, then kept
  only where the data call for it).

"Where the data call for it" is a likelihood-ratio test: the term is kept if it lowers
``-2 log L`` by more than the chi-square quantile :data:`KEEP_LEVEL` for its number
of parameters, or if it lowers it at all and leaving it out would move ``theta`` by
more than :data:`KEEP_SHIFT` of its standard errors (:meth:`TermChoice.decide`).
Friction is in the whole search and the model without it is refitted from the
result (a viscous model fitted to a drive with Coulomb friction can wander far from
the prior, so it cannot be the search's model). The current loop is tested the other
way round: the model with ``tau_i`` is refitted from the search's result, from
several starts (fitting it through the search costs many times more: its stiff mode
slows every simulation).
The breakaway torque is tied to the Coulomb torque (``fs = fc``): step-down records
hold no information on it, since the motor torque jumps far beyond any breakaway
torque and a load stuck at the end of a decay is never pushed again.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ..actuator import CurrentLoop
from ..errors import InputError, Option
from ..io import UNCERTAIN_TERM_KEYS
from ..plants import TwoMassDrive
from .record import Record
from .step import HELD_UNSTEADY, find_step_down, held_speed_gain, held_unsteady_share

__all__ = [
    "ESTIMATED_FALL", "FRICTION_CHOICES", "KEEP_LEVEL", "KEEP_SHIFT", "PRIOR_PARAMS",
    "SCREEN_DROP", "Term", "chi2_upper", "prior_std_option",
    "TermChoice", "actuator_term", "check_known_loop", "friction_term",
    "MAX_LOOP_RINGING",
]

#: Confidence of the likelihood-ratio test that keeps a term: at 0.99 a term the data
#: do not need is kept in at most 1 % of records (fewer at the boundary fc = 0, where
#: the statistic is a mixture of chi-squares with fewer degrees of freedom), so paper A's
#: ideal records keep the viscous model in at least 99 % of fits.
KEEP_LEVEL = 0.99
#: The terms' parameters a prior may give with a relative std (``prior_rel_std``), as
#: the drive file's ``[uncertainty]`` table may: the Coulomb torques, about the values
#: of the :class:`~backlashkit.TwoMassDrive` prior, and a current loop's time constant,
#: about a known loop's (``actuator=CurrentLoop(tau_i)``: the loop is then fitted, with
#: that prior, instead of held).
PRIOR_PARAMS = UNCERTAIN_TERM_KEYS
#: A term the test would drop is kept anyway where it is estimated (it lowers
#: ``-2 log L`` and the data pin it down) and dropping it moves ``theta`` by more than
#: this many of its standard errors (in the model without it). Keeping a term the
#: drive lacks mostly widens the interval; dropping one it has biases ``theta``. The
#: current loop needs this where the drive also has Coulomb friction: the loop's lag
#: then trades against the Coulomb torques and the linear parameters, so on 8 s
#: records at 40 dB the test dropped it in 69 % of the trials while dropping it moves
#: ``theta`` by a median of 3.3 standard errors, and the intervals covered the truth
#: in 33 % of the trials. Where the drive has no loop, a loop on its floor moves
#: ``theta`` by a median of 0.73-0.80 standard errors (``docs/validation/real-drives.md``).
KEEP_SHIFT = 1.0
#: A term added after the search (the current loop) whose score test at the fit
#: without it predicts a fall of ``-2 log L`` below this (chi-square units) is dropped
#: unfitted (:mod:`backlashkit.identify._score`). Linearised, the fitted term's standard
#: error in logarithms is ``1 / sqrt(fall)``, so below a fall of 1 it is not pinned down
#: and the test drops it whatever the fit finds: a screen at 1 would change no choice
#: if the linearisation were exact. Half of that leaves a factor 2 for the loop's lag,
#: which is not quite linear in its time constant.
SCREEN_DROP = 0.5
#: A term that lowers ``-2 log L`` by more than this share of its test's threshold is
#: estimated (for :meth:`TermChoice.decide`) even where its Fisher standard error at
#: the larger fit exceeds a factor ``e``. On the second drive of the real-drive study
#: the loop's lag lowered ``-2 log L`` by more than 4 while its Fisher check failed
#: (its likelihood is far from quadratic), and dropping it unwidened left ``theta``
#: 3 % off (docs/validation/real-drives.md). Half the 99 % threshold (3.32 for one
#: parameter) is passed by chance by a term the drive lacks in at most about 7 % of
#: fits (the chi-squared tail of one degree of freedom); a fixed fall of 1 (its tail:
#: 32 %) counted a third of them as estimated and spanned their intervals with the
#: other model's, unbounded in some fits of ideal records.
ESTIMATED_FALL = 0.5
#: A model with a term that ends this much higher in ``-2 log L`` than the model without
#: it (which it contains) did not converge: its reason says so (rounding and a stop
#: within ``_lm.FINAL_ATOL`` of an optimum stay far below it).
STOPPED_SHORT = 1.0
#: The smallest :attr:`TermChoice.widening` its reason states, in ``log theta``: the
#: 0.01 % that the clause's two significant digits still show.
PRINTED_WIDENING = 1e-4
#: Values of ``friction``.
FRICTION_CHOICES = ("auto", "viscous", "coulomb")
#: Start of each fitted Coulomb torque when the held levels show none, as a fraction
#: of the largest held torque: a negligible model change, which the fit (in natural
#: units, ``Problem.scales``) moves to 0 within a step where the data show no friction.
FC_START_FLOOR = 1e-3
#: The held speeds must differ by this factor for the line through the levels to give
#: the Coulomb torques' start (:func:`coulomb_start`): closer levels make its intercept
#: an extrapolation that amplifies the speeds' noise (paper A's two levels differ by a
#: factor of about 6).
LEVEL_SPREAD = 1.5
#: Starts of a fitted current-loop time constant, in sample times. The loop is added to
#: the model after the search, from its result: where the drive also has Coulomb
#: friction, that result has traded the loop's lag for friction and backlash, and a
#: refit from one start can walk the lag down to the floor, a local minimum with
#: theta well off the truth even on near noise-free records. The refit therefore
#: starts from each of these, and the lowest goes on.
TAU_START_SAMPLES = (0.5, 1.0, 2.0, 4.0)
#: Smallest current-loop time constant simulated, in sample times. A loop's lag
#: withholds about ``T tau_i`` of impulse at each torque jump, so its effect on the
#: likelihood grows as ``tau_i^2``: on 8 s records of paper A's drive at 40 dB a
#: one-sample loop lowers ``-2 log L`` by a median of 29.5 (``benchmarks/real_drive.py``,
#: the 1 ms loop), so one of a quarter sample by about 2, below the test's threshold.
#: Faster loops are stiff modes that make every simulation several times slower; the
#: fit sees a flat cost below this floor, and the likelihood-ratio test then drops it.
TAU_FLOOR_SAMPLES = 0.25
#: A known current loop's time constant must be below this many periods of the prior's
#: shaft ringing (``TwoMassDrive.ringing_frequency``): a current loop is the fast
#: inner loop of the drive, far faster than the mechanics it drives, and a lag as long
#: as the ringing is a unit slip (1 for 1 ms). The fit with such a loop wandered to
#: parameters the kernel simulates slowly, or was refused for another cause.
MAX_LOOP_RINGING = 1.0
#: Smallest Coulomb torque simulated, relative to the largest torque: the fit moves a
#: Coulomb torque in natural units down to 0, yet the kernel needs every simulated row
#: of a batch to have the same friction switches (a breakaway torque > 0), and one of
#: 1e-12 of the torque changes no speed at working precision.
FC_FLOOR = 1e-12


@dataclass(frozen=True)
class Term:
    """A group of parameters the model adds, and whether to fit or test it.

    Parameters
    ----------
    name : str
        ``"friction"`` or ``"actuator"`` (the hyperparameter that set it).
    params : tuple of str
        The packed names of the parameters it adds.
    mode : {"off", "fixed", "prior", "fit", "auto"}
        Absent, present with fixed values, fitted about them with a prior std (after
        the search, which holds them), fitted, or fitted and tested.
    fixed : tuple of float
        The values when ``mode`` is ``"fixed"`` or ``"prior"``.
    searched : bool
        Whether an ``"auto"`` term is in the whole search (then tested by removing
        it) or only added after it (then tested by adding it).
    prior_std : float or None
        The relative prior std of a ``"prior"`` term's parameters.
    """

    name: str
    params: tuple[str, ...]
    mode: str
    fixed: tuple[float, ...] = ()
    searched: bool = True
    prior_std: float | None = None

    @property
    def fitted(self) -> bool:
        """Whether the whole search fits the term's parameters."""
        return self.mode == "fit" or (self.mode == "auto" and self.searched)

    @property
    def present(self) -> bool:
        """Whether the model has the term at all (fitted or fixed)."""
        return self.mode != "off"

    @property
    def threshold(self) -> float:
        """Rise of ``-2 log L`` (chi-square units) without the term that keeps it."""
        return chi2_upper(len(self.params), 1.0 - KEEP_LEVEL)

    def starts(self, recs: Sequence[Record], prior: TwoMassDrive) -> dict[str, float]:
        """Starting values of the parameters of a term in the whole search (friction;
        the current loop starts from :meth:`start_grid` after the search).

        Parameters
        ----------
        recs : sequence of Record
            The records fitted.
        prior : TwoMassDrive
            The prior; its Coulomb torques, where it gives them, start the fit.

        Returns
        -------
        dict
            Parameter name -> starting value in N m.
        """
        given = (prior.fc_M, prior.fc_L)
        if any(given):
            return dict(zip(self.params, given, strict=True))
        return dict.fromkeys(self.params, coulomb_start(recs, prior))

    def start_grid(self, recs: Sequence[Record]) -> list[dict[str, float]]:
        """Starting values of a term added after the search, one dict per start.

        Parameters
        ----------
        recs : sequence of Record
            The records fitted.

        Returns
        -------
        list of dict
            Parameter name -> starting value in s (:data:`TAU_START_SAMPLES`).
        """
        ts = min(r.ts for r in recs)
        return [dict.fromkeys(self.params, x * ts) for x in TAU_START_SAMPLES]

    def check_prior(self, rel: dict, prior: TwoMassDrive) -> None:
        """Refuse a prior std of the term's parameters that the fit cannot use.

        Parameters
        ----------
        rel : dict
            Parameter name -> relative prior std (``prior_rel_std``, read).
        prior : TwoMassDrive
            The prior; a relative std needs its value > 0.

        Raises
        ------
        InputError
            If the term is not fitted, the std is 0, or the prior's value is 0.
        """
        for n in self.params:
            if n not in rel:
                continue
            given = (f"a relative std of {n} is given (", prior_std_option(n, rel[n]), ")")
            if self.name == "actuator":
                _check_loop_prior(self, given, rel[n])
                continue
            if rel[n] == 0:
                raise InputError(
                    *given, ": a Coulomb torque is fitted, not held at the prior's value; "
                    "give a std > 0 (0.01 for 1 %), or remove it to fit it freely")
            if not self.fitted:
                raise InputError(
                    *given, ", but ", Option(self.name, "viscous"), " does not fit it: use ",
                    Option(self.name, "coulomb"), " or ", Option(self.name, "auto"),
                    ", or remove it")
            if not getattr(prior, n, 0.0) > 0:
                raise InputError(
                    *given, f", but the prior's {n} is 0: give its value in N m (",
                    Option("prior_value", n, python=f"TwoMassDrive({n}=...)"), ")")

    def floors(self, recs: Sequence[Record]) -> dict[str, float]:
        """Smallest values simulated of the fitted parameters.

        Parameters
        ----------
        recs : sequence of Record
            The records fitted (their torques and sample times set the floors).

        Returns
        -------
        dict
            Parameter name -> floor (:data:`FC_FLOOR`, :data:`TAU_FLOOR_SAMPLES`).
        """
        if self.name == "friction":
            return dict.fromkeys(self.params, FC_FLOOR * torque_scale(recs))
        return dict.fromkeys(self.params, TAU_FLOOR_SAMPLES * min(r.ts for r in recs))

    def scales(self, recs: Sequence[Record]) -> dict[str, float]:
        """The fitted parameters estimated in natural units, and their scales.

        Parameters
        ----------
        recs : sequence of Record
            The records fitted.

        Returns
        -------
        dict
            The Coulomb torques -> the largest torque in N m (they are estimated in
            its units); empty for the current loop, whose time constant is estimated
            as a logarithm.
        """
        if self.name != "friction":
            return {}
        return dict.fromkeys(self.params, torque_scale(recs))


#: What the messages call each term.
TERM_NAMES = {"friction": "Coulomb friction", "actuator": "current loop"}


@dataclass(frozen=True)
class TermChoice:
    """What the likelihood-ratio test of one term found.

    Parameters
    ----------
    term : str
        ``"friction"`` or ``"actuator"``.
    kept : bool
        Whether the model keeps it.
    rise : float
        Rise of ``-2 log L`` when it is removed (chi-square units).
    threshold : float
        The rise above which it is kept (:data:`KEEP_LEVEL`).
    shift : float
        How far ``theta`` moves when the term is removed, in standard errors of
        ``theta`` without it (a term below the threshold is kept where this exceeds
        :data:`KEEP_SHIFT`); NaN where the fit without it stopped before converging
        (its ``theta`` is then no answer to compare with).
    other_ci95 : tuple of float or None
        Where the test cannot tell the two models apart (the term estimated, lowering
        ``-2 log L``, but by no more than the threshold): the Fisher 95 % interval of
        ``theta`` in rad of the model not chosen, which the estimate's interval is
        widened to cover. None otherwise.
    screened : bool
        Whether the term was dropped unfitted by its score test (:data:`SCREEN_DROP`);
        ``rise`` and ``shift`` are then the test's linearised predictions.
    determined : bool
        Whether the data pin the term's values down (see :meth:`decide`); a term that
        is not is neither kept for its ``shift`` nor widens the interval.
    widening : tuple of float
        Where the term is dropped: how far down and up, in ``log theta``, the
        estimate's interval reaches out to span ``theta`` at every value of the term
        the data do not rule out (the score test's linearisation,
        :func:`backlashkit.identify._score.held_widening`); (0, 0) where it is kept.
    held_ci95 : tuple of float or None
        Where the term is dropped: the interval of ``theta`` in rad that the model
        without it spans when refitted with the term held at each of its starts
        (:func:`backlashkit.identify._search.held_ci95`), which the estimate's
        interval is widened to cover; None where no held fit lies within the 95 %
        level, or the term is kept.
    """

    term: str
    kept: bool
    rise: float
    threshold: float
    shift: float = 0.0
    other_ci95: tuple[float, float] | None = None
    screened: bool = False
    determined: bool = True
    widening: tuple[float, float] = (0.0, 0.0)
    held_ci95: tuple[float, float] | None = None

    @classmethod
    def decide(cls, term: str, rise: float, threshold: float, shift: float,
               determined: bool = True,
               ci95s: tuple[tuple[float, float], tuple[float, float]] | None = None
               ) -> TermChoice:
        """Keep a term where the data call for it (``rise > threshold``) or where
        leaving it out would move ``theta`` (``shift > KEEP_SHIFT``) and the term is
        estimated (``rise > 0`` and ``determined``).

        Where the term is estimated but the test does not call for it, the data cannot
        tell the two models apart, and the estimate's interval then also covers the
        other model's: which of the two the drive follows is not known, and either
        choice alone leaves its interval too narrow in the trials where it is wrong.

        Parameters
        ----------
        term : str
            ``"friction"`` or ``"actuator"``.
        rise, threshold, shift : float
            As the attributes.
        determined : bool, optional
            Whether the data pin the term's values down (within a factor ``e`` at one
            standard error). A term on its floor is not: a current loop of a quarter
            sample, the smallest simulated, still lags the torque and moves ``theta``,
            yet the data do not show it, and its interval would not widen. A rise
            beyond :data:`ESTIMATED_FALL` of the threshold counts as determined
            whatever this says.
        ci95s : pair of (float, float), optional
            The Fisher 95 % intervals of ``theta`` with the term and without it.

        Returns
        -------
        TermChoice
            The decision.
        """
        # the Fisher check at the larger fit misjudges a lag whose likelihood is far from
        # quadratic; a large enough fall pins it down as well
        determined = determined or rise > ESTIMATED_FALL * threshold
        estimated = rise > 0 and determined
        kept = rise > threshold or (estimated and shift > KEEP_SHIFT)
        other = None
        if estimated and rise <= threshold and ci95s is not None:
            lo, hi = ci95s[1 if kept else 0]
            # a Fisher interval reaching 0 or infinity does not bound theta: no span
            if 0.0 < lo and math.isfinite(hi):
                other = (float(lo), float(hi))
        return cls(term, bool(kept), float(rise), float(threshold), float(shift), other,
                   determined=bool(determined))

    def reason(self) -> str:
        """Say what was chosen and why.

        Returns
        -------
        str
            One sentence.
        """
        name = TERM_NAMES.get(self.term, self.term)
        test = f"likelihood-ratio test at {KEEP_LEVEL:.0%}"
        both = ("; the data cannot tell, so the 95 % interval spans the other model's too"
                if self.other_ci95 is not None else "") + self._widening_words()
        if self.screened:
            # rounded down, so that a drop just under the limit does not print as it
            drop = math.floor(self.rise * 1e3) / 1e3
            return (f"{name} dropped unfitted: a score test at the fit without it "
                    f"predicts -2 log L {drop:.3g} lower with it, under {SCREEN_DROP}: too "
                    f"little to pin it down{self._widening_words()}")
        if self.rise <= 0:
            # the nested model is the limit of the larger one (a loop of lag 0, Coulomb
            # torques of 0), so a fit with the term ending higher found no better point;
            # far higher, its search stopped short of the model it contains
            short = (f"; it ended {-self.rise:.3g} higher than the model without it, which "
                     "it contains, so its search may have stopped short"
                     if self.rise < -STOPPED_SHORT else "")
            return (f"{name} dropped: the fit with it ends no lower in -2 log L ({test}): "
                    f"the data do not call for it{short}{self._widening_words()}")
        gain = f"it lowers -2 log L by {self.rise:.3g}"
        moves = (f"without it theta moves by {self.shift:.2g} of its standard errors"
                 if math.isfinite(self.shift) else
                 "the fit without it stopped before converging, so how far theta moves "
                 "without it is not known")
        if self.kept and self.rise <= self.threshold:
            return (f"{name} kept: {gain}, not above {self.threshold:.3g} ({test}), but "
                    f"{moves} (> {KEEP_SHIFT}){both}")
        if self.kept:
            return f"{name} kept: {gain} > {self.threshold:.3g} ({test}); {moves}"
        if not self.determined and self.shift > KEEP_SHIFT:
            return (f"{name} dropped: {gain}, not above {self.threshold:.3g} ({test}); "
                    f"{moves}, but the data do not pin its value down (a standard error "
                    f"beyond a factor e), so that shift does not keep it{both}")
        return (f"{name} dropped: {gain}, not above {self.threshold:.3g} ({test}), and "
                f"{moves}{both}")

    def _widening_words(self) -> str:
        """The clause on :attr:`widening` and :attr:`held_ci95`, or "" where there is
        nothing to state."""
        down, up = self.widening
        parts = [f"{100 * math.expm1(w):.2g} % further {word} (linearised)"
                 for w, word in ((down, "down"), (up, "up")) if w >= PRINTED_WIDENING]
        if self.held_ci95 is not None:
            lo, hi = self.held_ci95
            parts.append(f"[{lo:.4g}, {hi:.4g}] rad (refitted with it held)")
        if not parts:
            return ""
        return ("; the 95 % interval spans theta over the values of it not ruled out: "
                f"{', '.join(parts)}")


def chi2_upper(dof: int, alpha: float) -> float:
    """The point that a chi-square variable of ``dof`` degrees of freedom exceeds with
    probability ``alpha`` (``scipy.stats.chi2.isf``).

    The terms have one or two parameters, whose points have closed forms: ``-2 ln
    alpha`` for two, the square of the normal point of ``alpha / 2`` for one (the
    standard library's). Others take ``scipy.special.chdtri``, imported only then:
    ``python -X importtime -c "import numpy; import scipy.special"`` puts its import at
    about 0.2 s, which every ``backlashkit`` command paid.

    Parameters
    ----------
    dof : int
        Degrees of freedom, >= 1.
    alpha : float
        Upper tail probability, in (0, 1).

    Returns
    -------
    float
        The point, in chi-square units.
    """
    if dof == 2:
        return -2.0 * math.log(alpha)
    if dof == 1:
        return NormalDist().inv_cdf(1.0 - alpha / 2.0) ** 2
    from scipy.special import chdtri

    return float(chdtri(dof, alpha))


def prior_std_option(name: str, value: float) -> Option:
    """Where a message says a prior std was given: ``prior_rel_std[name] = value`` in
    Python's words (a front end spells it as its own source, e.g. a file's table).

    Parameters
    ----------
    name : str
        The parameter.
    value : float
        Its relative std.

    Returns
    -------
    Option
        Named ``"prior_rel_std"``, its value ``(name, value)``.
    """
    return Option("prior_rel_std", (name, value),
                  python=f"prior_rel_std[{name!r}] = {value:g}")


def friction_term(friction: str) -> Term:
    """The :class:`Term` of the ``friction`` hyperparameter.

    Parameters
    ----------
    friction : {"auto", "viscous", "coulomb"}
        The joint estimator's ``friction``.

    Returns
    -------
    Term
        Its term (checked).
    """
    if friction not in FRICTION_CHOICES:
        raise InputError(
            f"friction must be one of {', '.join(map(repr, FRICTION_CHOICES))}, got "
            f"{friction!r}"
        )
    mode = {"auto": "auto", "viscous": "off", "coulomb": "fit"}[friction]
    return Term("friction", ("fc_M", "fc_L"), mode)


def actuator_term(actuator, prior_std: float | None = None) -> Term:
    """The :class:`Term` of the ``actuator`` hyperparameter.

    Parameters
    ----------
    actuator : "auto", None or CurrentLoop
        The joint estimator's ``actuator``.
    prior_std : float, optional
        A relative prior std of ``tau_i`` (``prior_rel_std``): a known loop is then
        fitted about its value (mode ``"prior"``) instead of held.

    Returns
    -------
    Term
        Its term (checked).
    """
    if isinstance(actuator, str):
        if actuator != "auto":
            raise InputError(f"actuator must be 'auto', None or a CurrentLoop, got {actuator!r}")
        return Term("actuator", ("tau_i",), "auto", searched=False)
    if actuator is None:
        return Term("actuator", ("tau_i",), "off")
    if not isinstance(actuator, CurrentLoop):
        hint = (f" (a loop of that time constant: CurrentLoop(tau_i={actuator!r}))"
                if isinstance(actuator, (int, float)) and not isinstance(actuator, bool)
                else "")
        raise InputError("actuator must be 'auto', None or a CurrentLoop, got "
                         f"{type(actuator).__name__} {actuator!r}{hint}")
    if actuator.exact:
        return Term("actuator", ("tau_i",), "off")
    mode = "prior" if prior_std else "fixed"
    return Term("actuator", ("tau_i",), mode, (actuator.tau_i,), searched=False,
                prior_std=prior_std or None)


def _check_loop_prior(term: Term, given: tuple, std: float) -> None:
    """Refuse a prior std of ``tau_i`` without a known loop to hold it about, or of 0."""
    if std == 0:
        raise InputError(*given, ": a std of 0 is the known loop itself; give a std > 0 "
                         "(0.3 for 30 %), or remove it to hold the loop")
    if term.mode != "prior":
        raise InputError(*given, ", but no known loop to fit it about: give its time "
                         "constant (", Option("actuator", "S",
                                              python="actuator=CurrentLoop(tau_i)"), ")")


def check_known_loop(term: Term, prior: TwoMassDrive) -> None:
    """Refuse a known current loop no faster than the drive's shaft ringing
    (:data:`MAX_LOOP_RINGING`).

    Parameters
    ----------
    term : Term
        The actuator's term.
    prior : TwoMassDrive
        The prior (its shaft ringing).

    Raises
    ------
    InputError
        If ``term`` is a fixed loop whose time constant is too long.
    """
    if term.mode not in ("fixed", "prior"):
        return
    period = 2 * math.pi / prior.ringing_frequency
    tau = term.fixed[0]
    if tau >= MAX_LOOP_RINGING * period:
        raise InputError(
            f"the current loop's time constant {tau:g} s is not below the drive's shaft "
            f"ringing period ({period * 1e3:.3g} ms, from the prior): a current loop is far "
            "faster than the mechanics it drives; give its time constant in s (1 ms = "
            "0.001), or fit it with ", Option("actuator", "auto"))


def torque_scale(recs: Sequence[Record]) -> float:
    """The largest torque magnitude of the records.

    Parameters
    ----------
    recs : sequence of Record
        The records.

    Returns
    -------
    float
        In N m; 1 where every torque is 0.
    """
    return max((float(np.max(np.abs(r.torque))) for r in recs), default=0.0) or 1.0


def coulomb_start(recs: Sequence[Record], prior: TwoMassDrive) -> float:
    """Half the Coulomb torque the held levels show.

    Before each step-down the drive turns steadily: ``T = (f_M + f_L) w + fc_M + fc_L``.
    Where the held speeds differ by :data:`LEVEL_SPREAD` or more, the line through the
    levels ``(|w|, |T|)`` gives ``fc_M + fc_L`` as its intercept, whatever the prior's
    viscous friction. Otherwise the median over records of ``T - (f_M + f_L) w`` with
    the prior's: a small difference of large numbers, which a prior 10 % high in
    ``f_M + f_L`` put at its floor on the second drive of
    ``benchmarks/real_drive.py`` (16 times below the truth's half-sum). Holds that
    still accelerate the drive (beyond :data:`~backlashkit.identify.step.HELD_UNSTEADY`)
    are left out; where
    every hold does, the median over records of the friction the prior's rigid body
    sees in each, ``T (1 - g)`` (``g``:
    :func:`~backlashkit.identify.step.held_speed_gain`). Halved, floored at
    :data:`FC_START_FLOOR` of the held torque, it starts both Coulomb torques.

    Parameters
    ----------
    recs : sequence of Record
        Step-down records (others are skipped).
    prior : TwoMassDrive
        The prior (its viscous frictions, where one level is held).

    Returns
    -------
    float
        The start of each Coulomb torque in N m.
    """
    steady = [r for r in recs if not _accelerates(r, prior)]
    if recs and not steady:  # every hold from rest, not yet steady
        return max(0.5 * float(np.median(_body_friction(recs, prior))),
                   FC_START_FLOOR * float(np.max(np.abs(held_levels(recs)[1]))))
    w, t = (np.abs(x) for x in held_levels(steady))
    if t.size == 0:
        return FC_START_FLOOR
    spread = w.max() > 0.0 and w.max() >= LEVEL_SPREAD * w.min()  # not all at rest
    slope, total = np.polyfit(w, t, 1) if spread else (math.nan, math.nan)
    if not slope > 0:  # one level, or a line no drive has: the prior's viscous friction
        total = float(np.median(t - (prior.f_M + prior.f_L) * w))
    return max(0.5 * float(total), FC_START_FLOOR * float(t.max()))


def _accelerates(rec: Record, prior: TwoMassDrive) -> bool:
    """Whether a step-down record's hold is no steady level: at its step-down the drive
    still accelerates by more than :data:`~backlashkit.identify.step.HELD_UNSTEADY` of
    the torque, where the two-step method refuses its steady start (False where that is
    not known: no step-down, or too short a hold to tell). ``T - (f_M + f_L) w`` would
    count that share as friction: a 2 s hold of paper A's drive from rest started both
    Coulomb torques at over 0.3 N m for a truth of 0.02 and 0.04, and theta ended 12 %
    low (``tests/test_identify_real_drive.py::
    test_a_short_hold_from_rest_starts_the_coulomb_torques_from_the_rigid_body``)."""
    try:
        return held_unsteady_share(rec, prior) > HELD_UNSTEADY
    except InputError:
        return False


def _body_friction(recs: Sequence[Record], prior: TwoMassDrive) -> np.ndarray:
    """The torque that friction takes of each record's hold, by the prior's rigid body:
    ``T (1 - g)`` with ``g`` its :func:`~backlashkit.identify.step.held_speed_gain` (the
    body from rest under ``T - fc_M - fc_L`` is ``g`` times the one under ``T``: the
    share of the torque left to speed it up, whether or not it has settled)."""
    return np.array([held_levels([r])[1][0] * (1.0 - held_speed_gain(r, prior))
                     for r in recs])


def held_levels(recs: Sequence[Record]) -> tuple[np.ndarray, np.ndarray]:
    """The motor's mean speed (rad/s) over the last 0.1 s of each record's hold before
    its step-down, and the held torque (N m); records without a step-down skipped."""
    speeds, levels = [], []
    for rec in recs:
        try:
            i_s, _, level, _ = find_step_down(rec)
        except InputError:
            continue
        n = max(1, min(i_s // 4, int(round(0.1 / rec.ts))))  # the last 0.1 s of the hold
        speeds.append(float(np.mean(rec.w_motor[i_s - n : i_s])))
        levels.append(float(level))
    return np.array(speeds), np.array(levels)
