"""The drive's free decay after a torque step-down, with viscous and Coulomb friction:
the criterion of paper A's final least squares and the decay model of its commutation
instants (Ravanbod-Shirazi & Besançon-Voda, IFAC 2002, eqs. 9 and ``W_1``).

After the step-down the torque is held at its lower level; an inertia ``J`` with
viscous friction ``f`` and Coulomb torque ``fc`` that moves freely (the shaft in the
gap) decelerates as ``J w' = -f w - fc`` while ``w > 0``, so

    w(t) = w(t_i) exp(-alpha (t - t_i)) - (fc / J) E(t - t_i),
    E(tau) = (1 - exp(-alpha tau)) / alpha   (tau when alpha = f / J = 0),

and it sticks at ``w = 0`` where that reaches zero (the breakaway torque is not
reached by a drive left to itself). With ``fc = 0`` this is paper A's exponential
decay. The Coulomb part is linear in ``fc``: :func:`coulomb_commutation_instants`
evaluates eq. 9's two piecewise fits with it, on the windows the viscous fit chose.

The criterion ``W_1`` (:func:`criterion_costs`) simulates the prior from the
measured steady state at ``t_s``: state ``[w_0, w_0, theta + (f_L w_0 + fc_L) / k_sh]``
(the shaft carries the load's friction). :func:`coulomb_profile_costs` minimises it
over the Coulomb torques ``fc_M, fc_L >= 0`` for every candidate ``theta`` by a few
Gauss-Newton steps (two more simulations per step for the sensitivities; the motor
speed is affine in the torques between contact changes, but they move the impact, so
one linearisation is not enough); :func:`coulomb_fit` searches theta on that
profile.

Every ``theta`` is the backlash **half-width** in rad. Units are SI: s, N m, rad,
rad/s.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError, Option, SearchEdgeWarning
from ..plants import TwoMassDrive
from .commutation import Commutation
from .record import Record
from .step import find_step_down

__all__ = [
    "AT_EDGE",
    "COULOMB_ITERATIONS",
    "COULOMB_STEP",
    "ZOOM_POINTS",
    "CriterionWindow",
    "coulomb_commutation_instants",
    "coulomb_profile_costs",
    "criterion_costs",
    "coulomb_fit",
    "criterion_window",
    "free_decay",
    "likelihood_ratio",
    "search_edges",
    "search_theta",
    "viscous_fit",
]

#: Candidates per zoomed grid of :func:`search_theta` (21: each zoom narrows the cell
#: tenfold).
ZOOM_POINTS = 21
#: Finite-difference step of the Coulomb torques, as a fraction of the largest torque
#: held before a step-down (the response is affine in them between contact changes,
#: so the step's size hardly matters; 1 % keeps it far above rounding).
COULOMB_STEP = 1e-2
#: Gauss-Newton steps of the Coulomb torques per candidate theta: from 0 on paper A's
#: drive with fc = (0.01, 0.02) N m, 4 steps bring W_1 within 1e-4 (rad/s)^2 of its
#: minimum on noise-free records (1 step: 2.3), far below a 40 dB noise's W_1 of ~800.
COULOMB_ITERATIONS = 4


def free_decay(tau: np.ndarray, alpha: float, decel: float) -> tuple[np.ndarray, np.ndarray]:
    """The two parts of a free decay: ``w(tau) = w_0 g(tau) - decel E(tau)``.

    Parameters
    ----------
    tau : numpy.ndarray
        Time since the anchor instant in s (may be negative: the decay backwards).
    alpha : float
        Viscous decay rate ``f / J`` in 1/s, >= 0.
    decel : float
        Coulomb deceleration ``fc / J`` in rad/s^2, >= 0.

    Returns
    -------
    g : numpy.ndarray
        ``exp(-alpha tau)``.
    coulomb : numpy.ndarray
        ``-decel E(tau)``, ``E(tau) = (1 - exp(-alpha tau)) / alpha`` (``tau`` when
        ``alpha = 0``), in rad/s.
    """
    g = np.exp(-alpha * tau)
    e = -np.expm1(-alpha * tau) / alpha if alpha > 0 else tau
    return g, -decel * e


def _misfit(y: np.ndarray, g: np.ndarray, off: np.ndarray, c: int, anchor: str,
            free: np.ndarray) -> float:
    """Squared residual of ``A g + off`` with ``A = y[c]`` or its least squares; the
    freely decaying samples ``free`` stick at 0 instead of crossing it."""
    a = y[c] if anchor == "sample" else float((y - off) @ g) / float(g @ g)
    model = a * g + off
    if a > 0:
        model = np.where(free, np.maximum(model, 0.0), model)
    r = y - model
    return float(r @ r)


def _w_c(y, tt, alpha, decel, anchor, onset) -> np.ndarray:
    """Eq. 9's ``W_c`` with the Coulomb decay after the candidate (module docstring)."""
    m = y.size
    out = np.full(m, np.inf)
    idx = np.arange(m)
    tau = tt - tt[0]
    for c in range(1, m - 1):
        g_after, off_after = free_decay(tt - tt[c], alpha, decel)
        if onset == "unloading":  # the cubic fall joins the decay's slope -(alpha A + decel)
            d = tau[c]
            q = (d**3 - tau**3) / (3.0 * d**2)
            g_before, off_before = 1.0 + alpha * q, decel * q
        else:
            g_before, off_before = 1.0, 0.0
        before = idx < c
        g = np.where(before, g_before, g_after)
        off = np.where(before, off_before, off_after)
        out[c] = _misfit(y, g, off, c, anchor, ~before)
    return out


