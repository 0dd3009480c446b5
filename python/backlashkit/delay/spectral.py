"""Rightmost characteristic roots at a given delay by Chebyshev collocation of the
infinitesimal generator (Breda, Maset & Vermiglio, SIAM J. Sci. Comput. 27, 2005).

An independent check of :mod:`.chen` and :mod:`.kronecker`: it never looks at the
imaginary axis or at unit-modulus eigenvalues; it approximates the spectrum of the
solution operator's generator on ``C([-q h, 0], R^n)`` by collocation at ``N + 1``
Chebyshev points and returns the eigenvalues of that matrix. For a neutral system the
domain condition ``phi'(0) - sum B_k phi'(-k h) = A0 phi(0) + sum A_k phi(-k h)``
becomes the first block row of a generalized eigenproblem.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import scipy.linalg

from .system import DelaySystem

__all__ = ["axis_frequency_scale", "default_nodes", "rightmost_root", "spectral_margin",
           "spectral_roots", "spectral_scan"]

#: Fewest collocation intervals, and the extra ones per unit of ``|s| q h`` for the
#: roots that can reach the imaginary axis (Chebyshev needs about ``|s| q h / 2``).
#: With 12, the rightmost root just below and above ``h_max`` has the sign and 3 digits
#: of a fine collocation on 42 random systems (n <= 6, q <= 3, some neutral:
#: tests/test_delay_agreement.py); with 4 nodes 35 of them fail.
MIN_NODES = 12
NODES_PER_UNIT = 0.6
MAX_NODES = 200
#: Samples of the unit circle for :func:`axis_frequency_scale`, and its safety factor.
N_CIRCLE = 64
SCALE_SAFETY = 1.5


@functools.lru_cache(maxsize=64)
def axis_frequency_scale(system: DelaySystem) -> float:
    """``max |lambda|`` over the generalized eigenvalues of ``(M(z), N(z))`` for ``z`` on
    the unit circle (sampled, widened): roots near the imaginary axis have ``|Im s|``
    below it, so the collocation must resolve them.

    Parameters
    ----------
    system : DelaySystem
        The system.

    Returns
    -------
    float
        rad/s.
    """
    zs = np.exp(2j * np.pi * np.arange(N_CIRCLE) / N_CIRCLE)
    m = np.stack([system.M(z) for z in zs])
    nmat = np.stack([system.N(z) for z in zs])
    return SCALE_SAFETY * float(np.max(np.abs(np.linalg.eigvals(np.linalg.solve(nmat, m)))))


def default_nodes(system: DelaySystem, h: float) -> int:
    """Collocation degree ``N`` that resolves the roots near the imaginary axis.

    Parameters
    ----------
    system : DelaySystem
        The system.
    h : float
        Delay (s).

    Returns
    -------
    int
        Between :data:`MIN_NODES` and :data:`MAX_NODES`.
    """
    units = axis_frequency_scale(system) * system.q * h
    return int(min(MAX_NODES, MIN_NODES + math.ceil(NODES_PER_UNIT * units)))


def _cheb(n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Chebyshev extremal points on [-1, 1] (descending) and the differentiation matrix
    (Trefethen, Spectral Methods in MATLAB, cheb.m)."""
    x = np.cos(np.pi * np.arange(n_nodes + 1) / n_nodes)
    c = np.ones(n_nodes + 1)
    c[0] = c[-1] = 2.0
    c *= (-1.0) ** np.arange(n_nodes + 1)
    dx = x[:, None] - x[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(n_nodes + 1))
    d -= np.diag(d.sum(axis=1))
    return x, d


def _lagrange_row(x: np.ndarray, t: float) -> np.ndarray:
    """Values at ``t`` of the Lagrange basis on the Chebyshev points ``x`` (barycentric)."""
    hit = np.flatnonzero(np.abs(x - t) < 1e-14)
    row = np.zeros(x.size)
    if hit.size:
        row[hit[0]] = 1.0
        return row
    w = (-1.0) ** np.arange(x.size)
    w[0] *= 0.5
    w[-1] *= 0.5
    terms = w / (t - x)
    return terms / terms.sum()


