"""Forward sensitivities of a two-mass drive with backlash, in plain NumPy (issue 24).

The reference for the compiled sensitivities (:mod:`backlashkit._sensitivity`, which
takes the same conventions): the derivatives of the speeds with respect to the
parameters :data:`PARAMS` (``J_M, J_L, k_sh, f_M, f_L, f_sh, theta``, the Coulomb
torques ``fc_M, fc_L`` and the current loop's time constant ``tau_i``) of a drive under
paper A's contact law, with Coulomb friction whose breakaway torque is the Coulomb
torque (``fs = fc``: the two are one parameter), with or without a first-order current
loop. Not used by the estimators.

The state is ``x = [w_M, w_L, phi]``, or with a current loop (``tau_i > 0``) ``[w_M,
w_L, phi, T]``: the motor torque ``T`` follows the set-point ``u`` by ``tau_i dT/dt = u
- T`` and acts on the motor in place of ``u``. With ``motor_angle`` the motor's angle
``phi_M`` (``dphi_M/dt = w_M``) is one more state, last: its sensitivity is the motor
speed's integral, and no change makes it jump (the speeds are continuous).

A mode is the shaft's contact (gap, or flank ``s = +-1``) and, for each inertia with
``fc > 0``, its friction switch: slipping forwards or backwards (``+1`` / ``-1``, a
Coulomb torque ``-+fc`` on it) or stuck (``0``, its speed row of the dynamics zero).
Inside a mode the drive is linear, ``dx/dt = A x + b u + c``, and so are its
sensitivities ``S = dx/dp``: ``dS_j/dt = A S_j + dA/dp_j x + db/dp_j u + dc/dp_j``. The
state and the sensitivities together follow one linear system, whose flow over a
sample of held torque is exact (a matrix exponential, as the simulator's own). The
derivatives of ``A``, ``b`` and ``c`` are taken by complex step, exact to rounding.

The run walks the simulator's changes in time order. At a change at time ``tau`` a
guard ``g`` crosses 0, the change moves with the parameters, ``dtau/dp = -(dg/dx S +
dg/dp) / (dg/dx f_-)``, and the sensitivities jump by the saltation ``S_+ = S_- + (f_-
- f_+) dtau/dp``, ``f_-`` and ``f_+`` the vector fields before and after. The guards:

* the shaft meets or leaves flank ``s``: ``g = phi - s theta``;
* inertia ``i`` slipping in direction ``m`` stops (it sticks, or slips on the other
  way): ``g = -m w_i``; after a stick ``w_i`` and its sensitivities are exactly 0;
* inertia ``i`` stuck breaks away in direction ``s``: ``g = s T_i - fc_i``, ``T_i``
  the torque on it from the motor torque (``u``, or ``T`` with a loop) and the shaft
  (friction excluded). A breakaway whose guard is already positive at the change was
  set off by another change at that instant (a contact's damper torque) and moves with
  it, or, without a loop, by the torque's step at a sample instant and does not move.
  With a loop the torque on a stuck inertia is continuous but for the damper's, so
  every other breakaway is a located crossing.

Where a guard is crossed at zero rate (the shaft grazes a flank, an inertia creeps to
a stop, the torque on a stuck one barely exceeds ``fc``) the derivative does not exist,
and the jump grows without bound near it; at exactly zero rate a ValueError is raised.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from ._sensitivity import PARAMS, default_params
from .actuator import CurrentLoop
from .errors import InputError
from .plants import TwoMassDrive

__all__ = ["PARAMS", "sensitivities"]

#: Complex step of the derivatives of the mode matrices (exact for h far below 1).
COMPLEX_STEP = 1e-30
#: The states' names without and with a current loop (its motor torque ``T`` last).
STATES, LOOP_STATES = ("w_M", "w_L", "phi"), ("w_M", "w_L", "phi", "T")
#: A breakaway whose guard exceeds this share of the Coulomb torque at the change did
#: not cross it there but was set off (a located crossing is at 0 to the simulator's
#: tolerance, 1e-12 of it, and the twin's drift from the simulator's state: up to 4.6e-7
#: of it on random reversing records, whose stick-slip cycles leave the two twists
#: 1e-11 rad apart; a set-off guard was at 1.9e-2 of it or more there).
PINNED_RTOL = 1e-6
#: Changes closer than this share of a sample are at the same instant (the simulator's
#: times of one instant differ by rounding).
SAME_INSTANT = 1e-9
#: Index in :data:`PARAMS` of each inertia's Coulomb torque (0 the motor, 1 the load).
_FC = (PARAMS.index("fc_M"), PARAMS.index("fc_L"))
#: Index in :data:`PARAMS` of the current loop's time constant (0: no loop).
_TAU = PARAMS.index("tau_i")
#: Index of the loop's torque ``T`` in the state, after the drive's own states.
_T = len(STATES)
#: The friction switch of an inertia without Coulomb friction: slipping forwards, which
#: adds nothing (its Coulomb torque is 0).
NO_SWITCH = 1


def has_loop(p) -> bool:
    """Whether the parameters ``p`` (real or complex) have a current loop: ``tau_i >
    0`` (at 0 the set-point is applied exactly)."""
    return bool(np.real(p[_TAU]) > 0)


def n_states(p) -> int:
    """The drive's state count with parameters ``p``: :data:`STATES`, or
    :data:`LOOP_STATES` with a current loop (the motor's angle, where carried, is one
    more)."""
    return len(LOOP_STATES if has_loop(p) else STATES)


def _has_angle(p, x: np.ndarray) -> bool:
    """Whether the state ``x`` carries the motor's angle, after the drive's."""
    return x.size > n_states(p)


def mode_system(p, mode: tuple[int, int, int], *, friction: bool = True,
                angle: bool = False):
    """``(A, b, c)`` of ``mode = (flank, m_M, m_L)`` for parameters ``p`` (the ten of
    :data:`PARAMS`, real or complex; ``tau_i > 0`` adds the loop's torque ``T`` as a
    fourth state, ``angle`` the motor's angle last); without the viscous and Coulomb
    friction when not ``friction`` (``J_i`` times row ``i`` is then the torque on
    inertia ``i``)."""
    j_m, j_l, k, f_m, f_l, d, theta, fc_m, fc_l, tau_i = p
    flank, n = mode[0], n_states(p) + angle
    dtype = np.result_type(*p, float)
    a = np.zeros((n, n), dtype)
    b, c = np.zeros(n, dtype), np.zeros(n, dtype)
    if friction:
        a[0, 0], a[1, 1] = -f_m / j_m, -f_l / j_l
    a[2, 0], a[2, 1] = 1.0, -1.0
    if flank:  # shaft torque k (phi - s theta) + d (w_M - w_L)
        a[0, :_T] += np.array([-d, d, -k]) / j_m
        a[1, :_T] += np.array([d, -d, k]) / j_l
        c[0], c[1] = k * flank * theta / j_m, -k * flank * theta / j_l
    if has_loop(p):  # tau_i dT/dt = u - T, and T, not u, drives the motor
        a[0, _T], a[_T, _T], b[_T] = 1.0 / j_m, -1.0 / tau_i, 1.0 / tau_i
    else:
        b[0] = 1.0 / j_m
    if angle:  # dphi_M/dt = w_M
        a[-1, 0] = 1.0
    if friction:
        for i, (j_i, fc_i) in enumerate(((j_m, fc_m), (j_l, fc_l))):
            if mode[1 + i] == 0:  # stuck: the speed stays at 0 (T's row never is)
                a[i], b[i], c[i] = 0.0, 0.0, 0.0
            else:
                c[i] -= mode[1 + i] * fc_i / j_i
    return a, b, c


def _complex_step(p: np.ndarray, col: int) -> np.ndarray:
    pj = p.astype(complex)
    pj[col] += 1j * COMPLEX_STEP
    return pj


def augmented_flow(p: np.ndarray, mode: tuple[int, int, int], tau: float, cols,
                   angle: bool = False):
    """``(Phi, Gamma)``: ``z(tau) = Phi z(0) + Gamma [u, 1]`` for ``z = [x, S_1 ..]``,
    the sensitivities to the parameters ``cols`` (indices in :data:`PARAMS`), in a mode
    under a held torque ``u`` (the motor's angle carried where ``angle``)."""
    a, b, c = mode_system(p, mode, angle=angle)
    n = a.shape[0]
    m = n * (1 + len(cols))
    big = np.zeros((m + 2, m + 2))
    for blk in range(1 + len(cols)):
        big[blk * n:(blk + 1) * n, blk * n:(blk + 1) * n] = a
    big[:n, m], big[:n, m + 1] = b, c
    for j, col in enumerate(cols):
        da, db, dc = (x.imag / COMPLEX_STEP
                      for x in mode_system(_complex_step(p, col), mode, angle=angle))
        rows = slice((1 + j) * n, (2 + j) * n)
        big[rows, :n] = da
        big[rows, m], big[rows, m + 1] = db, dc
    e = expm(big * tau)
    return e[:m, :m], e[:m, m:]


def field(p: np.ndarray, mode: tuple[int, int, int], x: np.ndarray, u: float) -> np.ndarray:
    """The vector field ``A x + b u + c`` of a mode at ``x`` (with the motor's angle where
    ``x`` has it)."""
    a, b, c = mode_system(p, mode, angle=_has_angle(p, x))
    return a @ x + b * u + c


def drive_torque(p, flank: int, i: int, x: np.ndarray, u: float):
    """The torque in N m on inertia ``i`` from the motor torque (``u``, or the loop's
    ``T`` in ``x``) and the shaft (friction excluded) at the state ``x``; complex with
    complex ``p``."""
    a, b, c = mode_system(p, (flank, NO_SWITCH, NO_SWITCH), friction=False,
                          angle=_has_angle(p, x))
    return p[i] * (a[i] @ x + b[i] * u + c[i])  # p[i]: J_i


def sensitivities(drive: TwoMassDrive, t: np.ndarray, torque: np.ndarray, *,
                  params=None, initial_state=None, initial_sensitivity=None,
                  actuator: CurrentLoop | None = None, motor_angle: bool = False
                  ) -> np.ndarray:
    """Derivatives of ``(w_M, w_L)`` (and the motor's angle) at ``t`` with respect to
    ``params``.

    Parameters
    ----------
    drive : TwoMassDrive
        With ``theta > 0``, and each breakaway torque the Coulomb torque (``fs_M`` and
        ``fs_L`` None or equal to ``fc_M``, ``fc_L``).
    t, torque : numpy.ndarray
        Uniform time grid in s and the motor torque in N m held over each sample (its
        set-point, with a current loop).
    params : sequence of str, optional
        Distinct names of :data:`PARAMS`, in the order wanted; default
        :func:`~backlashkit._sensitivity.default_params` of ``drive`` and ``actuator``
        (``fc_i`` only where > 0, ``tau_i`` only with a loop).
    initial_state : numpy.ndarray, optional
        ``[w_M, w_L, phi]`` at ``t[0]``, with a current loop ``[w_M, w_L, phi, T]``;
        default rest (with a loop ``T = torque[0]``, settled, as the simulator's
        default).
    initial_sensitivity : numpy.ndarray, optional
        ``d x / d p`` at ``t[0]``, ``(3, len(params))``, with a current loop ``(4,
        len(params))``; default zero.
    actuator : CurrentLoop, optional
        The current loop between the set-point and the motor torque; default none (as
        ``CurrentLoop(0.0)``: the set-point applied exactly).
    motor_angle : bool, optional
        Carry the motor's angle in rad as one more state, last (from 0, with zero
        sensitivity; ``initial_state`` and ``initial_sensitivity`` then have its
        entry), and return its sensitivity; default False.

    Returns
    -------
    numpy.ndarray
        ``(len(t), 2, len(params))``: ``d w / d p`` in the parameters' SI units; with
        ``motor_angle`` ``(len(t), 3, len(params))``, the angle's last.

    Raises
    ------
    InputError
        For a drive other than the above, an actuator other than a CurrentLoop, a
        parameter unknown, repeated, a Coulomb torque that is 0 (its derivative is
        one-sided) or ``tau_i`` without a loop, or a start of the wrong size.
    ValueError
        At a change whose guard is crossed at zero rate (exactly grazing).
    """
    names = _checked_params(drive, params, actuator)
    cols = [PARAMS.index(n) for n in names]
    p = _param_values(drive, actuator)
    states = (LOOP_STATES if has_loop(p) else STATES) + (("phi_M",) if motor_angle else ())
    x0, s0 = _checked_start(initial_state, initial_sensitivity, states, len(cols))
    if initial_state is None and has_loop(p):  # the loop settled, as the simulator's
        x0[n_states(p) - 1] = float(torque[0])
    # the simulator's changes do not depend on the angle, which it leaves out
    res = drive.simulate(t, torque, initial_state=x0[:n_states(p)], actuator=actuator)
    z = np.concatenate([x0, s0.T.ravel()])  # z holds a column's states together
    return _walk(p, (t, torque, res), cols, z, motor_angle)


def _walk(p: np.ndarray, run, cols: list[int], z: np.ndarray, angle: bool = False
          ) -> np.ndarray:
    """The speeds' sensitivities ``(len(t), 2, len(cols))`` along ``run = (t, torque,
    res)``, ``res`` the simulator's run on that grid and torque, from ``z = [x, S_1
    ..]`` at ``t[0]``; with the motor's angle's last where ``angle`` (``z`` has it)."""
    (t, torque, res), n = run, n_states(p) + angle
    rows = [0, 1, n - 1] if angle else [0, 1]
    ts = float(t[1] - t[0])
    sticky = [i for i in (0, 1) if p[_FC[i]] > 0]
    changes = [(time, int(j), int(to)) for time, j, _, to in res.event_array.tolist()]
    mode = _initial_mode(res, sticky)
    i_ev, full, last = 0, {}, (-np.inf, None)
    out = np.empty((t.size, len(rows), len(cols)))
    for k in range(t.size):
        out[k] = z[n:].reshape(len(cols), n)[:, rows].T
        if k == t.size - 1:
            break
        t_now, u = float(t[k]), float(torque[k])
        while i_ev < len(changes) and changes[i_ev][0] <= t[k + 1]:
            t_ev, j, to = changes[i_ev]
            z = _advance(p, mode, z, u, t_ev - t_now, cols, angle)
            z, mode, last = _change(p, z, u, mode, (j, to), (t_ev, ts, last), cols)
            t_now, i_ev = t_ev, i_ev + 1
        if t_now == t[k]:  # a whole sample in one mode: its flow is cached
            if mode not in full:
                full[mode] = augmented_flow(p, mode, ts, cols, angle)
            phi, gam = full[mode]
            z = phi @ z + gam @ np.array([u, 1.0])
        else:
            z = _advance(p, mode, z, u, float(t[k + 1]) - t_now, cols, angle)
    return out


def _param_values(drive: TwoMassDrive, actuator: CurrentLoop | None) -> np.ndarray:
    """The values of :data:`PARAMS`: the drive's, and the loop's ``tau_i`` (0 without
    one)."""
    tau_i = 0.0 if actuator is None else actuator.tau_i
    return np.array([tau_i if n == "tau_i" else getattr(drive, n) for n in PARAMS], float)


def _checked_params(drive, params, actuator) -> tuple[str, ...]:
    """The parameters' names, after the checks of :func:`sensitivities`."""
    if not isinstance(drive, TwoMassDrive):
        raise InputError(f"drive must be a TwoMassDrive, got {type(drive).__name__}")
    if actuator is not None and not isinstance(actuator, CurrentLoop):
        raise InputError(f"actuator must be a CurrentLoop or None, got "
                         f"{type(actuator).__name__}")
    if drive.theta is None or drive.theta <= 0:
        raise InputError(f"the sensitivities need theta > 0, got {drive.theta!r}")
    for side in ("M", "L"):
        fs, fc = getattr(drive, f"fs_{side}"), getattr(drive, f"fc_{side}")
        if fs is not None and fs != fc:
            raise InputError(f"fs_{side} = {fs!r} differs from fc_{side} = {fc!r} N m: the "
                             "sensitivities need the breakaway torque equal to the Coulomb "
                             f"torque (leave fs_{side} None)")
    names = default_params(drive, actuator) if params is None else tuple(params)
    if any(n not in PARAMS for n in names) or len(set(names)) != len(names):
        raise InputError(f"params must be distinct names among {', '.join(PARAMS)}, got "
                         f"{params!r}")
    for n in names:
        if n in ("fc_M", "fc_L") and getattr(drive, n) == 0:
            raise InputError(f"{n} is 0: the inertia has no friction switch and the "
                             f"derivative is one-sided; leave {n} out of params")
    if "tau_i" in names and (actuator is None or actuator.exact):
        raise InputError("tau_i needs a current loop with tau_i > 0 (actuator="
                         "CurrentLoop(tau_i)); without one leave tau_i out of params")
    return names


def _checked_start(initial_state, initial_sensitivity, states: tuple[str, ...], m: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The initial state ``(n,)`` and sensitivity ``(n, m)`` of a run of the ``n``
    ``states`` and ``m`` parameters (default rest and zero), after their checks."""
    n = len(states)
    x0 = np.zeros(n) if initial_state is None else np.asarray(initial_state, float)
    if x0.shape != (n,):
        raise InputError(f"initial_state must have {n} entries [{', '.join(states)}]"
                         f", got shape {x0.shape}")
    s0 = np.zeros((n, m)) if initial_sensitivity is None else np.asarray(
        initial_sensitivity, float)
    if s0.shape != (n, m):
        raise InputError(f"initial_sensitivity must have shape ({n}, {m}) (states "
                         f"[{', '.join(states)}] by parameters), got {s0.shape}")
    return x0, s0


def _initial_mode(res, sticky: list[int]) -> tuple[int, int, int]:
    """``(flank, m_M, m_L)`` at the start of the response ``res``."""
    m = [NO_SWITCH, NO_SWITCH]
    for r, i in enumerate(sticky):
        m[i] = int(res.friction_modes[0, r])
    return (int(res.modes[0, 0]), *m)


def _advance(p, mode, z, u, tau, cols, angle):
    if tau <= 0.0:
        return z
    phi, gam = augmented_flow(p, mode, tau, cols, angle)
    return phi @ z + gam @ np.array([u, 1.0])


def _change(p, z, u, before, change, when, cols):
    """``(z, mode, (time, dtau/dp))`` after the change ``(slot, to)`` (the simulator's
    event row ``j``: 0 the shaft, ``1 + i`` inertia ``i``'s switch, to mode ``to``) at
    ``when = (time, sample time, the last change's (time, dtau/dp))``."""
    (slot, to), (t_ev, ts, (t_last, dtau_last)) = change, when
    n = z.size // (1 + len(cols))
    after = list(before)
    after[slot] = to
    after = tuple(after)
    g, dg_dx, dg_dp = _guard(p, z[:n], u, before, slot, to, cols)
    crossed = g is None or abs(g) <= PINNED_RTOL * p[_FC[slot - 1]]
    same_instant = abs(t_ev - t_last) <= SAME_INSTANT * ts
    # With a loop the torque has no step at a sample instant: a breakaway not at another
    # change's instant was crossed there, whatever |g| the twin's drift from the
    # simulator's state leaves (PINNED_RTOL).
    if crossed or (has_loop(p) and not same_instant):
        dtau = jump_time(p, z, u, before, dg_dx, dg_dp, t_ev)
    elif same_instant:  # set off by the last change
        dtau = dtau_last
    else:  # set off by the torque's step at a sample instant: fixed in time
        dtau = np.zeros(len(cols))
    z = saltation(p, z, u, before, after, dtau)
    if slot and to == 0:  # stuck: the speed and its derivatives exactly 0
        z = z.copy()
        z[slot - 1::n] = 0.0
    return z, after, (t_ev, dtau)


def _guard(p, x, u, before, slot, to, cols):
    """``(g, dg/dx, dg/dp)`` of a change of ``slot`` (0 the shaft's contact, ``1 + i``
    inertia ``i``'s switch) from ``before`` to ``to``; ``g`` None but for a breakaway,
    the one guard that can be positive at its change."""
    dg_dx, dg_dp = np.zeros(x.size), np.zeros(len(cols))
    if slot == 0:  # g = phi - s theta
        s = to or before[0]
        dg_dx[2] = 1.0
        if PARAMS.index("theta") in cols:
            dg_dp[cols.index(PARAMS.index("theta"))] = -s
        return None, dg_dx, dg_dp
    i, m = slot - 1, before[slot]
    if m:  # a slipping inertia stops: g = -m w_i
        dg_dx[i] = -m
        return None, dg_dx, dg_dp
    a, _, _ = mode_system(p, (before[0], NO_SWITCH, NO_SWITCH), friction=False,
                          angle=_has_angle(p, x))
    dg_dx = to * p[i] * a[i]  # breakaway in direction s = to: g = s T_i - fc_i (T too)
    for n, col in enumerate(cols):
        dt_dp = drive_torque(_complex_step(p, col), before[0], i, x, u).imag / COMPLEX_STEP
        dg_dp[n] = to * dt_dp - (col == _FC[i])
    return to * drive_torque(p, before[0], i, x, u) - p[_FC[i]], dg_dx, dg_dp


def jump_time(p, z, u, before, dg_dx, dg_dp, time: float) -> np.ndarray:
    """``dtau/dp = -(dg/dx S + dg/dp) / (dg/dx f_-)`` of a change at ``time`` from the
    mode ``before``.

    Raises
    ------
    ValueError
        Where the guard's rate ``dg/dx f_-`` is 0 (exactly grazing).
    """
    n = dg_dx.size
    x = z[:n]
    sens = z[n:].reshape(-1, n).T  # (state, parameter)
    with np.errstate(divide="ignore", invalid="ignore"):
        dtau = -(dg_dx @ sens + dg_dp) / (dg_dx @ field(p, before, x, u))
    if not np.all(np.isfinite(dtau)):
        raise ValueError(f"the change at t = {time!r} s is crossed at zero rate (exactly "
                         "grazing): its sensitivities do not exist")
    return dtau


def saltation(p: np.ndarray, z: np.ndarray, u: float, before, after, dtau: np.ndarray
              ) -> np.ndarray:
    """``z`` after a change from mode ``before`` to ``after`` that moves by ``dtau`` per
    parameter: the sensitivities jump by ``(f_- - f_+) dtau/dp`` (the loop's torque's
    row of the two fields is one, and so is the motor's angle's, so their
    sensitivities do not jump)."""
    n = z.size // (1 + dtau.size)
    x = z[:n]
    sens = z[n:].reshape(-1, n).T  # (state, parameter)
    f_minus, f_plus = field(p, before, x, u), field(p, after, x, u)
    sens = sens + np.outer(f_minus - f_plus, dtau)
    return np.concatenate([x, sens.T.ravel()])