def _w_b(y, tt, alpha, decel, anchor) -> np.ndarray:
    """Eq. 9's ``W_b`` with the Coulomb decay before the candidate, constant after."""
    m = y.size
    out = np.full(m, np.inf)
    idx = np.arange(m)
    for c in range(0, m - 1):
        g_dec, off_dec = free_decay(tt - tt[c], alpha, decel)
        before = idx <= c
        g = np.where(before, g_dec, 1.0)
        off = np.where(before, off_dec, 0.0)
        out[c] = _misfit(y, g, off, c, anchor, before)
    return out


def coulomb_commutation_instants(record: Record, viscous: Commutation, alpha: float,
                                 decel: float, *, anchor: str = "sample",
                                 onset: str = "constant") -> Commutation:
    """Eq. 9's contact loss ``t_c`` and impact ``t_b`` with the load's Coulomb friction.

    The two piecewise fits of :func:`~backlashkit.identify.commutation_instants` with
    the free decay of :func:`free_decay` (the load sticks at 0 rather than crossing
    it), on the same windows ``dt1 .. dt3``.

    Parameters
    ----------
    record : Record
        A step-down experiment.
    viscous : Commutation
        The viscous fit's result on ``record`` (its windows are kept).
    alpha : float
        Load decay rate ``f_L / J_L`` in 1/s, >= 0.
    decel : float
        Load Coulomb deceleration ``fc_L / J_L`` in rad/s^2, >= 0; 0 returns
        ``viscous`` itself.
    anchor : {"sample", "fit"}, optional
        Amplitude of the decay (as :func:`~backlashkit.identify.commutation_instants`).
    onset : {"constant", "unloading"}, optional
        Load speed before ``t_c`` (as :func:`~backlashkit.identify.commutation_instants`).

    Returns
    -------
    Commutation
        The instants, with the windows of ``viscous``.

    Raises
    ------
    InputError
        If the impact comes out before the contact loss.
    """
    alpha, decel = v.nonnegative("alpha", alpha), v.nonnegative("decel", decel)
    if decel == 0.0:
        return viscous
    ts, i_s, t = record.ts, viscous.i_s, record.t
    n1, n2, n3 = (int(round(x / ts)) for x in (viscous.dt1, viscous.dt2, viscous.dt3))
    # scaled by a power of 2 (exact), as the viscous fit: no overflow of the squares
    exp2 = math.frexp(float(np.max(np.abs(record.w_load))))[1]
    y, decel = np.ldexp(record.w_load, -exp2), math.ldexp(decel, -exp2)
    wc = _w_c(y[i_s : i_s + n1 + 1], t[i_s : i_s + n1 + 1], alpha, decel, anchor, onset)
    i_c = i_s + int(np.argmin(wc))
    lo = i_s + n2
    i_b = lo + int(np.argmin(_w_b(y[lo : i_s + n3 + 1], t[lo : i_s + n3 + 1], alpha, decel,
                                  anchor)))
    if not i_b > i_c:
        raise InputError(
            f"{record.name}: with the load's Coulomb friction the impact on the negative "
            f"flank (t = {t[i_b]:.6g} s) comes before the contact loss (t = {t[i_c]:.6g} s): "
            "no passage through the backlash found; use friction='viscous'")
    return replace(viscous, i_c=i_c, i_b=i_b, t_c=float(t[i_c]), t_b=float(t[i_b]))


