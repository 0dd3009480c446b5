"""The interval's widening for a dropped term (``_score.held_widening``) against a
brute-force profile: a linear least-squares model with the term's value held in
``[0, top]``, ``theta``'s confidence set found by bounded least squares at every
``theta`` of a fine grid (``scipy.optimize.lsq_linear``), not by the union the
function takes."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from backlashkit.identify._score import held_widening
from backlashkit.identify.intervals import Z_95
from backlashkit.identify.terms import TermChoice

#: Points of the brute force's grid of theta over its search range.
BRUTE_GRID = 1601


def _problem(seed: int, pull: float, weak: float):
    """A random linear model: Jacobian ``jac`` (theta first), the term's column ``col``
    and a residual ``r0`` at the fit without the term (orthogonal to ``jac``), whose
    component along the term's own direction is ``pull`` (its sign says which side the
    data push the term to). ``weak`` scales the column's part the model cannot mimic."""
    rng = np.random.default_rng(seed)
    n, p = 40, 3
    jac = rng.normal(size=(n, p))
    q, _ = np.linalg.qr(jac)
    mimic = jac @ rng.normal(size=p)  # what the model can make up for
    own = rng.normal(size=n)
    own -= q @ (q.T @ own)
    own /= np.linalg.norm(own)
    col = mimic + weak * own
    noise = rng.normal(size=n)
    noise -= q @ (q.T @ noise)
    noise -= own * (own @ noise)
    r0 = noise - pull * own
    return jac, col, r0


def _score_parts(jac, col, r0):
    """``held_widening``'s inputs as ``score_test`` makes them."""
    cov = np.linalg.inv(jac.T @ jac)
    along = cov @ (jac.T @ col)
    col_out = col - jac @ along
    norm = float(col_out @ col_out)
    return float(along[0]), math.sqrt(cov[0, 0]), norm, -float(col_out @ r0) / norm


def _brute_interval(jac, col, r0, top):
    """``theta``'s 95 % profile set, each ``theta`` refitted over the other parameters
    and the term's value in ``[0, top]``; its ends found on :data:`BRUTE_GRID`."""
    a = np.column_stack([jac[:, 1:], col])
    lo = np.r_[np.full(jac.shape[1] - 1, -np.inf), 0.0]
    hi = np.r_[np.full(jac.shape[1] - 1, np.inf), top]

    def cost(t):
        res = lsq_linear(a, -(r0 + jac[:, 0] * t), bounds=(lo, hi), tol=1e-12)
        r = r0 + jac[:, 0] * t + a @ res.x
        return float(r @ r)

    std0 = math.sqrt(np.linalg.inv(jac.T @ jac)[0, 0])
    ts = np.linspace(-20 * std0, 20 * std0, BRUTE_GRID)
    prof = np.array([cost(t) for t in ts])
    inside = ts[prof - prof.min() <= Z_95 * Z_95]
    return float(inside.min()), float(inside.max()), ts[1] - ts[0], std0


@pytest.mark.parametrize(("seed", "pull", "weak", "top"), [
    (1, 0.0, 1.0, 10.0),   # the data say nothing of the term's sign
    (2, 1.5, 1.0, 10.0),   # they push it up: estimated inside the range
    (3, -1.5, 1.0, 10.0),  # they push it below 0: held at 0 is best
    (4, 0.5, 0.3, 2.0),    # weakly seen, the range's end bounds it
    (5, 0.0, 300.0, 10.0),  # clearly seen: next to no widening
])
def test_the_widening_reaches_the_brute_force_profile(seed, pull, weak, top):
    jac, col, r0 = _problem(seed, pull, weak)
    along, std, norm, value = _score_parts(jac, col, r0)
    down, up = held_widening(along, std, norm, value, top)
    lo, hi, step, std0 = _brute_interval(jac, col, r0, top)
    assert std == pytest.approx(std0)
    own = Z_95 * std
    # the estimate's interval widened to the profile set (where the data push the
    # term up, that set can end inside the model's own interval on one side); the
    # brute force's ends are on its grid, within a step of the exact ones
    assert -own - down == pytest.approx(min(lo, -own), abs=1.01 * step)
    assert own + up == pytest.approx(max(hi, own), abs=1.01 * step)
    if weak >= 300.0:
        assert max(down, up) < 0.05 * own


