"""Imaginary-axis crossings ``s = j omega`` at delay ``h``: polish, direction, windows.

Both methods (:mod:`.chen` and :mod:`.kronecker`) produce candidate pairs
``(omega, z)`` with ``|z| = 1`` and ``det T(j omega, h) = 0`` for ``exp(-j omega h) =
z``. This module turns them into crossings: it polishes ``(omega, h)`` by Newton's
method on ``det T(j omega, h) = 0``, computes the null vectors and the direction in
which the root moves as ``h`` grows, and counts right half-plane roots along ``h``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .system import DelaySystem

__all__ = ["Crossing", "crossing_from_candidate", "direction", "merge_candidates",
           "polish", "unstable_count_changes"]

#: Newton on (omega, h) stops when the relative step is below this.
POLISH_STEP_TOL = 1e-15
POLISH_MAX_ITER = 30
#: ``|Re ds/dh|`` below this times ``|ds/dh|`` is a tangential touch (no count change):
#: a touch is located only to about the square root of the rounding error.
TOUCH_TOL = 1e-5
#: Two candidates closer than this (relative, in omega and in the phase) are one crossing.
MERGE_TOL = 1e-7


@dataclass(frozen=True, eq=False)
class Crossing:
    """A root ``s = j omega`` of the characteristic equation at the delays ``h0 + k T``.

    Parameters
    ----------
    omega : float
        Crossing frequency (rad/s), > 0.
    phase : float
        ``omega h0`` in (0, 2 pi] (rad); the crossings are at ``h = (phase + 2 pi k) /
        omega``, ``k = 0, 1, ...``.
    residual : float
        ``sigma_min(T) / (omega ||N|| + ||M||)`` at the polished ``(j omega, h0)``.
    vector : numpy.ndarray
        Unit right null vector of ``T(j omega, h0)``.
    """

    omega: float
    phase: float
    residual: float
    vector: np.ndarray

    @property
    def h0(self) -> float:
        """The smallest delay of this crossing (s)."""
        return self.phase / self.omega

    def delays(self, h_hi: float) -> np.ndarray:
        """The delays ``h0 + 2 pi k / omega <= h_hi`` (s).

        Parameters
        ----------
        h_hi : float
            Upper end (s).

        Returns
        -------
        numpy.ndarray
            Increasing delays (s).
        """
        if not math.isfinite(h_hi):
            raise ValueError("h_hi must be finite")
        kmax = math.floor((h_hi * self.omega - self.phase) / (2 * math.pi))
        return (self.phase + 2 * math.pi * np.arange(max(kmax + 1, 0))) / self.omega


def _derivatives(system: DelaySystem, s: complex, h: float):
    """``T``, ``dT/ds`` and ``dT/dh`` at ``(s, h)``."""
    z = np.exp(-s * h)
    t = s * system.N(z) - system.M(z)
    ts = system.N(z).copy()
    th = np.zeros_like(ts)
    for k, (a, b) in enumerate(zip(system.A, system.B, strict=True), start=1):
        term = k * z**k * (s * b + a)
        ts = ts + h * term
        th = th + s * term
    return t, ts, th


def polish(system: DelaySystem, omega: float, h: float) -> tuple[float, float, float]:
    """Newton's method on ``det T(j omega, h) = 0`` in the two real unknowns.

    The complex equation is linearised through the log-derivative
    ``d log det T = tr(T^-1 dT)``, which stays well scaled as ``T`` becomes singular.

    Parameters
    ----------
    system : DelaySystem
    omega : float
        Start frequency (rad/s).
    h : float
        Start delay (s).

    Returns
    -------
    omega, h : float
        Polished values (the start values when Newton does not converge).
    residual : float
        ``sigma_min(T) / (omega ||N|| + ||M||)`` at the returned point.
    """
    w, hh = float(omega), float(h)
    last = math.inf
    for _ in range(POLISH_MAX_ITER):
        t, ts, th = _derivatives(system, 1j * w, hh)
        try:
            a = np.trace(np.linalg.solve(t, 1j * ts))
            b = np.trace(np.linalg.solve(t, th))
            dw, dh = np.linalg.solve(np.array([[a.real, b.real], [a.imag, b.imag]]),
                                     [-1.0, 0.0])
        except np.linalg.LinAlgError:  # exactly singular: already at the root
            break
        size = math.hypot(dw / w, dh / hh)
        if not np.isfinite(size) or size > 0.5 * last:  # rounding noise, not convergence
            break
        w, hh, last = w + dw, hh + dh, size
        if size <= POLISH_STEP_TOL:
            break
    return w, hh, _residual(system, w, hh)


def _residual(system: DelaySystem, omega: float, h: float) -> float:
    """``sigma_min(T) / (omega ||N(z)|| + ||M(z)||)``: relative to the size of the terms
    (``||T||`` itself would make every 1x1 residual equal to 1)."""
    z = np.exp(-1j * omega * h)
    sv = np.linalg.svd(system.characteristic_matrix(1j * omega, h), compute_uv=False)
    size = abs(omega) * np.linalg.norm(system.N(z), 2) + np.linalg.norm(system.M(z), 2)
    return float(sv[-1] / max(size, 1e-300))


def null_vectors(system: DelaySystem, omega: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit right and left null vectors of ``T(j omega, h)`` (smallest singular value).

    Parameters
    ----------
    system : DelaySystem
    omega : float
        Frequency (rad/s).
    h : float
        Delay (s).

    Returns
    -------
    v, w : numpy.ndarray
        ``T v ~ 0`` and ``w^H T ~ 0``; ``v`` scaled so that its largest entry is real.
    """
    u, _, vh = np.linalg.svd(system.characteristic_matrix(1j * omega, h))
    v, w = vh[-1].conj(), u[:, -1]
    k = int(np.argmax(np.abs(v)))
    rot = abs(v[k]) / v[k]
    return v * rot, w