@dataclass

class CriterionWindow:
    """The part of a record in the final least squares: from ``t_s`` over ``dt4``.

    Parameters
    ----------
    t, torque, w_motor : numpy.ndarray
        Time (s), torque (N m) and measured motor speed (rad/s) on the window.
    w0 : float
        The measured speed level that starts the model (rad/s).
    name : str
        The record's name.
    held : float
        The torque held before the step-down in N m.
    """

    t: np.ndarray
    torque: np.ndarray
    w_motor: np.ndarray
    w0: float
    name: str = "record"
    held: float = 0.0


def criterion_window(record: Record, dt4: float, level_window: float) -> CriterionWindow:
    """The window of ``record`` in the final least squares.

    Parameters
    ----------
    record : Record
        A step-down experiment.
    dt4 : float
        Span after ``t_s`` in s.
    level_window : float
        Span before ``t_s`` in s over which the starting speed is averaged.

    Returns
    -------
    CriterionWindow
        The samples from ``t_s`` to ``t_s + dt4`` and the measured starting speed.

    Raises
    ------
    InputError
        If the record ends before ``t_s + dt4``.

    Warns
    -----
    UserWarning
        If ``level_window`` is longer than the record before ``t_s`` (the speed level
        is then the mean of what there is).
    """
    i_s, t_s, held, _ = find_step_down(record)
    ts = record.ts
    n4 = int(round(dt4 / ts))
    if i_s + n4 >= record.t.size:
        raise InputError(
            f"{record.name}: the final least squares fits the motor speed over the "
            f"{dt4:.6g} s after the step-down at t = {t_s:.6g} s, but the record ends at "
            f"t = {record.t[-1]:.6g} s (record at least {dt4:.6g} s after the step-down, or "
            "shorten that span with ", Option("dt4", None), ")"
        )
    nl = max(1, int(round(level_window / ts)))
    if nl > i_s:
        warnings.warn(
            f"{record.name}: level_window = {level_window:g} s is longer than the "
            f"{i_s * ts:.6g} s recorded before the step-down at t = {t_s:.6g} s; the "
            f"speed level is their mean (give at most that span)", UserWarning,
            stacklevel=2)
        nl = max(1, i_s)
    w0 = float(np.mean(record.w_motor[i_s - nl : i_s]))
    sl = slice(i_s, i_s + n4 + 1)
    return CriterionWindow(record.t[sl], record.torque[sl], record.w_motor[sl], w0,
                           record.name, held)


def _simulate(prior: TwoMassDrive, seg: CriterionWindow, thetas: np.ndarray,
              fc: np.ndarray | None, workers: int | None) -> list:
    """The prior's motor speeds on ``seg`` per theta, with the Coulomb torques ``fc``
    (one row ``(fc_M, fc_L)`` per theta; None: the prior's own, the shaft started
    without them)."""
    if fc is None:
        drives = [prior.with_theta(float(th)) for th in thetas]
        x0 = np.array([[seg.w0, seg.w0, th + prior.f_L * seg.w0 / prior.k_sh] for th in thetas])
        return _batch(seg, drives, x0, workers)
    out: list = [None] * thetas.size
    # a batch's drives share which inertias have Coulomb friction: one batch per pattern
    pattern = (fc > 0) @ [1, 2]
    for p in np.unique(pattern):
        idx = np.flatnonzero(pattern == p)
        drives = [replace(prior, theta=float(thetas[j]), fc_M=float(fc[j, 0]),
                          fc_L=float(fc[j, 1]), fs_M=None, fs_L=None) for j in idx]
        x0 = np.array([[seg.w0, seg.w0,
                        thetas[j] + (prior.f_L * seg.w0 + fc[j, 1]) / prior.k_sh] for j in idx])
        for j, w in zip(idx, _batch(seg, drives, x0, workers), strict=True):
            out[j] = w
    return out


