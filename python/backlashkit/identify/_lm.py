"""Levenberg-Marquardt on the normal equations, the joint estimator's local optimiser."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: Initial Marquardt damping; divided by DAMPING_DOWN after an accepted step (not below
#: DAMPING_MIN) and multiplied by DAMPING_UP after a rejected one, at most
#: STEP_TRIALS times per iteration: the usual asymmetric schedule (fast to trust a
#: good model, slower to give up on it).
DAMPING_START = 1e-3
DAMPING_DOWN = 5.0
DAMPING_UP = 8.0
DAMPING_MIN = 1e-12
STEP_TRIALS = 12
#: Marquardt scaling floor relative to the largest diagonal of ``J^T J``: a parameter
#: the residual does not see still gets a finite, damped step.
SCALE_FLOOR = 1e-12
#: An accepted step that lowers the cost by less than this (chi-square units) ends the
#: run: a parameter change of about 0.03 standard errors.
FINAL_ATOL = 1e-3


@dataclass
class LMState:
    """Levenberg-Marquardt iterate: point, residual, cost, Jacobian at the point."""

    z: np.ndarray
    r: np.ndarray
    cost: float
    jac: np.ndarray | None
    mu: float = DAMPING_START
    done: bool = False


def lm(fun: Callable[[np.ndarray], np.ndarray],
       jac: Callable[[np.ndarray, np.ndarray], np.ndarray], z0: np.ndarray, *,
       max_iter: int, state: LMState | None = None, rtol: float = 1e-10, atol: float = FINAL_ATOL,
       max_step: float = 0.5, bounds: tuple[np.ndarray, np.ndarray] | None = None) -> LMState:
    """Levenberg-Marquardt on the normal equations (Marquardt scaling).

    The residual vector is long (every sample of both speeds) and the parameters few,
    so the step is solved from ``J^T J`` (n x n) rather than by an SVD of ``J``.
    Stops after ``max_iter`` Jacobians, or when an accepted step lowers the cost by
    less than ``rtol`` relative or ``atol`` absolute (the cost is in chi-square units;
    default :data:`FINAL_ATOL`), or when no step lowers it. An accepted step is
    extrapolated (doubled while the cost keeps falling); no step changes a
    log-parameter by more than ``max_step``. ``state`` continues an
    earlier run that stopped at ``max_iter``.
    """
    if state is None or state.done:
        r0 = fun(z0)
        state = LMState(np.array(z0, float), r0, float(r0 @ r0), None)
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
        if not _step(state, fun, rtol, atol, max_step, bounds):
            state.done = True
        if state.done:
            break
    return state


def _step(state: LMState, fun, rtol: float, atol: float, max_step: float, bounds) -> bool:
    """One damped step from ``state`` (updated in place); False when none lowers the cost."""
    jz = state.jac
    g = jz.T @ state.r
    a = jz.T @ jz
    d = np.maximum(np.diag(a), SCALE_FLOOR * max(float(np.max(np.diag(a))), 1e-300))
    for _ in range(STEP_TRIALS):
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
            z_new, r_new, c_new = _extrapolate(state, fun, g, step, z_new, r_new, c_new,
                                               max_step, bounds)
            gain = state.cost - c_new
            state.z, state.r, state.jac = z_new, r_new, None
            old, state.cost = state.cost, c_new
            state.mu = max(state.mu / DAMPING_DOWN, DAMPING_MIN)
            if gain <= rtol * old or gain < atol:
                state.done = True
            return True
        state.mu *= DAMPING_UP
    return False


def _extrapolate(state: LMState, fun, g, step, z_new, r_new, c_new, max_step, bounds):
    """Double an accepted step while the cost keeps falling (slow valleys, e.g. f_sh),
    where the parabola along the step predicts that it falls (:func:`_doubling_pays`)."""
    while True:
        if 2.0 * float(np.max(np.abs(step))) > max_step:
            break
        if not _doubling_pays(state.cost, float(g @ step), c_new):
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
    return z_new, r_new, c_new


def _doubling_pays(cost: float, slope: float, c_new: float) -> bool:
    """Whether the parabola through the cost along a step, ``cost`` and its slope
    ``2 slope`` at the start (``slope = g . step``, ``g = J^T r``) and ``c_new`` at
    the step's end, is lower at twice the step than at its end: ``c(t) = cost + 2 slope
    t + k t^2`` with ``k = c_new - cost - 2 slope``, and ``c(2) < c(1)`` where
    ``3 k < -2 slope``. On paper A's protocol most accepted steps end near the
    minimum along their line, and a doubling tried there costs a simulation and fails;
    the parabola tells those apart (docs/design/joint-search.md, "Doubling a step")."""
    curvature = c_new - cost - 2.0 * slope
    return 3.0 * curvature < -2.0 * slope
