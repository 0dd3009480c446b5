"""Adaptive law (3.11) of paper B: configuration and its right-hand side.

``dtheta_b/dt = -Gamma zeta (e + xi) / z + f_b`` with ``theta_b = (mc_r, m, mc_l)``
estimates, ``omega_b = (chi_r, -v, chi_l)``, ``zeta = H[omega_b]``,
``xi = theta_b' zeta - H[theta_b' omega_b]``, ``z = 1 + zeta' zeta + xi^2``, a
projection keeping ``m_hat >= m_0``, ``(mc_r)_hat >= 0``, ``(mc_l)_hat <= 0`` (A3),
and ``f_b`` the *switching* sigma-modification of Ioannou & Sun (paper B's ref. [6]):

    f_b = -sigma_s Gamma theta_b,
    sigma_s = 0                          if |theta_b| <= M_0,
            = sigma (|theta_b|/M_0 - 1)  if M_0 < |theta_b| <= 2 M_0,
            = sigma                      otherwise,

which leaves the ideal behaviour untouched while the estimates stay in the ball
``|theta_b| <= M_0`` (choose ``M_0`` above the largest plausible ``|theta_b*|``) and
keeps every signal bounded under bounded disturbances. ``Gamma`` is diagonal, so the
projection (zeroing an outward component on the boundary) is the exact orthogonal
projection in the ``Gamma^{-1}`` metric.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .. import validate as v
from ..errors import InputError

__all__ = ["AdaptiveLaw", "adaptive_rate"]


@dataclass(frozen=True)
class AdaptiveLaw:
    """Parameters of the adaptive law (3.11).

    Parameters
    ----------
    gamma : float or sequence of 3 floats
        Adaptation gain ``Gamma`` (diagonal, ``> 0``); paper B's example uses ``5 I``.
    theta_b0 : sequence of 3 floats
        Initial estimate ``(mc_r, m, mc_l)(0)``; needs ``m > 0``, ``mc_r >= 0``,
        ``mc_l <= 0``. Paper B: ``(1.51, 0.2, -0.55)``.
    m0 : float, optional
        Known lower bound ``m_0 > 0`` of the slope (A3). Default ``0.1 * theta_b0[1]``.
    sigma : float
        Switching sigma-modification gain ``>= 0`` (0 disables it). Default 0.1.
    sigma_bound : float, optional
        ``M_0`` of the switching sigma-modification, ``> 0``. Default
        ``10 * max(1, |theta_b0|)``.
    """

    gamma: float | Sequence[float] = 5.0
    theta_b0: Sequence[float] = (1.51, 0.2, -0.55)
    m0: float | None = None
    sigma: float = 0.1
    sigma_bound: float | None = None
    _gamma: np.ndarray = field(init=False, repr=False, compare=False)
    _theta_b0: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("gamma", "theta_b0"):
            v.real_numbers(name, getattr(self, name))
        g = np.atleast_1d(v.finite_array("gamma", np.atleast_1d(np.asarray(self.gamma, float))))
        if g.size == 1:
            g = np.repeat(g, 3)
        if g.size != 3:
            raise InputError(
                f"gamma must be a scalar or 3 values (a diagonal), got {g.size} values"
            )
        if not (g >= 0).all() or not (g > 0).any():
            raise InputError(f"gamma must be > 0, got {[float(x) for x in g]!r}")
        th = v.finite_array("theta_b0", self.theta_b0)
        if th.size != 3:
            raise InputError(f"theta_b0 must have 3 values (mc_r, m, mc_l), got {th.size}")
        if not th[1] > 0:
            raise InputError(f"theta_b0[1] (initial m_hat) must be > 0, got {float(th[1])!r}")
        if th[0] < 0 or th[2] > 0:
            raise InputError(
                "theta_b0 must satisfy A3: mc_r >= 0 and mc_l <= 0, got "
                f"mc_r={float(th[0])!r}, mc_l={float(th[2])!r}"
            )
        m0 = 0.1 * th[1] if self.m0 is None else v.positive("m0", self.m0)
        if m0 > th[1]:
            raise InputError(f"m0 must be <= theta_b0[1] = {float(th[1])!r} (A3), got {m0!r}")
        sb = (
            10.0 * max(1.0, float(np.linalg.norm(th)))
            if self.sigma_bound is None
            else (v.positive("sigma_bound", self.sigma_bound))
        )
        object.__setattr__(self, "m0", float(m0))
        object.__setattr__(self, "sigma", v.nonnegative("sigma", self.sigma))
        object.__setattr__(self, "sigma_bound", float(sb))
        object.__setattr__(self, "_gamma", g)
        object.__setattr__(self, "_theta_b0", th)

    @property
    def gamma_diag(self) -> np.ndarray:
        """Diagonal of ``Gamma`` (3 values)."""
        return self._gamma.copy()

    @property
    def theta_b0_array(self) -> np.ndarray:
        """Initial estimate as an array."""
        return self._theta_b0.copy()

    def as_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``gamma``, ``theta_b0``, ``m0``, ``sigma``, ``sigma_bound``.
        """
        return {
            "gamma": [float(x) for x in self._gamma],
            "theta_b0": [float(x) for x in self._theta_b0],
            "m0": self.m0,
            "sigma": self.sigma,
            "sigma_bound": self.sigma_bound,
        }


def adaptive_rate(
    law: AdaptiveLaw,
    theta_b: np.ndarray,
    zeta: np.ndarray,
    h_theta_omega: float,
    e: float,
    *,
    gamma: np.ndarray | None = None,
) -> np.ndarray:
    """Right-hand side of (3.11) with projection and switching sigma-modification.

    Parameters
    ----------
    law : AdaptiveLaw
        Gains and bounds.
    theta_b : numpy.ndarray, shape (3,)
        Current estimate ``(mc_r, m, mc_l)``.
    zeta : numpy.ndarray, shape (3,)
        ``H[omega_b]``.
    h_theta_omega : float
        ``H[theta_b' omega_b]``.
    e : float
        Tracking error ``y - y_m``.
    gamma : numpy.ndarray, optional
        Diagonal of ``Gamma`` overriding ``law.gamma`` (used for the gain-only variant).

    Returns
    -------
    numpy.ndarray, shape (3,)
        ``dtheta_b/dt``.
    """
    g = law.gamma_diag if gamma is None else gamma
    xi = float(theta_b @ zeta) - h_theta_omega
    nz = 1.0 + float(zeta @ zeta) + xi * xi
    d = -g * zeta * (e + xi) / nz
    if law.sigma > 0:
        nrm = float(np.sqrt(theta_b @ theta_b))
        m0b = law.sigma_bound
        ss = (
            0.0 if nrm <= m0b else (law.sigma * (nrm / m0b - 1.0) if nrm <= 2 * m0b else law.sigma)
        )
        d = d - ss * g * theta_b
    if theta_b[1] <= law.m0 and d[1] < 0:
        d[1] = 0.0
    if theta_b[0] <= 0 and d[0] < 0:
        d[0] = 0.0
    if theta_b[2] >= 0 and d[2] > 0:
        d[2] = 0.0
    return d