def _batch(seg: CriterionWindow, drives: list, x0: np.ndarray, workers: int | None) -> list:
    from ..simulate import simulate_batch

    try:
        responses = simulate_batch(drives, seg.t, seg.torque, initial_state=x0,
                                   workers=workers)
    except InputError:
        raise
    except ValueError as exc:  # what the compiled core refuses, with the record named
        text = " ".join(str(exc).split())
        raise InputError(f"{seg.name}: cannot simulate the prior on this record: "
                         f"{text}") from exc
    return [r.w_motor for r in responses]


def criterion_costs(prior: TwoMassDrive, segments: list[CriterionWindow], thetas: np.ndarray,
                    workers: int | None = None, *,
                    fc: tuple[float, float] | np.ndarray | None = None) -> np.ndarray:
    """Sum over windows of ``W_1(theta)`` for every theta (simulated in parallel).

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters (and Coulomb torques, if it has any).
    segments : list of CriterionWindow
        The windows (:func:`criterion_window`).
    thetas : numpy.ndarray
        Backlash half-widths in rad.
    workers : int, optional
        Threads for the simulations (default all cores).
    fc : tuple of float or numpy.ndarray, optional
        Coulomb torques ``(fc_M, fc_L)`` in N m of the model (or one row per theta),
        the shaft started carrying ``fc_L``; default None: the prior as it is,
        started with the viscous twist ``f_L w_0 / k_sh`` (paper A).

    Returns
    -------
    numpy.ndarray
        ``W_1`` in (rad/s)^2 per theta.
    """
    total = np.zeros(thetas.size)
    rows = None if fc is None else np.broadcast_to(np.asarray(fc, float), (thetas.size, 2))
    for seg in segments:
        for j, w in enumerate(_simulate(prior, seg, thetas, rows, workers)):
            e = seg.w_motor - w
            total[j] += float(e @ e)
    return total


