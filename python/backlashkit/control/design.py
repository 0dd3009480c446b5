"""Model-reference design of paper B, Section III-A: the Diophantine equation (3.3).

For a known plant ``G(s) = k_p Z(s)/R(s)`` (``Z`` monic of degree ``m``, ``R`` monic
of degree ``n``), a reference model ``y_m = 1/R_m(s) [r]`` and a filter ``Lambda(s)``
of degree ``n``, the linear controller (3.2)

    u_d = theta_1' a(s)/Lambda(s) [u_d] + theta_2' a(s)/Lambda(s) [y] + theta_3 r,
    a(s) = (1, s, ..., s^{n-1})',

matches the closed loop to the reference model when its parameters solve

    theta_1' a R + theta_2' a k_p Z = Lambda (R - k_p theta_3 Z R_m),   theta_3 = 1/(k_p r_m),

with ``r_m`` the leading coefficient of ``R_m`` (1 in the paper, where ``R_m`` is
monic). The error model (3.10) then has ``H(s) = (1/theta_3) / R_m(s)
(1 - theta_1' a(s)/Lambda(s))`` (the OCR prints ``Lambda/Lambda`` for ``a/Lambda``).

Assumptions checked (paper B, Section III): A1 ``Z`` Hurwitz; A2 ``deg R_m`` equals
the relative degree ``n* = n - m >= 1``; ``R_m`` and ``Lambda`` Hurwitz; ``Lambda`` of
degree ``n``; ``Z`` and ``R`` coprime (otherwise (3.3) has no unique solution).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError
from ..lti import as_transfer_function

__all__ = ["MRCDesign", "companion", "default_filter", "default_reference_model", "design_mrc"]

#: Real parts above ``-_HURWITZ_TOL * (1 + |root|)`` count as not in the open left half-plane.
_HURWITZ_TOL = 1e-9


def _roots_fmt(roots: np.ndarray) -> str:
    return ", ".join(
        f"{complex(r).real:.6g}{complex(r).imag:+.6g}j"
        if abs(complex(r).imag) > 1e-12
        else f"{complex(r).real:.6g}"
        for r in roots
    )


def _unstable_roots(poly: np.ndarray) -> np.ndarray:
    if poly.size <= 1:
        return np.zeros(0)
    r = np.roots(poly)
    return r[r.real >= -_HURWITZ_TOL * (1 + np.abs(r))]


def default_reference_model(n_star: int) -> np.ndarray:
    """Default ``R_m(s) = (s+2)(s+3)...(s+n*+1)`` (paper B's example for ``n* = 2``).

    Parameters
    ----------
    n_star : int
        Relative degree of the plant (``>= 1``).

    Returns
    -------
    numpy.ndarray
        Coefficients of ``R_m``, highest power first.
    """
    p = np.array([1.0])
    for i in range(n_star):
        p = np.polymul(p, [1.0, 2.0 + i])
    return p


def default_filter(n: int) -> np.ndarray:
    """Default ``Lambda(s) = (s+2)^n`` (paper B's example for ``n = 2``).

    Parameters
    ----------
    n : int
        Plant order.

    Returns
    -------
    numpy.ndarray
        Coefficients of ``Lambda``, highest power first.
    """
    p = np.array([1.0])
    for _ in range(n):
        p = np.polymul(p, [1.0, 2.0])
    return p


def companion(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Controllable canonical realisation of a strictly proper ``num/den``.

    The states are ``x_i = s^{i-1}/den [u]`` (``i = 1..q``), so that with
    ``num = (1,)`` the state vector is ``a(s)/den [u]``.

    Parameters
    ----------
    num : numpy.ndarray
        Numerator, highest power first, degree ``< q``.
    den : numpy.ndarray
        Denominator of degree ``q >= 1``, highest power first (need not be monic).

    Returns
    -------
    A : numpy.ndarray, shape (q, q)
        State matrix (companion form).
    b : numpy.ndarray, shape (q,)
        Input vector.
    c : numpy.ndarray, shape (q,)
        Output vector: ``dx/dt = A x + b u``, ``y = c x``.
    """
    den = np.asarray(den, dtype=float)
    q = den.size - 1
    asc = den[::-1] / den[0]
    a = np.zeros((q, q))
    a[:-1, 1:] = np.eye(q - 1)
    a[-1, :] = -asc[:q]
    b = np.zeros(q)
    b[-1] = 1.0 / den[0]
    num_asc = np.asarray(num, dtype=float)[::-1]
    if num_asc.size > q:
        raise InputError("companion realisation needs a strictly proper transfer function")
    c = np.zeros(q)
    c[: num_asc.size] = num_asc
    return a, b, c


@dataclass(frozen=True)
class MRCDesign:
    """Solution of paper B's model-reference design (3.2)-(3.3) for a known plant.

    Attributes
    ----------
    k_p : float
        High-frequency gain of the plant.
    zeros_poly, poles_poly : numpy.ndarray
        Monic ``Z(s)`` and ``R(s)``, highest power first.
    reference_model : numpy.ndarray
        ``R_m(s)`` (reference model ``1/R_m``).
    filter : numpy.ndarray
        ``Lambda(s)``.
    theta_1, theta_2 : numpy.ndarray, shape (n,)
        Controller parameters (coefficients of ``1, s, ..., s^{n-1}``).
    theta_3 : float
        Feed-forward gain ``1/(k_p r_m)``.
    h_num, h_den : numpy.ndarray
        ``H(s)`` of the error model (3.10), highest power first.
    """

    k_p: float
    zeros_poly: np.ndarray
    poles_poly: np.ndarray
    reference_model: np.ndarray
    filter: np.ndarray
    theta_1: np.ndarray
    theta_2: np.ndarray
    theta_3: float
    h_num: np.ndarray
    h_den: np.ndarray

    def __repr__(self) -> str:
        # the dataclass's would print every polynomial as an array
        th = ", ".join(f"{x:.6g}" for x in (*self.theta_1, *self.theta_2))
        return (f"MRCDesign(n={self.n}, n*={self.relative_degree}, theta_1 and theta_2 "
                f"[{th}], theta_3={self.theta_3:.6g})")

    @property
    def n(self) -> int:
        """Plant order ``n``."""
        return int(self.poles_poly.size - 1)

    @property
    def relative_degree(self) -> int:
        """Relative degree ``n* = n - m`` of the plant."""
        return int(self.poles_poly.size - self.zeros_poly.size)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``theta_1``, ``theta_2``, ``theta_3``, polynomials).

        Returns
        -------
        dict
            Plain Python lists and floats.
        """
        return {
            "theta_1": [float(x) for x in self.theta_1],
            "theta_2": [float(x) for x in self.theta_2],
            "theta_3": float(self.theta_3),
            "k_p": float(self.k_p),
            "Z": [float(x) for x in self.zeros_poly],
            "R": [float(x) for x in self.poles_poly],
            "R_m": [float(x) for x in self.reference_model],
            "Lambda": [float(x) for x in self.filter],
        }

    def matching_error(self) -> float:
        """Largest relative departure of the matched closed loop (``u = u_d``, no
        backlash) ``theta_3 G / (1 - theta_1' a / Lambda - theta_2' a G / Lambda)``
        from the reference model ``1 / R_m``, at 0.3, 1 and 3 times the geometric mean
        of the reference model's pole magnitudes.

        Returns
        -------
        float
            Zero up to rounding for a design that matches.
        """
        poles = np.abs(np.roots(self.reference_model))
        w0 = float(np.exp(np.mean(np.log(poles[poles > 0])))) if np.any(poles > 0) else 1.0
        s = 1j * w0 * np.array([0.3, 1.0, 3.0])
        num, den = self.k_p * np.polyval(self.zeros_poly, s), np.polyval(self.poles_poly, s)
        lam = np.polyval(self.filter, s)
        p = np.polyval(self.theta_1[::-1], s) / lam
        q = np.polyval(self.theta_2[::-1], s) / lam
        with np.errstate(all="ignore"):
            closed = self.theta_3 * num / (den - p * den - q * num)
            want = 1.0 / np.polyval(self.reference_model, s)
            err = np.max(np.abs(closed - want) / np.abs(want))
        return float(err) if np.isfinite(err) else math.inf

    def diophantine_residual(self) -> float:
        """Largest coefficient of ``LHS - RHS`` of (3.3), relative to the RHS scale.

        Returns
        -------
        float
            Zero up to rounding for a correct solution.
        """
        lhs, rhs = _diophantine_sides(self)
        d = np.polysub(lhs, rhs)
        return float(np.max(np.abs(d)) / max(1.0, np.max(np.abs(rhs))))


def _diophantine_sides(d: MRCDesign) -> tuple[np.ndarray, np.ndarray]:
    """Both sides of (3.3) expanded as polynomials (highest power first)."""
    t1 = d.theta_1[::-1]  # descending coefficients of theta_1' a(s)
    t2 = d.theta_2[::-1]
    lhs = np.polyadd(np.polymul(t1, d.poles_poly), np.polymul(t2, d.k_p * d.zeros_poly))
    rhs = np.polymul(
        d.filter,
        np.polysub(d.poles_poly, d.k_p * d.theta_3 * np.polymul(d.zeros_poly, d.reference_model)),
    )
    return lhs, rhs


def _hurwitz_poly(name: str, coeffs: Any) -> np.ndarray:
    try:
        arr = np.atleast_1d(np.asarray(coeffs, dtype=float)).ravel()
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a list of real coefficients, got {coeffs!r}") from None
    arr = v.finite_array(name, arr)
    nz = np.flatnonzero(arr)
    if nz.size == 0:
        raise InputError(f"{name} must not be the zero polynomial, got {arr.tolist()!r}")
    arr = arr[nz[0] :]
    bad = _unstable_roots(arr)
    if bad.size:
        raise InputError(
            f"{name} must be Hurwitz (all roots in the open left half-plane), got roots at "
            f"{_roots_fmt(bad)}"
        )
    return arr


#: Roots of the plant's numerator and denominator this close, relative to their size,
#: count as a pole-zero cancellation: (3.3) then has no unique solution, or gains of
#: order the inverse of their distance.
CANCEL_RTOL = 1e-8
#: (3.3)'s Sylvester matrix solved as it is up to this condition number; beyond (fast
#: poles or an extreme gain scale its columns apart) with its rows and columns
#: equilibrated first. Either way the design is then checked by its purpose
#: (:data:`MATCH_RTOL`).
PLAIN_SOLVE_COND = 1e12
#: Largest departure of the matched closed loop from the reference model
#: (:meth:`MRCDesign.matching_error`) of a design that is returned: far above rounding
#: for paper B's plant and random well-scaled ones, far below what a user would notice.
MATCH_RTOL = 1e-6


def _check_coprime(z: np.ndarray, den: np.ndarray) -> None:
    """Refuse a numerator ``z`` and denominator ``den`` with a common root (to
    :data:`CANCEL_RTOL`)."""
    zeros, poles = np.roots(z), np.roots(den)
    for zero in zeros:
        gap = np.abs(poles - zero)
        size = np.maximum(np.abs(poles), abs(zero))
        near = gap <= CANCEL_RTOL * np.where(size > 0, size, 1.0)
        if np.any(near):
            pole = poles[np.argmax(near)]
            raise InputError(
                f"plant has a common root of numerator and denominator near s = "
                f"{_root_text(pole)} (pole-zero cancellation); the Diophantine equation "
                "(3.3) has no unique solution - cancel it first")


def _root_text(root: complex) -> str:
    return f"{root.real:.6g}" if root.imag == 0 else f"{root.real:.6g}{root.imag:+.6g}j"


def _diophantine(mat: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """(3.3)'s solution; with rows and columns equilibrated where ``mat`` is badly
    scaled (:data:`PLAIN_SOLVE_COND`); NaN where it is singular even so (the design's
    check, :meth:`MRCDesign.matching_error`, then refuses it)."""
    with np.errstate(all="ignore"):
        if np.linalg.cond(mat) <= PLAIN_SOLVE_COND:
            return np.linalg.solve(mat, rhs)
        rows = 1.0 / np.max(np.abs(mat), axis=1)
        scaled = mat * rows[:, np.newaxis]
        cols = 1.0 / np.max(np.abs(scaled), axis=0)
        try:
            return np.linalg.solve(scaled * cols, rhs * rows) * cols
        except np.linalg.LinAlgError:
            return np.full(rhs.shape, np.nan)


def design_mrc(
    plant: Any,
    *,
    reference_model: Any = None,
    filter: Any = None,  # noqa: A002 - the paper's name for Lambda
) -> MRCDesign:
    """Solve paper B's Diophantine equation (3.3) for a known plant.

    Parameters
    ----------
    plant : tuple or python-control or scipy.signal LTI object
        ``G(s) = k_p Z(s)/R(s)``; ``(num, den)`` highest power first, a python-control
        ``TransferFunction``/``StateSpace`` or a ``scipy.signal.lti``.
    reference_model : array_like, optional
        ``R_m(s)`` (reference model ``y_m = 1/R_m [r]``), Hurwitz, of degree equal to
        the plant's relative degree (A2). Default ``(s+2)(s+3)...``.
    filter : array_like, optional
        ``Lambda(s)``, Hurwitz, of degree ``n`` (the plant order). Default ``(s+2)^n``.

    Returns
    -------
    MRCDesign
        Controller parameters and the error-model filter ``H(s)``.

    Raises
    ------
    InputError
        If the plant is improper, has relative degree 0, violates A1 (zeros not in
        the open left half-plane), has a pole-zero cancellation, or ``R_m`` /
        ``Lambda`` violate A2 / are not Hurwitz / have the wrong degree.
    """
    num, den = as_transfer_function(plant)
    n = den.size - 1
    if num.size > den.size:
        raise InputError(
            f"plant must be proper; its numerator degree {num.size - 1} exceeds its "
            f"denominator degree {n}"
        )
    n_star = n - (num.size - 1)
    if n_star < 1:
        raise InputError(
            "plant must be strictly proper (relative degree >= 1) for the backlash-inverse "
            f"controller; got relative degree {n_star}"
        )
    k_p = float(num[0])
    z = num / k_p
    bad = _unstable_roots(z)
    if bad.size:
        raise InputError(
            "plant violates assumption A1 (minimum phase): zeros at "
            f"{_roots_fmt(bad)} are not in the open left half-plane; model-reference "
            "control would cancel them"
        )
    r_m = (
        default_reference_model(n_star)
        if reference_model is None
        else _hurwitz_poly("reference_model (R_m)", reference_model)
    )
    if r_m.size - 1 != n_star:
        raise InputError(
            "reference_model (R_m) violates assumption A2: its degree must equal the "
            f"plant's relative degree {n_star}, got degree {r_m.size - 1}"
        )
    lam = default_filter(n) if filter is None else _hurwitz_poly("filter (Lambda)", filter)
    if lam.size - 1 != n:
        raise InputError(
            f"filter (Lambda) must have degree n = {n} (the plant order), got degree "
            f"{lam.size - 1}"
        )
    theta_3 = 1.0 / (k_p * r_m[0])
    rhs = np.polymul(lam, np.polysub(den, k_p * theta_3 * np.polymul(z, r_m)))
    rhs = np.trim_zeros(rhs, "f") if np.any(rhs) else np.zeros(1)
    # leading coefficient of s^{2n} cancels by the choice of theta_3
    rhs_asc = np.zeros(2 * n)
    asc = rhs[::-1]
    if asc.size > 2 * n and np.max(np.abs(asc[2 * n :])) > 1e-9 * max(1.0, np.max(np.abs(asc))):
        raise InputError("internal error: (3.3) right-hand side has degree 2n")  # pragma: no cover
    rhs_asc[: min(asc.size, 2 * n)] = asc[: 2 * n]
    mat = np.zeros((2 * n, 2 * n))
    r_asc, zk_asc = den[::-1], (k_p * z)[::-1]
    for i in range(n):
        mat[i : i + r_asc.size, i] = r_asc
        mat[i : i + zk_asc.size, n + i] = zk_asc
    _check_coprime(z, den)
    sol = _diophantine(mat, rhs_asc)
    theta_1, theta_2 = sol[:n], sol[n:]
    h_num = np.polysub(lam, theta_1[::-1]) / theta_3
    h_den = np.polymul(lam, r_m)
    design = MRCDesign(
        k_p=k_p,
        zeros_poly=z,
        poles_poly=den,
        reference_model=r_m,
        filter=lam,
        theta_1=theta_1,
        theta_2=theta_2,
        theta_3=float(theta_3),
        h_num=h_num,
        h_den=h_den,
    )
    error = design.matching_error()
    if not error <= MATCH_RTOL:
        raise InputError(
            f"the design is too ill-conditioned for this plant: its matched closed loop "
            f"departs from the reference model by {error:.2g} (relative; poles or gains "
            "many orders of magnitude apart): rescale time or the plant's units")
    return design
