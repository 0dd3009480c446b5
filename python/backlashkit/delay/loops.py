"""Delay systems of the toolkit's control loops, with the delay where the controller's
output enters the plant (a computation, communication or PWM delay).

The plant ``xp' = Ap xp + Bp u``, ``y = Cp xp`` (strictly proper) receives
``u(t) = u_c(t - h)``; the controller ``xc' = Ac xc + Bc e``, ``u_c = Cc xc + Dc e``,
``e = sign * y`` (``sign = -1``: negative feedback), sees the undelayed measurement
and its own undelayed output. The closed loop is ``x' = A0 x + A1 x(t - h)`` with
``x = (xp, xc)``; its characteristic equation is ``1 + L(s) exp(-s h) = 0`` with
``L = -sign C(s) G(s)``, the loop broken at the delay. The SISO margin
``min_i PM_i / omega_i`` over the gain crossovers of ``L`` is the same number
(when the loop is stable at ``h = 0``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..control.design import MRCDesign, companion
from ..errors import InputError
from .system import DelaySystem

__all__ = ["input_delay_loop", "mrc_controller", "mrc_delay_margin", "mrc_delay_system",
           "pi_controller", "siso_delay_margin", "two_mass_contact"]

StateSpace = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _ss(value: Any, name: str) -> StateSpace:
    try:
        a, b, c, d = (np.atleast_2d(np.asarray(m, dtype=float)) for m in value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a tuple (A, B, C, D) of real matrices") from None
    n = a.shape[0]
    if a.shape != (n, n) or b.shape[0] != n or c.shape[1] != n or d.shape != (c.shape[0],
                                                                               b.shape[1]):
        raise InputError(f"{name}: shapes A {a.shape}, B {b.shape}, C {c.shape}, D {d.shape} "
                         f"do not form a state-space model")
    return a, b, c, d


def input_delay_loop(plant: Any, controller: Any, *, sign: float = -1.0) -> DelaySystem:
    """The closed loop with the delay at the plant input, as a :class:`DelaySystem`.

    Parameters
    ----------
    plant : tuple (A, B, C, D)
        Strictly proper plant (``D = 0``); time in s.
    controller : tuple (A, B, C, D)
        Controller from ``e`` to ``u_c`` (``A`` may be 0x0 for a static gain).
    sign : float
        ``e = sign * y`` (default -1, negative feedback).

    Returns
    -------
    DelaySystem
        ``x' = A0 x + A1 x(t - h)``, ``x = (plant states, controller states)``.
    """
    ap, bp, cp, dp = _ss(plant, "plant")
    ac, bc, cc, dc = _ss(controller, "controller") if np.size(controller[0]) else (
        np.zeros((0, 0)), np.zeros((0, cp.shape[0])), np.zeros((bp.shape[1], 0)),
        np.atleast_2d(np.asarray(controller[3], dtype=float)))
    if np.any(dp):
        raise InputError("plant must be strictly proper (D = 0): a direct feed-through "
                         "behind the delay makes the loop a neutral difference equation")
    if dc.shape != (bp.shape[1], cp.shape[0]):
        raise InputError(f"controller D has shape {dc.shape}; it must be (plant inputs, plant "
                         f"outputs) = {(bp.shape[1], cp.shape[0])}")
    npl, nc = ap.shape[0], ac.shape[0]
    a0 = np.zeros((npl + nc, npl + nc))
    a1 = np.zeros_like(a0)
    a0[:npl, :npl] = ap
    a0[npl:, :npl] = sign * bc @ cp
    a0[npl:, npl:] = ac
    a1[:npl, :npl] = sign * bp @ dc @ cp
    a1[:npl, npl:] = bp @ cc
    return DelaySystem(a0, [a1])


def mrc_controller(design: MRCDesign, *, gain: float = 1.0) -> StateSpace:
    """Paper B's linear controller (3.2) from ``y`` to ``u_d`` (``r = 0``), with the loop
    gain ``gain`` between ``u_d`` and the plant input.

    The filters ``a(s)/Lambda(s)`` see the controller's own output ``u_d`` (undelayed)
    and the measured ``y``. ``gain`` is the linear gain of the backlash and its inverse in
    the moving regime, ``m / m_hat``: 1 with the true parameters ``theta_b*``, and
    ``0.7 / 0.2 = 3.5`` with paper B's initial estimates ``theta_b(0)``; the inverse's
    offsets add a constant input, which does not change stability.

    Parameters
    ----------
    design : MRCDesign
        From :func:`backlashkit.control.design_mrc`.
    gain : float
        Gain from ``u_d`` to the plant input.

    Returns
    -------
    tuple (A, B, C, D)
        ``e = y`` (use ``sign = +1``): ``u = gain * (theta_1' w1 + theta_2' w2)``.
    """
    af, bf, _ = companion(np.array([1.0]), design.filter)
    n = af.shape[0]
    t1, t2 = np.asarray(design.theta_1, float), np.asarray(design.theta_2, float)
    a = np.zeros((2 * n, 2 * n))
    a[:n, :n] = af + np.outer(bf, t1)
    a[:n, n:] = np.outer(bf, t2)
    a[n:, n:] = af
    b = np.concatenate([np.zeros(n), bf])[:, None]
    c = gain * np.concatenate([t1, t2])[None, :]
    return a, b, c, np.zeros((1, 1))


def mrc_delay_system(design: MRCDesign, *, gain: float = 1.0
                     ) -> tuple[StateSpace, StateSpace, DelaySystem]:
    """Paper B's linear model-reference loop (no backlash) with the delay at the plant
    input: plant ``k_p Z/R`` in controllable form, :func:`mrc_controller`, and the
    closed loop.

    Parameters
    ----------
    design : MRCDesign
        From :func:`backlashkit.control.design_mrc`.
    gain : float
        Gain from ``u_d`` to the plant input (``m / m_hat``; 1 for the linear loop).

    Returns
    -------
    plant : tuple (A, B, C, D)
        The plant.
    controller : tuple (A, B, C, D)
        The controller, from ``y`` to ``u`` (``sign = +1``).
    system : DelaySystem
        The closed loop, ``x = (plant states, w1, w2)``.
    """
    a, b, c = companion(design.k_p * np.asarray(design.zeros_poly, float), design.poles_poly)
    plant = (a, b[:, None], c[None, :], np.zeros((1, 1)))
    ctrl = mrc_controller(design, gain=gain)
    return plant, ctrl, input_delay_loop(plant, ctrl, sign=+1.0)


def mrc_delay_margin(design: MRCDesign, *, gain: float = 1.0, verify: bool = True):
    """Delay margin of paper B's linear model-reference loop, delay at the plant input
    (what ``backlashkit control`` reports).

    Parameters
    ----------
    design : MRCDesign
        From :func:`backlashkit.control.design_mrc`.
    gain : float
        Gain from ``u_d`` to the plant input (1: the linear loop without backlash).
    verify : bool
        Spectral check of the answer (see :func:`~backlashkit.delay.delay_margin`).

    Returns
    -------
    DelayMarginResult
        ``h_max`` in s.
    """
    from .margin import margin_of_system

    return margin_of_system(mrc_delay_system(design, gain=gain)[2], verify=verify)


def pi_controller(kp: float, ki: float) -> StateSpace:
    """PI controller ``u_c = kp e + ki int e`` as a state-space model.

    Parameters
    ----------
    kp : float
        Proportional gain (input units per error unit).
    ki : float
        Integral gain (per s).

    Returns
    -------
    tuple (A, B, C, D)
        One state, the integral of ``e``.
    """
    return (np.zeros((1, 1)), np.ones((1, 1)), np.array([[float(ki)]]),
            np.array([[float(kp)]]))


def two_mass_contact(drive: Any) -> StateSpace:
    """A two-mass drive in contact, linearised, from motor torque to motor speed.

    In contact the backlash offset ``theta`` is a constant that drops out; the states are
    ``(w_M, w_L, phi_d -+ theta)``; viscous friction only (Coulomb friction is not
    linear and is ignored).

    Parameters
    ----------
    drive : TwoMassDrive
        The drive (SI units).

    Returns
    -------
    tuple (A, B, C, D)
        Input motor torque (N m), output motor speed (rad/s).
    """
    jm, jl, k = drive.J_M, drive.J_L, drive.k_sh
    fm, fl, fsh = drive.f_M, drive.f_L, drive.f_sh
    a = np.array([[-(fm + fsh) / jm, fsh / jm, -k / jm],
                  [fsh / jl, -(fl + fsh) / jl, k / jl],
                  [1.0, -1.0, 0.0]])
    b = np.array([[1.0 / jm], [0.0], [0.0]])
    c = np.array([[1.0, 0.0, 0.0]])
    return a, b, c, np.zeros((1, 1))


def siso_delay_margin(plant: Any, controller: Any, *, sign: float = -1.0
                      ) -> tuple[float, list[tuple[float, float]]]:
    """``min_i PM_i / omega_i`` over every gain crossover of ``L = -sign C G``, by
    python-control (the classical SISO check).

    Parameters
    ----------
    plant : tuple (A, B, C, D)
        SISO plant.
    controller : tuple (A, B, C, D)
        SISO controller.
    sign : float
        As in :func:`input_delay_loop`.

    Returns
    -------
    margin : float
        s; ``inf`` without a gain crossover.
    crossovers : list of (float, float)
        ``(omega_i, PM_i)`` in rad/s and degrees.
    """
    import control

    g = control.ss(*plant)
    k = control.ss(*controller) if np.size(controller[0]) else control.ss([], [], [],
                                                                         controller[3])
    loop = -sign * control.series(k, g)
    _, pm, _, _, wgc, _ = control.stability_margins(loop, returnall=True)
    pairs = [(float(w), float(p)) for w, p in zip(np.atleast_1d(wgc), np.atleast_1d(pm),
                                                    strict=True) if w > 0]
    if not pairs:
        return float("inf"), []
    return min(np.deg2rad(p % 360.0) / w for w, p in pairs), pairs
