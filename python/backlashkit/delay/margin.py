"""``delay_margin``: the maximal delay interval of a linear delay system (Chen 1995)."""

from __future__ import annotations

import math
import numbers
import warnings
from typing import Any

from .. import validate as v
from ..errors import InputError
from .chen import N_OMEGA, sweep_candidates
from .crossings import TOUCH_TOL, crossing_from_candidate, direction, merge_candidates
from .kronecker import kronecker_candidates
from .result import DelayMarginResult
from .spectral import rightmost_root
from .system import DelaySystem

__all__ = ["METHODS", "delay_margin", "margin_of_system"]

METHODS = ("sweep", "kronecker")
#: A polished crossing whose relative residual ``sigma_min(T) / (omega ||N|| + ||M||)``
#: exceeds this is
#: not a root (a spurious candidate) and is discarded.
RESIDUAL_TOL = 1e-8
#: Relative distance below and above ``h_max`` at which the rightmost root is checked.
VERIFY_STEP = 1e-3
#: Most grid frequencies of the sweep: its time and memory grow with them (1e9 asked
#: for more memory than a machine has), and a grid finer than this resolves nothing
#: that the default's 40 points and Newton's polish miss.
MAX_N_OMEGA = 1_000_000


def delay_margin(A0: Any, A: Any, B: Any = None, *, method: str = "sweep",
                 polish: bool = True, verify: bool = True,
                 n_omega: int = N_OMEGA) -> DelayMarginResult:
    """The largest ``h_max`` such that the delay system is stable for all ``h`` in
    ``[0, h_max)``.

    The system is ``x'(t) - sum_k B_k x'(t - k h) = A0 x(t) + sum_k A_k x(t - k h)``,
    ``k = 1..q`` (retarded when ``B`` is omitted). Preconditions are checked, not
    assumed: a system unstable at ``h = 0`` gives ``h_max = 0`` with
    ``stable_at_zero = False``; a neutral system whose difference operator is unstable
    (spectral radius of the companion of the ``B_k`` above 1) gives ``h_max = 0``; one
    with that radius equal to 1 is refused.

    Parameters
    ----------
    A0 : array_like, shape (n, n)
        Undelayed state matrix (1/s); a scalar is a 1x1 matrix.
    A : sequence of array_like, shape (n, n)
        ``[A1, ..., Aq]`` (1/s), ``A_k`` multiplying ``x(t - k h)``.
    B : sequence of array_like, shape (n, n), optional
        Neutral terms ``[B1, ..., Bq]`` (dimensionless).
    method : {"sweep", "kronecker"}
        ``"sweep"`` (default): Chen's (1995) frequency sweep of the unit-modulus
        generalized eigenvalues of the block-companion pencil, each sign change of
        ``log|z|`` refined by Newton's method on ``(omega, h)`` (``polish=True``) or by
        Brent's method (``polish=False``). ``"kronecker"``: the constant Kronecker-sum
        pencil of Chen, Gu & Nett (1995), one eigenproblem of size ``2 q n^2`` (for
        small systems and as a cross-check).
    polish : bool
        Polish every crossing ``(omega, h)`` by Newton's method on
        ``det T(j omega, h) = 0`` (default True).
    verify : bool
        Check the answer with the spectral method: the rightmost root must be left of
        the axis just below ``h_max`` and right of it just above (default True; a
        failure warns and is recorded in ``result.verification``).
    n_omega : int
        Frequency grid of the sweep.

    Returns
    -------
    DelayMarginResult
        ``h_max`` (s, ``math.inf`` when stable for every delay), ``omega`` (rad/s),
        ``vector``, ``stable_at_zero``, ``delay_independent``,
        ``stability_windows(h_range)`` and ``plot()``.

    Raises
    ------
    InputError
        Non-square, mismatched or non-finite matrices, an unknown method, or a neutral
        difference operator on the margin of stability.

    Examples
    --------
    >>> from backlashkit.delay import delay_margin
    >>> round(delay_margin(0.0, [-1.0]).h_max, 12)   # x' = -x(t - h): pi / 2
    1.570796326795
    """
    return margin_of_system(DelaySystem(A0, A, B), method=method, polish=polish,
                            verify=verify, n_omega=n_omega)


def margin_of_system(system: DelaySystem, *, method: str = "sweep", polish: bool = True,
                     verify: bool = True, n_omega: int = N_OMEGA) -> DelayMarginResult:
    """:func:`delay_margin` of a :class:`DelaySystem` already built.

    Parameters
    ----------
    system : DelaySystem
        The system.
    method : {"sweep", "kronecker"}
        See :func:`delay_margin`.
    polish : bool
        See :func:`delay_margin`.
    verify : bool
        See :func:`delay_margin`.
    n_omega : int
        See :func:`delay_margin`.

    Returns
    -------
    DelayMarginResult
        See :func:`delay_margin`.
    """
    if method not in METHODS:
        raise InputError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    if not (isinstance(n_omega, numbers.Integral) and not isinstance(n_omega, bool)
            and 10 <= n_omega <= MAX_N_OMEGA):
        raise InputError(f"n_omega must be an integer from 10 to {MAX_N_OMEGA:,}; got "
                         f"{n_omega!r}")
    polish, verify = v.flag("polish", polish), v.flag("verify", verify)
    rho = system.check_difference_operator()
    unstable0 = system.unstable_at_zero()
    sweep = None
    crossings = []
    if system.q and rho < 1.0:
        if method == "sweep":
            cands, sweep = sweep_candidates(system, n_omega=n_omega, newton=polish)
        else:
            cands = kronecker_candidates(system)
        crossings = [crossing_from_candidate(system, w, z, polish_root=polish)
                     for w, z in cands]
        if polish:
            crossings = [c for c in crossings if c.residual <= RESIDUAL_TOL]
        crossings = merge_candidates(crossings)
    result = DelayMarginResult(system, crossings, unstable_at_zero=unstable0,
                               difference_radius=rho, method=method, sweep=sweep)
    if verify and 0.0 < result.h_max < math.inf:
        _verify(result)
    return result


def _verify(result: DelayMarginResult) -> None:
    """Rightmost root just below and just above ``h_max`` (spectral method): left of the
    axis below; right of it above, or left again after a tangential touch."""
    first = min(result.crossings, key=lambda c: c.h0)
    d = direction(result.system, first.omega, first.h0)
    touch = abs(d.real) <= TOUCH_TOL * abs(d)
    below = rightmost_root(result.system, result.h_max * (1 - VERIFY_STEP)).real
    above = rightmost_root(result.system, result.h_max * (1 + VERIFY_STEP)).real
    passed = below < 0.0 and (above < 0.0 if touch else above >= 0.0)
    result.verification = {"residual": first.residual, "rightmost_below": below,
                           "rightmost_above": above, "step": VERIFY_STEP,
                           "touch": bool(touch), "passed": bool(passed)}
    if not passed:
        warnings.warn(
            f"delay_margin: the spectral check does not confirm h_max = {result.h_max:.10g} s "
            f"(rightmost real part {below:.3g} 1/s just below, {above:.3g} 1/s just above); "
            f"raise n_omega, or compare method='sweep' with method='kronecker'",
            RuntimeWarning, stacklevel=3)