def direction(system: DelaySystem, omega: float, h: float) -> complex:
    """``ds/dh`` of the root at ``s = j omega`` (1/s^2), by implicit differentiation.

    Parameters
    ----------
    system : DelaySystem
    omega : float
        Frequency (rad/s).
    h : float
        Delay (s) at which ``j omega`` is a root.

    Returns
    -------
    complex
        Its real part is positive when the root moves into the right half-plane as
        ``h`` grows.
    """
    v, w = null_vectors(system, omega, h)
    _, ts, th = _derivatives(system, 1j * omega, h)
    den = w.conj() @ ts @ v
    return complex(-(w.conj() @ th @ v) / den) if den != 0 else complex("nan")


def crossing_from_candidate(system: DelaySystem, omega: float, z: complex, *,
                            polish_root: bool = True) -> Crossing:
    """A :class:`Crossing` from ``(omega, z)`` with ``exp(-j omega h0) = z``.

    Parameters
    ----------
    system : DelaySystem
    omega : float
        Frequency (rad/s), > 0.
    z : complex
        Unit-modulus generalized eigenvalue.
    polish_root : bool
        Polish ``(omega, h0)`` by :func:`polish` (default True).

    Returns
    -------
    Crossing
        With ``h0 = phase / omega`` and the null vector there.
    """
    phase = float((-np.angle(z)) % (2 * math.pi))
    if phase == 0.0:  # z = 1 is a root at h = 0 only if the system is unstable there
        phase = 2 * math.pi
    h0 = phase / omega
    if polish_root:
        omega, h0, res = polish(system, omega, h0)
        phase = omega * h0
        phase = phase - 2 * math.pi * math.floor((phase - 1e-12) / (2 * math.pi))
    else:
        res = _residual(system, omega, h0)
    v, _ = null_vectors(system, omega, phase / omega)
    return Crossing(omega=float(omega), phase=float(phase), residual=res, vector=v)


def merge_candidates(crossings: list[Crossing]) -> list[Crossing]:
    """Drop duplicates: crossings with the same frequency and phase to :data:`MERGE_TOL`.

    Parameters
    ----------
    crossings : list of Crossing

    Returns
    -------
    list of Crossing
        Sorted by ``h0``; of each group the one with the smallest residual.
    """
    out: list[Crossing] = []
    for c in sorted(crossings, key=lambda c: c.residual):
        same = [o for o in out if abs(o.omega - c.omega) <= MERGE_TOL * max(o.omega, 1e-300)
                and abs(math.remainder(o.phase - c.phase, 2 * math.pi)) <= MERGE_TOL * 2 * math.pi]
        if not same:
            out.append(c)
    return sorted(out, key=lambda c: c.h0)


def unstable_count_changes(system: DelaySystem, crossings: list[Crossing],
                           h_hi: float) -> list[tuple[float, int]]:
    """Every crossing delay up to ``h_hi`` with the change in the number of roots in the
    open right half-plane (``+2``, ``-2``, or 0 for a tangential touch; a conjugate pair).

    Parameters
    ----------
    system : DelaySystem
    crossings : list of Crossing
    h_hi : float
        Upper end of the delay range (s).

    Returns
    -------
    list of (float, int)
        Sorted by delay.
    """
    events = []
    for c in crossings:
        for h in c.delays(h_hi):
            d = direction(system, c.omega, float(h))
            if not np.isfinite(d.real) or abs(d.real) <= TOUCH_TOL * abs(d):
                change = 0
            else:
                change = 2 if d.real > 0 else -2
            events.append((float(h), change))
    return sorted(events)
