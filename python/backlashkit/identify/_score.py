"""The score test of a term added after the search, before it is fitted.

A term the joint search leaves out (the current loop) is tested by fitting the larger
model from several starts (:func:`backlashkit.identify._search.added_term_fit`), which
costs hundreds of simulations of the records. Most drives do not call for it, and the
fit without the term already tells, to first order, what the fit with it would find:
at its point ``z`` the residual is ``r0``, its Jacobian ``J``, and the term's column
``j`` (the residual's change per unit of the term from 0, by one simulation at the
term's floor). Linearised, the larger model's residual is ``r0 + J d + j x`` with
``x >= 0``, whose least squares give the term's value ``x*``, the fall of
``-2 log L``

    D = (j'.r0)^2 / (j'.j')   where j' = j - J (J^T J)^-1 J^T j, if x* > 0 (else 0),

and the move of ``theta``. The fitted term's standard error in logarithms is then
``1 / sqrt(D)``, so a term with ``D <= 1`` is not pinned down by the data, and the
likelihood-ratio test (:meth:`backlashkit.identify.terms.TermChoice.decide`) drops it
without widening the interval. The term is fitted only where ``D`` is at least
:data:`backlashkit.identify.terms.SCREEN_DROP`, below that limit by a margin for the
linearisation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ._lm import LMState
from ._problem import Problem, Residual
from .intervals import Z_95
from .record import Record
from .terms import SCREEN_DROP, Term

__all__ = ["Linearised", "Score", "bounds_theta", "held_widening", "linearise",
           "score_test"]


@dataclass(frozen=True)
class Linearised:
    """A residual linearised at a point: the tests' Gauss-Newton information.

    Parameters
    ----------
    r : numpy.ndarray
        The residual at the point.
    jac : numpy.ndarray
        Its Jacobian there: exact where the compiled sensitivities cover the model,
        else by forward differences (they only scale and qualify a test).
    cov : numpy.ndarray or None
        The inverse of ``jac.T @ jac``; None where it is singular.
    std : numpy.ndarray
        The standard errors of the estimated values (inf where singular).
    theta_std : float
        The standard error of ``log theta`` with the directions the data do not see
        held (the pseudo-inverse's, as the fit's own uncertainty takes it): finite
        where a nuisance term sits on its floor and its column is zero, which makes
        ``std`` inf. What a term's test measures ``theta``'s move in.
    """

    r: np.ndarray
    jac: np.ndarray
    cov: np.ndarray | None
    std: np.ndarray
    theta_std: float


def linearise(rows: Residual, z: np.ndarray) -> Linearised:
    """The residual ``rows`` linearised at ``z``: one simulation and a sensitivity run
    along it, or ``z.size + 1`` simulations outside the sensitivities' scope
    (:meth:`Residual.jacobian`)."""
    r = rows.at(z)
    jac = rows.jacobian(z, r)
    info = jac.T @ jac
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return Linearised(r, jac, None, np.full(z.size, math.inf), _held_theta_std(info))
    std = np.where(np.diag(cov) > 0, np.sqrt(np.abs(np.diag(cov))), math.inf)
    return Linearised(r, jac, cov, std,
                      float(std[0]) if math.isfinite(std[0]) else _held_theta_std(info))


def _held_theta_std(info: np.ndarray) -> float:
    """:attr:`Linearised.theta_std` from a singular information ``info``; inf where
    ``theta`` itself is not seen."""
    var = float(np.linalg.pinv(info)[0, 0])
    return math.sqrt(var) if var > 0 else math.inf


@dataclass(frozen=True)
class Score:
    """What the score test predicts of the fit with one added term.

    Parameters
    ----------
    drop : float
        Fall of ``-2 log L`` (chi-square units) with the term; 0 where its best value
        is at or below 0.
    value : float
        The term's best value in its units (0 where the fall is 0).
    shift : float
        How far ``theta`` moves with the term, in standard errors of ``theta`` in the
        model without it.
    std : numpy.ndarray
        The standard errors of the log-parameters of the model without the term (inf
        where its information is singular).
    widening : tuple of float
        How far down and up, in ``log theta``, the 95 % interval must reach beyond the
        model's own to span ``theta`` at every value of the term the data do not rule
        out (:func:`held_widening`); both 0 where the term's column is not known or
        the linearisation does not bound ``theta``.
    """

    drop: float
    value: float
    shift: float
    std: np.ndarray
    widening: tuple[float, float] = (0.0, 0.0)

    @property
    def screened(self) -> bool:
        """Whether the term is dropped without being fitted."""
        return self.drop < SCREEN_DROP


def score_test(small: Problem, best: LMState, at: Linearised, big: Problem,
               big_rows: Residual, term: Term, recs: Sequence[Record]) -> Score:
    """The score test of the one-parameter ``term`` that ``big`` adds to ``small``.

    ``best`` is ``small``'s fit and ``at`` its residual linearised there
    (:func:`linearise`); ``big_rows`` is ``big``'s residual on the same spans. Costs
    one simulation.
    """
    (name,) = term.params
    r0, jac, cov, std = at.r, at.jac, at.cov, at.std
    if cov is None:
        return Score(math.inf, math.nan, math.inf, std)
    step = term.floors(recs)[name]
    r1 = big_rows.at(np.r_[best.z, big.z_of([name], [step])])
    data = r0.size - len(small.free)  # the prior's rows do not move with the term
    if r1.size < data or not np.all(np.isfinite(r1[:data])):
        return Score(math.inf, math.nan, math.inf, std)  # no column: fit the term
    col = np.zeros(r0.size)
    col[:data] = (r1[:data] - r0[:data]) / step
    along = cov @ (jac.T @ col)  # the model's own move per unit of the term
    col_out = col - jac @ along
    norm = float(col_out @ col_out)
    value = -float(col_out @ r0) / norm if norm > 0 else 0.0
    top = max(start[name] for start in term.start_grid(recs))
    widening = held_widening(float(along[0]), float(std[0]), norm, value, top)
    if not value > 0:
        return Score(0.0, 0.0, 0.0, std, widening)
    drop = value * value * norm
    return Score(drop, value, abs(float(along[0])) * value / std[0], std, widening)


def held_widening(along: float, std: float, norm: float, value: float, top: float
                  ) -> tuple[float, float]:
    """How far the 95 % interval of ``log theta`` reaches beyond the model's own where
    the term is not known: the profile interval of the linearised larger model with
    the term's value ``x`` held in ``[0, top]`` and profiled out.

    Held at ``x``, the model without the term refits to ``log theta - along x`` with
    its own standard error ``std``, and ``-2 log L`` rises by ``norm ((x - value)^2 -
    value^2)`` from the fit without it (``value``: the unconstrained best ``x``,
    ``norm``: the information on ``x`` left once the model has moved). ``theta`` is
    in the interval where some ``x`` puts it within ``Z_95^2`` of the lowest of
    those: the union over ``x`` of ``log theta - along x -+ std sqrt(Z_95^2 - rise)``.
    Each end of that union is the largest of a line plus the root of a concave
    quadratic in ``x``, so it has a closed form. Where the data cannot tell the term
    from none and it moves ``theta``, the union reaches past the model's interval on
    one side, as far as the larger model's Fisher interval on that side where nothing
    bounds ``x`` but the data; a term the data see clearly widens it by next to
    nothing. None where the model's own linearised interval reaches ``theta = 0``
    (``Z_95 std >= 1``): it does not bound ``theta``.
    """
    own = Z_95 * std
    if not (math.isfinite(along) and bounds_theta(std) and top > 0
            and math.isfinite(norm) and math.isfinite(value)):
        return (0.0, 0.0)
    return (max(_held_reach(along, std, norm, value, top) - own, 0.0),
            max(_held_reach(-along, std, norm, value, top) - own, 0.0))


def bounds_theta(std: float) -> bool:
    """Whether a linearisation whose standard error of ``log theta`` is ``std`` bounds
    ``theta``: its Fisher interval ``theta (1 -+ Z_95 std)`` stays above 0. One whose
    interval reaches 0 cannot say how far a term moves ``theta`` either."""
    return 0 < Z_95 * std < 1


def _held_reach(slope: float, std: float, norm: float, value: float, top: float) -> float:
    """The largest ``slope x + std sqrt(room(x))`` over ``x`` in ``[0, top]`` where
    ``room = Z_95^2 - (rise(x) - min rise)`` is not negative (:func:`held_widening`)."""
    q = Z_95 * Z_95
    if norm <= 0:  # the data do not see the term: its whole range is allowed
        return max(slope * top, 0.0) + std * math.sqrt(q)
    lowest = min(max(value, 0.0), top)
    reach2 = q / norm + (lowest - value) ** 2  # room >= 0 where (x - value)^2 <= this
    radius = math.sqrt(reach2)
    # the stationary point of the line plus the root, inside the allowed x
    u = math.copysign(math.sqrt(slope * slope * reach2
                                / (slope * slope + std * std * norm)), slope)
    x = min(max(value + u, 0.0, value - radius), top, value + radius)
    room = norm * (reach2 - (x - value) ** 2)
    return slope * x + std * math.sqrt(max(room, 0.0))
