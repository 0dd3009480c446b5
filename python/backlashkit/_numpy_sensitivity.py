"""Forward sensitivities of a two-mass drive with backlash, in plain NumPy (issue 24).

The reference for the compiled sensitivities to come: the derivatives of the speeds
with respect to the parameters ``J_M, J_L, k_sh, f_M, f_L, f_sh, theta`` of a drive
without Coulomb friction or current loop, under paper A's contact law, from rest. Not
yet used by the estimators, which still difference simulations.

Inside a mode the drive is linear, ``dx/dt = A x + b u + c``, and so are its
sensitivities ``S = dx/dp``: ``dS_j/dt = A S_j + dA/dp_j x + db/dp_j u + dc/dp_j``. The
state and the seven sensitivities together follow one linear system, whose flow over a
sample of held torque is exact (a matrix exponential, as the simulator's own). The
derivatives of ``A``, ``b`` and ``c`` are taken by complex step, exact to rounding.

At a contact change at time ``tau`` the guard ``g = phi - s theta`` crosses 0 (``s``
the flank). The change moves with the parameters, ``dtau/dp = -(dg/dx S + dg/dp) /
(dg/dx f_-)``, and the sensitivities jump by the saltation ``S_+ = S_- + (f_- - f_+)
dtau/dp``, ``f_-`` and ``f_+`` the vector fields before and after. Where the shaft
grazes a flank (``dphi/dt = 0`` at the change) the derivative does not exist, and the
jump grows without bound near it.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from .plants import TwoMassDrive

#: The parameters, in the order of the sensitivities' last axis.
PARAMS = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh", "theta")
#: Complex step of the derivatives of the mode matrices (exact for h far below 1).
COMPLEX_STEP = 1e-30
N_STATES, N_PARAMS = 3, len(PARAMS)


def mode_system(p, flank: int):
    """``(A, b, c)`` of a mode: the gap (``flank`` 0) or a flank (+-1), for parameters
    ``p`` (order :data:`PARAMS`; real or complex)."""
    j_m, j_l, k, f_m, f_l, d, theta = p
    dtype = np.result_type(*p, float)
    a = np.zeros((N_STATES, N_STATES), dtype)
    c = np.zeros(N_STATES, dtype)
    a[0, 0], a[1, 1] = -f_m / j_m, -f_l / j_l
    a[2, 0], a[2, 1] = 1.0, -1.0
    if flank:  # shaft torque k (phi - s theta) + d (w_M - w_L)
        a[0] += np.array([-d, d, -k]) / j_m
        a[1] += np.array([d, -d, k]) / j_l
        c[0], c[1] = k * flank * theta / j_m, -k * flank * theta / j_l
    b = np.array([1.0 / j_m, 0.0, 0.0], dtype)
    return a, b, c


def augmented_flow(p: np.ndarray, flank: int, tau: float):
    """``(Phi, Gamma)``: ``z(tau) = Phi z(0) + Gamma [u, 1]`` for ``z = [x, S_1 .. S_7]``
    in a mode under a held torque ``u``."""
    a, b, c = mode_system(p, flank)
    n, m = N_STATES, N_STATES * (1 + N_PARAMS)
    big = np.zeros((m + 2, m + 2))
    for blk in range(1 + N_PARAMS):
        big[blk * n:(blk + 1) * n, blk * n:(blk + 1) * n] = a
    big[:n, m], big[:n, m + 1] = b, c
    for j in range(N_PARAMS):
        pj = p.astype(complex)
        pj[j] += 1j * COMPLEX_STEP
        da, db, dc = (x.imag / COMPLEX_STEP for x in mode_system(pj, flank))
        rows = slice((1 + j) * n, (2 + j) * n)
        big[rows, :n] = da
        big[rows, m], big[rows, m + 1] = db, dc
    e = expm(big * tau)
    return e[:m, :m], e[:m, m:]


def field(p: np.ndarray, flank: int, x: np.ndarray, u: float) -> np.ndarray:
    """The vector field ``A x + b u + c`` of a mode."""
    a, b, c = mode_system(p, flank)
    return a @ x + b * u + c


def sensitivities(drive: TwoMassDrive, t: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """Derivatives of ``(w_M, w_L)`` at ``t`` with respect to :data:`PARAMS`, from rest.

    Parameters
    ----------
    drive : TwoMassDrive
        Without Coulomb friction (``fc_M = fc_L = 0``), ``theta > 0``.
    t, torque : numpy.ndarray
        Uniform time grid in s and the torque in N m held over each sample.

    Returns
    -------
    numpy.ndarray
        ``(len(t), 2, 7)``: ``d w / d p`` in the parameters' SI units.
    """
    p = np.array([getattr(drive, n) for n in PARAMS], float)
    ts = float(t[1] - t[0])
    res = drive.simulate(t, torque)
    changes = [(e.time, 0 if e.kind == "contact_lost" else (1 if e.flank == "positive" else -1),
                1 if e.flank == "positive" else -1) for e in res.contact_events]
    z = np.zeros(N_STATES * (1 + N_PARAMS))
    flank, i_ev, full = 0, 0, {}
    out = np.empty((t.size, 2, N_PARAMS))
    for k in range(t.size):
        out[k] = z[N_STATES:].reshape(N_PARAMS, N_STATES)[:, :2].T
        if k == t.size - 1:
            break
        t_now, u = float(t[k]), float(torque[k])
        while i_ev < len(changes) and changes[i_ev][0] <= t[k + 1]:
            t_ev, to, s = changes[i_ev]
            z = _advance(p, flank, z, u, t_ev - t_now)
            z = saltation(p, z, u, flank, to, s)
            flank, t_now, i_ev = to, t_ev, i_ev + 1
        if t_now == t[k]:  # a whole sample in one mode: its flow is cached
            if flank not in full:
                full[flank] = augmented_flow(p, flank, ts)
            phi, gam = full[flank]
            z = phi @ z + gam @ np.array([u, 1.0])
        else:
            z = _advance(p, flank, z, u, float(t[k + 1]) - t_now)
    return out


def _advance(p, flank, z, u, tau):
    if tau <= 0.0:
        return z
    phi, gam = augmented_flow(p, flank, tau)
    return phi @ z + gam @ np.array([u, 1.0])


def saltation(p: np.ndarray, z: np.ndarray, u: float, before: int, after: int, s: int
              ) -> np.ndarray:
    """``z`` after a contact change from mode ``before`` to ``after`` at the flank
    ``s``: the sensitivities jump by ``(f_- - f_+) dtau/dp``."""
    x = z[:N_STATES]
    sens = z[N_STATES:].reshape(N_PARAMS, N_STATES).T  # (state, parameter)
    f_minus, f_plus = field(p, before, x, u), field(p, after, x, u)
    dg_dp = np.zeros(N_PARAMS)
    dg_dp[PARAMS.index("theta")] = -s  # g = phi - s theta
    dtau = -(sens[2] + dg_dp) / f_minus[2]
    sens = sens + np.outer(f_minus - f_plus, dtau)
    return np.concatenate([x, sens.T.ravel()])
