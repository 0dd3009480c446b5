"""The constant Kronecker-sum pencil of Chen, Gu & Nett (1995): one eigenproblem, no sweep.

If ``j omega`` is a generalized eigenvalue of ``(M(z), N(z))`` with ``|z| = 1``, then
``-j omega`` is one of ``(M(1/z), N(1/z))`` (real matrices, ``1/z = conj z``), so

    det( M(z) (x) N(1/z) + N(z) (x) M(1/z) ) = 0,

a matrix polynomial of degree ``2 q`` in ``z`` (after multiplying by ``z^q``) with
constant ``n^2 x n^2`` coefficients. Its unit-modulus roots are the candidates;
for each, the generalized eigenvalues of ``(M(z), N(z))`` on the imaginary axis give
the frequencies. Roots with ``|z| != 1`` and eigenvalue pairs ``lambda_i + conj
lambda_j = 0`` off the axis are discarded. Cost: one ``2 q n^2`` generalized
eigenproblem, so this is the method for small systems.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .system import DelaySystem

__all__ = ["kronecker_candidates", "kronecker_coefficients"]

#: ``| |z| - 1 |`` below this makes ``z`` a candidate (double roots, at tangential
#: touches, are perturbed by about the square root of the rounding error).
UNIT_TOL = 1e-6
#: ``|Re lambda|`` below this times ``(|lambda| + scale)`` puts ``lambda`` on the axis.
AXIS_TOL = 1e-6
#: Frequencies below this times the scale are the ``omega -> 0`` limit (``h -> inf``).
OMEGA_FLOOR_REL = 1e-9


def kronecker_coefficients(system: DelaySystem) -> list[np.ndarray]:
    """Coefficients ``C_0 .. C_2q`` of ``z^q (M(z) (x) N(1/z) + N(z) (x) M(1/z))``.

    Parameters
    ----------
    system : DelaySystem

    Returns
    -------
    list of numpy.ndarray, shape (n^2, n^2) each
        ``C_d`` multiplies ``z^d``.
    """
    n, q = system.n, system.q
    m_list = [system.A0, *system.A]
    n_list = [np.eye(n), *(-b for b in system.B)]
    coefs = [np.zeros((n * n, n * n)) for _ in range(2 * q + 1)]
    for i in range(q + 1):
        for j in range(q + 1):
            term = np.kron(m_list[i], n_list[j]) + np.kron(n_list[i], m_list[j])
            coefs[q + i - j] += term
    return coefs


def _polynomial_roots(coefs: list[np.ndarray]) -> np.ndarray:
    d, m = len(coefs) - 1, coefs[0].shape[0]
    a = np.zeros((d * m, d * m))
    b = np.eye(d * m)
    a[:m, :] = np.concatenate([-coefs[i] for i in range(d - 1, -1, -1)], axis=1)
    b[:m, :m] = coefs[d]
    if d > 1:
        a[m:, : (d - 1) * m] = np.eye((d - 1) * m)
    alpha, beta = scipy.linalg.eig(a, b, right=False, homogeneous_eigvals=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(beta) > 0, alpha / beta, np.inf)


def kronecker_candidates(system: DelaySystem) -> list[tuple[float, complex]]:
    """Frequencies ``omega > 0`` with ``det T(j omega, h) = 0`` for some ``h``.

    Parameters
    ----------
    system : DelaySystem

    Returns
    -------
    list of (float, complex)
        ``(omega, z)`` with ``|z| = 1`` and ``exp(-j omega h0) = z``.
    """
    roots = _polynomial_roots(kronecker_coefficients(system))
    roots = roots[np.isfinite(roots)]
    roots = roots[np.abs(np.abs(roots) - 1.0) <= UNIT_TOL]
    scale = system.scale
    out: list[tuple[float, complex]] = []
    for z in roots / np.abs(roots):
        lam = scipy.linalg.eig(system.M(z), system.N(z), right=False)
        lam = lam[np.isfinite(lam)]
        on_axis = np.abs(lam.real) <= AXIS_TOL * (np.abs(lam) + scale)
        for w in lam[on_axis].imag:
            if w > OMEGA_FLOOR_REL * scale:
                out.append((float(w), complex(z)))
            elif w < -OMEGA_FLOOR_REL * scale:
                out.append((float(-w), complex(np.conj(z))))
    return out