def _nnls2(a: np.ndarray, b: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """``argmin |r0|^2 - 2 b.d + d.A d`` over ``d >= lower`` (2 unknowns, active sets)."""
    best, best_val = None, math.inf
    candidates = []
    try:
        candidates.append(np.linalg.solve(a, b))
    except np.linalg.LinAlgError:
        pass
    for k in (0, 1):
        d = lower.copy()
        o = 1 - k
        d[o] = (b[o] - a[o, k] * d[k]) / a[o, o] if a[o, o] > 0 else lower[o]
        candidates.append(d)
    candidates.append(lower.copy())
    for d in candidates:
        d = np.maximum(d, lower)
        val = float(d @ a @ d - 2.0 * b @ d)
        if val < best_val:
            best, best_val = d, val
    return best


def coulomb_profile_costs(prior: TwoMassDrive, segments: list[CriterionWindow],
                          thetas: np.ndarray, fc0: tuple[float, float],
                          workers: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``W_1(theta)`` minimised over the Coulomb torques ``fc_M, fc_L >= 0``.

    :data:`COULOMB_ITERATIONS` Gauss-Newton steps from ``fc0`` for every theta at once
    (finite-difference sensitivities, two more simulations per step; each step a
    non-negative least squares on the 2 x 2 normal equations); the cost is simulated
    at the last torques.

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters (its own Coulomb torques are replaced).
    segments : list of CriterionWindow
        The windows (:func:`criterion_window`).
    thetas : numpy.ndarray
        Backlash half-widths in rad.
    fc0 : tuple of float
        ``(fc_M, fc_L)`` in N m to start from.
    workers : int, optional
        Threads for the simulations (default all cores).

    Returns
    -------
    costs : numpy.ndarray
        ``W_1`` in (rad/s)^2 per theta at its torques.
    fc : numpy.ndarray
        The torques ``(fc_M, fc_L)`` in N m per theta, shape ``(len(thetas), 2)``.
    """
    h = COULOMB_STEP * max(max(abs(s.held) for s in segments), 1e-12)
    n = thetas.size
    fc = np.tile(np.asarray(fc0, float), (n, 1))
    for _ in range(COULOMB_ITERATIONS):
        costs, a, b = np.zeros(n), np.zeros((n, 2, 2)), np.zeros((n, 2))
        for seg in segments:
            w0 = _simulate(prior, seg, thetas, fc, workers)
            wm = _simulate(prior, seg, thetas, fc + [h, 0.0], workers)
            wl = _simulate(prior, seg, thetas, fc + [0.0, h], workers)
            for j in range(n):
                e = seg.w_motor - w0[j]
                jac = np.column_stack([(wm[j] - w0[j]) / h, (wl[j] - w0[j]) / h])
                a[j] += jac.T @ jac
                b[j] += jac.T @ e
                costs[j] += float(e @ e)
        fc = np.array([fc[j] + _nnls2(a[j], b[j], -fc[j]) for j in range(n)])
    costs = criterion_costs(prior, segments, thetas, workers, fc=fc)
    return costs, fc


def search_theta(costs_of: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray | None]],
                 lo: float, hi: float, n_grid: int) -> tuple[float, float, Any]:
    """Grid search over ``[lo, hi]``, then zoomed grids around the best point.

    Each zoom evaluates :data:`ZOOM_POINTS` candidates in one batch over the two grid
    cells around the current best (a factor 10 narrower each time) until the cell is
    below ``1e-6 max(hi, 1e-3)`` rad: no serial scalar minimiser, whose import
    (``scipy.optimize``, about 0.6 s) would cost more than the whole search.

    Parameters
    ----------
    costs_of : callable
        ``thetas -> (costs, extra)``; ``extra`` (per-theta values, or None) is
        returned for the best theta.
    lo, hi : float
        The interval in rad.
    n_grid : int
        Points of the first grid, >= 2.

    Returns
    -------
    theta : float
        The minimiser in rad.
    cost : float
        Its cost.
    extra : object
        ``extra`` of the minimiser (None if ``costs_of`` gives none).
    """
    grid = np.linspace(lo, hi, n_grid)
    costs, extra = costs_of(grid)
    j = int(np.argmin(costs))
    best = (float(grid[j]), float(costs[j]), None if extra is None else extra[j])
    step = float(grid[1] - grid[0]) if n_grid > 1 else 0.0
    tol = 1e-6 * max(hi, 1e-3)
    while step > tol:
        a, b = max(lo, best[0] - step), min(hi, best[0] + step)
        zoom = np.linspace(a, b, ZOOM_POINTS)
        z_costs, z_extra = costs_of(zoom)
        k = int(np.argmin(z_costs))
        if z_costs[k] < best[1]:
            best = (float(zoom[k]), float(z_costs[k]), None if z_extra is None else z_extra[k])
        step = float(zoom[1] - zoom[0])
    return best


def viscous_fit(prior: TwoMassDrive, segments: list[CriterionWindow], lo: float, hi: float,
                n_grid: int, workers: int | None = None) -> tuple[float, float]:
    """Paper A's ``W_1`` (the prior as it is) minimised over theta in ``[lo, hi]``.

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters.
    segments : list of CriterionWindow
        The windows (:func:`criterion_window`).
    lo, hi : float
        The search interval in rad.
    n_grid : int
        Points of the first grid (:func:`search_theta`).
    workers : int, optional
        Threads for the simulations (default all cores).

    Returns
    -------
    theta : float
        The minimiser in rad.
    cost : float
        ``W_1`` there in (rad/s)^2.
    """
    def costs_of(th):
        return criterion_costs(prior, segments, th, workers), None

    theta, cost, _ = search_theta(costs_of, lo, hi, n_grid)
    return theta, cost


def coulomb_fit(prior: TwoMassDrive, segments: list[CriterionWindow], lo: float, hi: float,
                n_grid: int, workers: int | None = None,
                fc: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float, tuple]:
    """``W_1`` with Coulomb torques minimised over theta in ``[lo, hi]`` and
    ``fc_M, fc_L >= 0``.

    :func:`search_theta` on :func:`coulomb_profile_costs` (the torques profiled out
    for every candidate theta, starting from ``fc``).

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters (its Coulomb torques are replaced).
    segments : list of CriterionWindow
        The windows (:func:`criterion_window`).
    lo, hi : float
        The search interval in rad.
    n_grid : int
        Points of the first grid.
    workers : int, optional
        Threads for the simulations (default all cores).
    fc : tuple of float, optional
        ``(fc_M, fc_L)`` in N m to start from (default 0, 0).

    Returns
    -------
    theta : float
        The minimiser in rad.
    cost : float
        ``W_1`` simulated at it in (rad/s)^2.
    fc : tuple of float
        ``(fc_M, fc_L)`` in N m.
    """
    theta, _, best = search_theta(partial(_profile, prior, segments, fc, workers), lo, hi,
                                  n_grid)
    fc = (float(best[0]), float(best[1]))
    cost = float(criterion_costs(prior, segments, np.array([theta]), workers, fc=fc)[0])
    return theta, cost, fc


def _profile(prior, segments, fc, workers, thetas):
    return coulomb_profile_costs(prior, segments, thetas, fc, workers)


def likelihood_ratio(segments: list[CriterionWindow], viscous_cost: float,
                     coulomb_cost: float) -> float:
    """``N ln(W_1 viscous / W_1 Coulomb)`` over the ``N`` samples of ``W_1``.

    Twice the log-likelihood ratio of the two models for white Gaussian noise of
    unknown variance; chi-square with 2 degrees of freedom when the viscous model is
    right (the Coulomb torques on the boundary 0 make it smaller still).

    Parameters
    ----------
    segments : list of CriterionWindow
        The windows.
    viscous_cost, coulomb_cost : float
        ``W_1`` of the two fits in (rad/s)^2.

    Returns
    -------
    float
        The ratio, >= 0 (inf when the Coulomb fit is exact).
    """
    n = sum(seg.t.size for seg in segments)
    if not coulomb_cost > 0:
        return math.inf
    return n * math.log(max(viscous_cost, coulomb_cost) / coulomb_cost)


#: An estimate within this fraction of the interval's upper end from an end of the
#: search interval sits on that end (the zoomed grids stop at 1e-6 of it).
AT_EDGE = 1e-6


def search_edges(theta: float, lo: float, hi: float, *, advice: tuple = (),
                 stacklevel: int = 3) -> list[str]:
    """The ends of the search interval ``[lo, hi]`` that ``theta`` sits on, each warned.

    Parameters
    ----------
    theta : float
        The estimate in rad.
    lo, hi : float
        The search interval in rad.
    advice : tuple of str or Option, optional
        What to do, appended to the warning (e.g. widen ``n_theta``).
    stacklevel : int, optional
        The warning's ``stacklevel`` (default 3: the caller of the function that
        calls this one).

    Returns
    -------
    list of str
        ``"lower"``, ``"upper"``, both or none.

    Warns
    -----
    SearchEdgeWarning
        For each end it sits on: the criterion's minimum may lie beyond it (at a lower
        end of 0: the criterion is smallest without backlash).
    """
    ends = [end for end, edge in (("lower", lo), ("upper", hi))
            if abs(theta - edge) <= AT_EDGE * max(hi, 1e-300)]
    for end in ends:
        if end == "lower" and lo == 0.0:  # no minimum lies below a half-width of 0
            warnings.warn(SearchEdgeWarning(
                "theta is 0, the lower end of the search interval: the criterion is "
                "smallest without backlash on these records (check the prior's linear "
                "parameters, or use the joint method, which refines them)"),
                stacklevel=stacklevel)
            continue
        warnings.warn(SearchEdgeWarning(
            f"theta is at the {end} end of the search interval: the cost's minimum may lie "
            "beyond it", *advice), stacklevel=stacklevel)
    return ends


