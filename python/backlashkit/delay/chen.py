"""Chen's (1995) frequency sweep: unit-modulus generalized eigenvalues of the
frequency-dependent block-companion pencil.

At ``s = j omega`` the characteristic equation ``det T(j omega, h) = 0`` is a matrix
polynomial in ``z = exp(-j omega h)``::

    Q(z; omega) = Q_0 + Q_1 z + ... + Q_q z^q,
    Q_0 = j omega I - A0,   Q_k = -(A_k + j omega B_k),

whose roots are the generalized eigenvalues of its block-companion pencil. A root of
the delay system lies on the imaginary axis at ``omega`` exactly when one of them is
on the unit circle, and then ``h = (-arg z + 2 pi k) / omega``. The sweep follows the
moduli ``|z_i(omega)|`` on a frequency grid (eigenvalues matched from point to point),
refines each sign change of ``log|z_i|`` by Brent's method, and each interior minimum of
``|log|z_i||`` that may touch zero (tangential touches, and pairs of crossings inside
one grid cell) by bounded minimisation. Frequencies are bounded above by
:func:`frequency_bound`; crossings that converge to ``omega -> 0`` (where ``|z| -> 1``
without a root, e.g. ``x' = -x - x(t - h)``) lie in the run of unresolvable points at
the low end of the grid and are dropped: they mean ``h -> inf``.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.optimize import brentq, linear_sum_assignment, minimize_scalar

from .crossings import polish
from .system import DelaySystem

__all__ = ["SweepData", "frequency_bound", "sweep_candidates", "unit_circle_eigenvalues"]

#: ``|log|z||`` below this cannot be told from zero in double precision; such points
#: carry no sign.
LOG_MODULUS_NOISE = 1e-10
#: Newton's start from the grid is accepted when it converges (relative residual below
#: this) near the cell with ``z`` within this distance of the interpolated one.
NEWTON_RESIDUAL = 1e-10
NEWTON_PHASE_JUMP = 0.3
#: ... and within the cell, widened by this fraction of its width (rounding at the ends).
CELL_SLACK = 1e-6
#: Cells are bisected (at most REFINE_LEVELS times) where an eigenvalue's distance to
#: the unit circle at an end is below REACH times its movement across the cell.
REACH = 1.0
REFINE_LEVELS = 2
#: Bound on ``|log|z||`` in the refinements (zero and infinite eigenvalues).
LOG_MODULUS_CAP = 700.0
#: Lowest frequency of the grid, relative to the frequency bound: below it crossings
#: mean delays beyond ~1e9 / scale s and are treated as the ``omega -> 0`` limit.
OMEGA_FLOOR_REL = 1e-9
#: Default number of grid frequencies (LOG_FRACTION of them log-spaced from the floor,
#: the others linear).
N_OMEGA = 40
LOG_FRACTION = 0.4
#: Condition number above which ``Q_q`` is not inverted in the companion form, and the
#: relative distance of ``j omega`` to an eigenvalue of A0 below which ``Q_0`` is not.
COND_LIMIT = 1e10
SINGULAR_SEP = 1e-8
#: Samples of the unit circle for the frequency bound, per delay term (``M(z)`` is a
#: polynomial of degree q in z), with a floor.
N_CIRCLE_PER_DELAY = 16
N_CIRCLE_MIN = 32
#: Safety factor on the sampled frequency bound.
BOUND_SAFETY = 1.5
#: Lightly damped modes of ``A0`` make narrow features in ``|z_i(omega)|`` around
#: ``Im lambda`` of width ``|Re lambda|``: the grid gets ``MODE_POINTS`` extra points over
#: ``Im lambda +- MODE_HALF_WIDTH |Re lambda|`` for each lightly damped mode.
MODE_POINTS = 17
MODE_HALF_WIDTH = 6.0
#: Only modes with ``|Re lambda| < LIGHT_DAMPING Im lambda`` (damping ratio below about
#: 0.2): broader features are resolved by the base grid.
LIGHT_DAMPING = 0.2
#: A grid minimum of ``|log|z||`` is refined when a parabola through it and its
#: neighbours dips below this fraction of its value (it may reach zero between points).
DIP_FRACTION = 0.5


class SweepData:
    """Moduli of the generalized eigenvalues along the frequency grid (for plots).

    Parameters
    ----------
    omega : numpy.ndarray, shape (K,)
        Grid frequencies (rad/s).
    z : numpy.ndarray, shape (K, q n)
        Eigenvalues ``z_i(omega)``, matched from point to point (columns follow one
        eigenvalue; ``inf`` for infinite ones).
    """

    def __init__(self, omega: np.ndarray, z: np.ndarray) -> None:
        self.omega = omega
        self.z = z

    def moduli(self) -> np.ndarray:
        """``|z_i(omega)|``, shape (K, q n).

        Returns
        -------
        numpy.ndarray
            Shape (K, q n); ``inf`` for infinite eigenvalues.
        """
        return np.abs(self.z)


def frequency_bound(system: DelaySystem) -> float:
    """An upper bound of the frequencies at which a root can be on the imaginary axis.

    ``j omega`` on the axis is a generalized eigenvalue of ``(M(z), N(z))`` for some
    ``|z| = 1``, so ``|omega| <= max_z max |lambda(M(z), N(z))|``: sampled at
    :data:`N_CIRCLE_PER_DELAY` points per delay term on the circle and widened by
    :data:`BOUND_SAFETY`. For a retarded system it is also capped by the rigorous
    ``||A0|| + sum ||A_k||`` (far too loose for stiff drives, whose resonances it would
    drown in a coarse grid).

    Parameters
    ----------
    system : DelaySystem
        The system.

    Returns
    -------
    float
        rad/s.
    """
    k = max(N_CIRCLE_MIN, N_CIRCLE_PER_DELAY * system.q)
    zs = np.exp(2j * np.pi * np.arange(k) / k)
    m = np.stack([system.M(z) for z in zs])
    nmat = np.stack([system.N(z) for z in zs])
    lam = np.linalg.eigvals(np.linalg.solve(nmat, m))
    bound = BOUND_SAFETY * float(np.max(np.abs(lam)))
    if not system.neutral:
        bound = min(bound, 1.01 * system.scale)
    return max(bound, 1e-12 * system.scale)


def _coefficients(system: DelaySystem, omega: np.ndarray) -> list[np.ndarray]:
    """``Q_0 .. Q_q`` at each frequency, shape (K, n, n) each."""
    jw = 1j * omega[:, None, None]
    eye = np.eye(system.n)
    out = [jw * eye - system.A0]
    for a, b in zip(system.A, system.B, strict=True):
        out.append(-(a + jw * b))
    return out


def _companion_eigs(coefs: list[np.ndarray], lead: int) -> np.ndarray:
    """Eigenvalues of the monic companion with leading coefficient ``coefs[lead]``
    (``lead = q``: roots ``z``; ``lead = 0``: roots ``1/z``), batched over frequency."""
    q = len(coefs) - 1
    k, n = coefs[0].shape[0], coefs[0].shape[1]
    order = range(q - 1, -1, -1) if lead == q else range(1, q + 1)
    comp = np.zeros((k, q * n, q * n), dtype=complex)
    blocks = [-np.linalg.solve(coefs[lead], coefs[i]) for i in order]
    comp[:, :n, :] = np.concatenate(blocks, axis=2)
    if q > 1:
        comp[:, n:, : (q - 1) * n] = np.eye((q - 1) * n)
    return np.linalg.eigvals(comp)


def unit_circle_eigenvalues(system: DelaySystem, omega: np.ndarray) -> np.ndarray:
    """The roots ``z`` of ``det Q(z; omega) = 0`` at each frequency.

    Parameters
    ----------
    system : DelaySystem
    omega : numpy.ndarray, shape (K,)
        Frequencies (rad/s).

    Returns
    -------
    numpy.ndarray, shape (K, q n), complex
        Unordered; ``inf`` where a coefficient ``Q_q`` is singular.
    """
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    coefs = _coefficients(system, omega)
    q = len(coefs) - 1
    # Q_0 = j omega I - A0 is singular only at imaginary eigenvalues of A0: elsewhere
    # the roots are taken as 1/mu of the companion with leading Q_0 (no SVD per point)
    lam0 = np.linalg.eigvals(system.A0)
    dist = np.min(np.abs(1j * omega[:, None] - lam0[None, :]), axis=1)
    rev = dist > SINGULAR_SEP * (np.abs(omega) + np.linalg.norm(system.A0, 2) + 1e-300)
    fwd = np.zeros_like(rev)
    if not rev.all():
        fwd[~rev] = np.linalg.cond(coefs[q][~rev]) <= COND_LIMIT
    out = np.empty((omega.size, q * system.n), dtype=complex)
    with np.errstate(divide="ignore", invalid="ignore"):
        if rev.any():
            mu = _companion_eigs([c[rev] for c in coefs], 0)
            out[rev] = np.where(mu == 0, np.inf, 1.0 / mu)
    if fwd.any():
        out[fwd] = _companion_eigs([c[fwd] for c in coefs], q)
    for i in np.flatnonzero(~rev & ~fwd):  # both ends singular: a generalized problem
        out[i] = _pencil_eigs([c[i] for c in coefs])
    return out


def _pencil_eigs(coefs: list[np.ndarray]) -> np.ndarray:
    q, n = len(coefs) - 1, coefs[0].shape[0]
    a = np.zeros((q * n, q * n), dtype=complex)
    b = np.eye(q * n, dtype=complex)
    a[:n, :] = np.concatenate([-coefs[i] for i in range(q - 1, -1, -1)], axis=1)
    b[:n, :n] = coefs[q]
    if q > 1:
        a[n:, : (q - 1) * n] = np.eye((q - 1) * n)
    z = scipy.linalg.eig(a, b, right=False)
    return np.where(np.isfinite(z), z, np.inf)


def _sphere(z: np.ndarray) -> np.ndarray:
    """Points of the Riemann sphere (matching distances that accept ``inf``)."""
    with np.errstate(invalid="ignore", over="ignore"):
        d = 1.0 + np.abs(z) ** 2
        p = np.stack([2 * z.real / d, 2 * z.imag / d, (np.abs(z) ** 2 - 1) / d], axis=-1)
    p[~np.isfinite(z)] = (0.0, 0.0, 1.0)
    return p


def _track(z: np.ndarray) -> np.ndarray:
    """Reorder the columns of each row to follow each eigenvalue along the grid."""
    out = z.copy()
    pts = _sphere(z)
    prev = pts[0]
    for k in range(1, z.shape[0]):
        cur = pts[k]
        cost = ((prev[:, None, :] - cur[None, :, :]) ** 2).sum(axis=-1)
        _, cols = linear_sum_assignment(cost)
        out[k] = z[k][cols]
        prev = cur[cols]
    return out


def _grid(system: DelaySystem, wmax: float, n_omega: int) -> np.ndarray:
    """Log-spaced and linear points up to ``wmax``, plus points around each mode of A0
    whose imaginary part lies in the range (resonances of lightly damped plants)."""
    lo = OMEGA_FLOOR_REL * wmax
    n_log = int(LOG_FRACTION * n_omega)
    parts = [np.geomspace(lo, wmax, n_log), np.linspace(lo, wmax, n_omega - n_log)]
    offsets = np.linspace(-MODE_HALF_WIDTH, MODE_HALF_WIDTH, MODE_POINTS)
    for lam in np.linalg.eigvals(system.A0):
        if lo < lam.imag < wmax and abs(lam.real) < LIGHT_DAMPING * lam.imag:
            width = max(abs(lam.real), 1e-6 * lam.imag)
            parts.append(lam.imag + width * offsets)
    grid = np.unique(np.concatenate(parts))
    return grid[(grid >= lo) & (grid <= wmax)]


def _nearest(system: DelaySystem, omega: float, target: complex) -> complex:
    z = unit_circle_eigenvalues(system, np.array([omega]))[0]
    return z[int(np.argmin(np.linalg.norm(_sphere(z) - _sphere(np.array([target])), axis=-1)))]


def _log_modulus(z: complex) -> float:
    """``log|z|``, bounded so that 0 and infinite eigenvalues keep the optimisers finite."""
    with np.errstate(divide="ignore"):
        return float(np.clip(np.log(abs(z)), -LOG_MODULUS_CAP, LOG_MODULUS_CAP))


def _newton_from_cell(system, wa, wb, za, zb):
    """The crossing in a cell by Newton's method on ``(omega, h)``, started from the
    linear interpolation of ``log|z|``; ``None`` when it leaves the cell (it found a
    neighbour's crossing) or does not converge: then Brent's method is used."""
    ga, gb = _log_modulus(za), _log_modulus(zb)
    t = ga / (ga - gb)
    w0 = wa + t * (wb - wa)
    z0 = za + t * (zb - za)
    phase = float((-np.angle(z0)) % (2 * np.pi)) or 2 * np.pi
    w, h, res = polish(system, w0, phase / w0)
    slack = CELL_SLACK * (wb - wa)
    if not (wa - slack <= w <= wb + slack) or res > NEWTON_RESIDUAL:
        return None
    z = np.exp(-1j * w * h)
    if abs(z - z0 / abs(z0)) > NEWTON_PHASE_JUMP:  # converged to another crossing
        return None
    return [(w, z)]


def _refine_sign_change(system, wa, wb, za, zb, xtol):
    def g(w):
        t = (w - wa) / (wb - wa)
        return _log_modulus(_nearest(system, w, za + t * (zb - za)))
    try:
        w = brentq(g, wa, wb, xtol=xtol * wb, rtol=max(xtol, 8.9e-16), maxiter=200)
    except ValueError:  # the matching switched eigenvalue inside the cell
        return []
    t = (w - wa) / (wb - wa)
    return [(w, _nearest(system, w, za + t * (zb - za)))]


def _refine_dip(system, wa, wm, wb, zm, xtol):
    """A minimum of ``|log|z||`` between grid points: one touch or two crossings."""
    def g(w):
        return _log_modulus(_nearest(system, w, zm))
    sign = np.sign(g(wm)) or 1.0
    res = minimize_scalar(lambda w: sign * g(w), bounds=(wa, wb), method="bounded",
                          options={"xatol": max(xtol, 1e-14) * wb})
    wmin, gmin = float(res.x), g(float(res.x))
    if sign * gmin > LOG_MODULUS_NOISE:
        return []
    if abs(gmin) <= LOG_MODULUS_NOISE:
        return [(wmin, _nearest(system, wmin, zm))]
    out = []
    for lo, hi in ((wa, wmin), (wmin, wb)):
        try:
            w = brentq(g, lo, hi, xtol=xtol * wb, rtol=max(xtol, 8.9e-16), maxiter=200)
        except ValueError:
            continue
        out.append((w, _nearest(system, w, zm)))
    return out


def _refined(system: DelaySystem, omega: np.ndarray, z: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Bisect the cells in which an eigenvalue could reach the unit circle: its distance
    to the circle (on the Riemann sphere) at an end is below :data:`REACH` times how far
    it moves across the cell. Near crossings the grid becomes fine enough that the
    point-to-point matching cannot swap two eigenvalues that cross close together."""
    for _ in range(REFINE_LEVELS):
        z = _track(z)
        pts = _sphere(z)
        move = np.linalg.norm(pts[1:] - pts[:-1], axis=-1)
        near = np.minimum(np.abs(pts[:-1, :, 2]), np.abs(pts[1:, :, 2]))  # 0 on the circle
        flag = np.any(near < REACH * move, axis=1)
        if not flag.any():
            break
        mid = 0.5 * (omega[:-1] + omega[1:])[flag]
        omega = np.concatenate([omega, mid])
        z = np.concatenate([z, unit_circle_eigenvalues(system, mid)])
        order = np.argsort(omega)
        omega, z = omega[order], z[order]
    return omega, _track(z)


def sweep_candidates(system: DelaySystem, *, n_omega: int = N_OMEGA, xtol: float = 1e-15,
                     newton: bool = False) -> tuple[list[tuple[float, complex]], SweepData]:
    """Frequencies ``omega > 0`` with a unit-modulus eigenvalue ``z``, by the sweep.

    Parameters
    ----------
    system : DelaySystem
    n_omega : int
        Number of grid frequencies (default :data:`N_OMEGA`).
    xtol : float
        Relative tolerance on ``omega`` of Brent's method (1e-15: to rounding).
    newton : bool
        Refine each sign change by Newton's method on ``(omega, h)`` started from the
        grid (:func:`~backlashkit.delay.crossings.polish`), falling back to Brent's
        method when it wanders off the cell; default False (Brent's method only, the
        sweep independent of the polish).

    Returns
    -------
    candidates : list of (float, complex)
        ``(omega, z)`` pairs, normalised to ``|z| = 1``.
    sweep : SweepData
        The grid and the matched eigenvalues (for plots).
    """
    omega = _grid(system, frequency_bound(system), n_omega)
    omega, z = _refined(system, omega, unit_circle_eigenvalues(system, omega))
    with np.errstate(divide="ignore"):
        g = np.log(np.abs(z))
    sgn = np.where(np.abs(g) > LOG_MODULUS_NOISE, np.sign(g), 0.0)
    cands: list[tuple[float, complex]] = []
    for i in range(z.shape[1]):
        cands += _scan_column(system, omega, z[:, i], g[:, i], sgn[:, i], xtol, newton)
    return [(w, zz / abs(zz)) for w, zz in cands], SweepData(omega, z)


def _scan_column(system, omega, z, g, sgn, xtol, newton) -> list[tuple[float, complex]]:
    out: list[tuple[float, complex]] = []
    signed = np.flatnonzero(sgn != 0)
    # sign changes between consecutive signed points (unsigned points in between are
    # within noise of the circle); a leading unsigned run is the omega -> 0 limit
    a_idx, b_idx = signed[:-1], signed[1:]
    for a, b in zip(a_idx, b_idx, strict=True):
        if sgn[a] != sgn[b]:
            found = _newton_from_cell(system, omega[a], omega[b], z[a], z[b]) if newton else None
            out += found or _refine_sign_change(system, omega[a], omega[b], z[a], z[b], xtol)
        elif b > a + 1:  # equal signs around a run of unsigned points: a touch
            k = a + 1 + int(np.argmin(np.abs(g[a + 1:b])))
            out += _refine_dip(system, omega[a], omega[k], omega[b], z[k], xtol)
    y = np.abs(g)
    mid = slice(1, len(omega) - 1)
    same = (sgn[mid] != 0) & (sgn[:-2] == sgn[mid]) & (sgn[2:] == sgn[mid])
    finite = np.isfinite(y[:-2]) & np.isfinite(y[mid]) & np.isfinite(y[2:])
    local_min = same & finite & (y[mid] <= y[:-2]) & (y[mid] <= y[2:])
    for k in np.flatnonzero(local_min) + 1:
        if _parabola_dips(omega[k - 1:k + 2], y[k - 1:k + 2]):
            out += _refine_dip(system, omega[k - 1], omega[k], omega[k + 1], z[k], xtol)
    return out


def _parabola_dips(w: np.ndarray, y: np.ndarray) -> bool:
    """Whether the parabola through three points may dip near zero between them."""
    h1, h2 = w[0] - w[1], w[2] - w[1]
    d1, d2 = (y[0] - y[1]) / h1, (y[2] - y[1]) / h2
    curv = (d2 - d1) / (h2 - h1)  # y ~ y1 + b x + curv x^2
    if curv <= 0:
        return False
    b = d1 - curv * h1
    vertex = y[1] - b * b / (4 * curv)
    return vertex < DIP_FRACTION * y[1]
