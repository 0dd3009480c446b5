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
from .record import Record
from .terms import SCREEN_DROP, Term

__all__ = ["Linearised", "Score", "linearise", "score_test"]


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
    """

    drop: float
    value: float
    shift: float
    std: np.ndarray

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
    if not value > 0:
        return Score(0.0, 0.0, 0.0, std)
    drop = value * value * norm
    return Score(drop, value, abs(float(along[0])) * value / std[0], std)