def spectral_roots(system: DelaySystem, h: float, *, n_nodes: int | None = None) -> np.ndarray:
    """Approximate characteristic roots at delay ``h``, rightmost first.

    Parameters
    ----------
    system : DelaySystem
    h : float
        Delay (s), >= 0 (``h = 0``: eigenvalues of the delay-free system).
    n_nodes : int, optional
        Collocation degree ``N`` (default :func:`default_nodes`).

    Returns
    -------
    numpy.ndarray, complex
        The ``n (N + 1)`` finite eigenvalues of the discretised generator, sorted by
        decreasing real part. The rightmost ones converge spectrally in ``N``.
    """
    n, q = system.n, system.q
    if h == 0 or q == 0:
        roots = np.linalg.eigvals(system.delay_free_matrix())
        return roots[np.argsort(-roots.real)]
    big_n = n_nodes or default_nodes(system, h)
    tau = q * h
    x, d = _cheb(big_n)
    d = d * (2.0 / tau)  # theta = tau (x - 1) / 2 maps [-1, 1] onto [-tau, 0]
    rows = [_lagrange_row(x, 1.0 - 2.0 * k / q) for k in range(1, q + 1)]
    size = n * (big_n + 1)
    gen = np.kron(d, np.eye(n))
    first = np.kron(np.eye(big_n + 1)[0], system.A0)
    for row, a in zip(rows, system.A, strict=True):
        first = first + np.kron(row, a)
    gen[:n, :] = first
    if system.neutral:
        rhs = np.eye(size)
        lhs0 = np.kron(np.eye(big_n + 1)[0], np.eye(n))
        for row, b in zip(rows, system.B, strict=True):
            lhs0 = lhs0 - np.kron(row, b)
        rhs[:n, :] = lhs0
        roots = scipy.linalg.eig(gen, rhs, right=False)
        roots = roots[np.isfinite(roots)]
    else:
        roots = np.linalg.eigvals(gen)
    return roots[np.argsort(-roots.real)]


def rightmost_root(system: DelaySystem, h: float, *, n_nodes: int | None = None) -> complex:
    """The approximate characteristic root with the largest real part at delay ``h``.

    Parameters
    ----------
    system : DelaySystem
    h : float
        Delay (s).
    n_nodes : int, optional
        Collocation degree (default :func:`default_nodes`).

    Returns
    -------
    complex
        1/s.
    """
    return complex(spectral_roots(system, h, n_nodes=n_nodes)[0])


def spectral_scan(system: DelaySystem, delays, *, n_nodes: int | None = None) -> np.ndarray:
    """Real part of the rightmost root at each delay.

    Parameters
    ----------
    system : DelaySystem
    delays : array_like
        Delays (s).
    n_nodes : int, optional
        Collocation degree (default: :func:`default_nodes` at each delay).

    Returns
    -------
    numpy.ndarray
        1/s, same shape as ``delays``.
    """
    return np.array([rightmost_root(system, float(h), n_nodes=n_nodes).real
                     for h in np.asarray(delays, dtype=float)])


def spectral_margin(system: DelaySystem, h_hi: float, *, n_scan: int = 200,
                    n_nodes: int | None = None, xtol: float = 1e-12) -> float:
    """The first delay in ``(0, h_hi]`` at which the rightmost root reaches the axis.

    A scan of :func:`spectral_scan` over ``n_scan`` delays followed by bisection on the
    first sign change (a touch between scan points is not seen).

    Parameters
    ----------
    system : DelaySystem
    h_hi : float
        End of the scanned range (s).
    n_scan : int
        Number of scanned delays.
    n_nodes : int, optional
        Collocation degree (default :func:`default_nodes`).
    xtol : float
        Relative tolerance of the bisection.

    Returns
    -------
    float
        The delay (s); ``0.0`` if unstable at the first scan point, ``math.inf`` if no
        sign change in the range.
    """
    hs = np.linspace(0.0, h_hi, n_scan + 1)[1:]

    def re(h):
        return rightmost_root(system, h, n_nodes=n_nodes).real

    prev_h, prev = 0.0, re(hs[0] * 1e-6)
    if prev >= 0:
        return 0.0
    for h in hs:
        cur = re(h)
        if cur >= 0:
            lo, hi = prev_h, h
            while hi - lo > xtol * hi:
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if re(mid) < 0 else (lo, mid)
            return 0.5 * (lo + hi)
        prev_h = h
    return math.inf