def test_no_move_of_theta_no_widening():
    assert held_widening(0.0, 0.01, 4.0, 0.3, 1.0) == (0.0, 0.0)
    assert held_widening(0.0, 0.01, 4.0, -0.3, 1.0) == (0.0, 0.0)


def test_unknown_column_no_widening():
    assert held_widening(math.nan, 0.01, 4.0, 0.3, 1.0) == (0.0, 0.0)
    assert held_widening(0.5, math.inf, 4.0, 0.3, 1.0) == (0.0, 0.0)


def test_the_unbounded_widening_is_the_larger_models_fisher_interval():
    """Where the data say nothing of the term's sign (``value`` 0) and nothing bounds
    it but the data, one end moves out to the larger model's Fisher end, whose
    variance of ``log theta`` is ``std^2 + along^2 / norm``; the other stays."""
    along, std, norm = 0.02, 0.01, 9.0
    down, up = held_widening(along, std, norm, 0.0, 1e3)
    big = Z_95 * math.sqrt(std**2 + along**2 / norm)
    assert up == 0.0
    assert Z_95 * std + down == pytest.approx(big, rel=1e-5)


def test_a_dropped_terms_reason_states_its_widening():
    screened = TermChoice("actuator", False, 0.0, 6.63, 0.0, screened=True,
                          widening=(0.015, 0.0))
    assert "1.5 % further down (linearised)" in screened.reason()
    assert "further up" not in screened.reason()
    tiny = TermChoice("actuator", False, 0.0, 6.63, 0.0, screened=True,
                      widening=(5e-5, 0.0))
    assert "spans theta" not in tiny.reason()
    held = replace(tiny, held_ci95=(0.0198, 0.0212))
    assert held.reason().endswith("not ruled out: [0.0198, 0.0212] rad (refitted with it held)")


#: Draws of the coverage tests; their Monte Carlo standard error is about 0.0015.
COVER_DRAWS = 20_000
#: Marginal standard error of ``log theta`` and the correlation of its estimate with
#: the term's, as strong as a loop's lag and theta's on a stiff drive.
COVER_STD, COVER_RHO = 0.01, 0.9


def _coverage(true_term: float, top: float, seed: int) -> tuple[float, float]:
    """Coverage of the model's own interval and of it widened by ``held_widening``,
    over draws of the unconstrained estimates of ``(log theta, term)`` of a linear
    Gaussian model (the term's standard error 1, the true ``log theta`` 0): the model
    without the term refits ``theta`` at the held value ``x`` to ``a - rho s (b - x)``
    with standard error ``s sqrt(1 - rho^2)``, and ``-2 log L`` rises by
    ``(x - b)^2 - b^2``."""
    rng = np.random.default_rng(seed)
    rho, s = COVER_RHO, COVER_STD
    a = s * rng.standard_normal(COVER_DRAWS)
    b = true_term + rho * a / s + math.sqrt(1 - rho**2) * rng.standard_normal(COVER_DRAWS)
    own_std = s * math.sqrt(1 - rho**2)
    own = Z_95 * own_std
    held0 = a - rho * s * b  # the fit without the term: held at 0
    own_cover = spanned = 0
    for centre, value in zip(held0, b, strict=True):
        down, up = held_widening(-rho * s, own_std, 1.0, float(value), top)
        own_cover += abs(centre) <= own
        spanned += -own - up <= centre <= own + down
    return own_cover / COVER_DRAWS, spanned / COVER_DRAWS


def test_the_span_covers_where_a_term_the_data_cannot_see_is_there():
    """With a term one standard error from none, which the likelihood-ratio test drops
    as undetermined, the model's own interval misses about half the time; the widened
    one, which holds the profile interval of the model with the term, covers at least
    95 %."""
    own, spanned = _coverage(true_term=1.0, top=12.0, seed=11)
    assert own < 0.6
    assert spanned > 0.944


def test_the_span_over_covers_where_there_is_no_term():
    """With no term (its value on the range's end), the profile interval over the
    range covers more than 95 %: the misses on the side the term moves ``theta`` to are
    gone, so at most 97.5 %. This is the price of an interval that holds whether or not
    the drive has a term the data cannot see (docs/validation/real-drives.md)."""
    own, spanned = _coverage(true_term=0.0, top=12.0, seed=12)
    assert own == pytest.approx(0.95, abs=0.006)
    assert 0.962 < spanned < 0.981
