"""Event-located integration engine of :mod:`backlashkit.verify`'s reference.

Inside one mode configuration of :class:`~backlashkit._reference_model.ReferenceModel`
the drive is affine, ``dx/dt = A x + c``; a scipy solver object is stepped through it,
every step is scanned at interior points for the crossings of the switching functions
(with their exact time derivatives, so a short excursion inside one step is caught),
the first crossing is located by Brent's method on the dense output, and the solver
restarts there in the new configuration. The public face, the result objects and the
documentation of the switching rules live in :mod:`backlashkit.verify`.

Events are recorded as the model gives them (contact changes as ``(time, shaft, kind,
flank)`` tuples, friction changes as :class:`~backlashkit.response.FrictionEvent`) and
grazes as ``(time, shaft, margin)`` tuples; :mod:`backlashkit.verify` words them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import integrate, optimize

from ._reference_model import ReferenceModel
from .errors import InputError
from .laws import ShaftLaw

SOLVERS: dict[str, type[integrate.OdeSolver]] = {
    "DOP853": integrate.DOP853,
    "RK45": integrate.RK45,
    "RK23": integrate.RK23,
    "Radau": integrate.Radau,
    "BDF": integrate.BDF,
    "LSODA": integrate.LSODA,
}
#: Implicit solvers, given the exact Jacobian ``A`` of each configuration.
_IMPLICIT = ("Radau", "BDF", "LSODA")

#: Largest step of an explicit method behind a current loop, in lags ``tau_i``: the
#: loop's decay ``e^(-t / tau_i)`` is stable under a step within the method's stability
#: interval on the negative real axis (RK23 to -2.51, RK45 -3.31, DOP853 -6.39:
#: ``tests/test_verify.py -k stability_interval -s``, from scipy's tableaux). Beyond
#: it a step amplifies the decay once it lies below the error control's notice: at
#: ``rtol`` 1e-12, in free flight behind a 1 ms loop, the motor's speed strayed 7.8e-9
#: rad/s from its closed form, beyond the 1e-9 that ``rtol`` 1e-10 kept
#: (``tests/test_verify.py -k loop_steps``, run on the package before this bound). It
#: costs a step at least every two lags.
LOOP_MAX_STEP = 2.0
#: Interior points at which every solver step is scanned for switching-function roots.
_SCAN_POINTS = 8
#: A local extremum of a switching function closer than this (relative to the twist
#: scale of the shaft) to zero is recorded as a graze.
_GRAZE_RTOL = 1e-6
#: A switching function within this fraction of the twist scale of zero is on its
#: boundary (a located event leaves it within a few ulp of zero, whatever the solver
#: tolerance); the direction of motion then decides.
_ON_BOUNDARY_RTOL = 1e-10
#: Highest Lie derivative used to decide the direction of motion on a boundary.
_MAX_LIE_ORDER = 4
#: Zero-length restarts in a row after which the run is declared chattering.
_MAX_ZERO_LENGTH_RESTARTS = 64
#: Floor of every twist and speed scale (rad, rad/s): keeps a drive at rest with no
#: backlash and no torque from a zero tolerance.
_SCALE_FLOOR = 1e-12

# --------------------------------------------------------------------------- setup


def _chain_of(drive):
    to_chain = getattr(drive, "to_chain", None)
    if to_chain is None:
        raise InputError(
            f"drive must be a TwoMassDrive or a DriveChain, got {type(drive).__name__}"
        )
    return to_chain()


def _check_grid(t_arr: np.ndarray, u: np.ndarray) -> None:
    if t_arr.ndim != 1 or t_arr.size < 2:
        raise InputError("t must be a 1-D grid with at least 2 samples")
    if not np.all(np.diff(t_arr) > 0):
        raise InputError("t must be strictly increasing")
    if u.shape != t_arr.shape:
        raise InputError(f"torque must have one sample per time step ({t_arr.size}), got {u.size}")
    if not (np.all(np.isfinite(t_arr)) and np.all(np.isfinite(u))):
        raise InputError("t and torque must be finite")


def _initial_state(initial_state, n: int, tau_i: float, u: np.ndarray) -> np.ndarray:
    s = 2 * n - 1
    x0 = np.zeros(s) if initial_state is None else np.asarray(initial_state, dtype=float).ravel()
    if tau_i > 0 and x0.size == s:
        x0 = np.append(x0, u[0])  # the loop settled at the first set-point
    s += int(tau_i > 0)
    if x0.size != s or not np.all(np.isfinite(x0)):
        raise InputError(f"initial_state must have {s} finite entries")
    return x0


def prepare(drive, t, torque, law, initial_state, actuator=None):
    """Check a run's inputs and build its model.

    Returns ``(model, t, torque, x0, law, scale)``: the grid and torque as float
    arrays, the initial state (with the loop's torque last under a current loop), the
    parsed law and the scale of each state component (the default ``atol / rtol``).
    """
    chain = _chain_of(drive)
    t_arr = np.asarray(t, dtype=float)
    u = np.asarray(torque, dtype=float)
    _check_grid(t_arr, u)
    n = len(chain.J)
    tau_i = 0.0 if actuator is None else float(actuator.tau_i)
    x0 = _initial_state(initial_state, n, tau_i, u)
    law_ = ShaftLaw.parse(law)

    J, f = np.asarray(chain.J, float), np.asarray(chain.f, float)
    k, d, theta = (np.asarray(a, float) for a in (chain.k, chain.d, chain.theta))
    u_max = float(np.max(np.abs(u[:-1]))) if u.size > 1 else 0.0
    duration = float(t_arr[-1] - t_arr[0])
    twist_scale = np.maximum.reduce(
        [theta, np.abs(x0[n : 2 * n - 1]), np.full(n - 1, u_max) / k,
         np.full(n - 1, _SCALE_FLOOR)]
    )
    fc = np.asarray(getattr(chain, "fc", np.zeros(n)), float)
    fs = np.asarray(getattr(chain, "fs", fc), float)

    # Speed scale: initial speeds, the terminal speed u/sum(f) or, if friction is
    # too weak to reach it within the record, the speed gained in the record.
    gain = duration / J.sum()
    if f.sum() > 0:
        gain = min(gain, 1.0 / f.sum())
    w_scale = max(float(np.max(np.abs(x0[:n]))), u_max * gain, _SCALE_FLOOR)
    scale = np.concatenate([np.full(n, w_scale), twist_scale] + ([[u_max or 1.0]] if tau_i else []))
    model = ReferenceModel(J, f, k, d, theta, law_, twist_scale, fc, fs, tau_i, w_scale)
    return model, t_arr, u, x0, law_, scale


def segments(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and last grid index of each constant-torque segment: ``u[i]`` is held on
    ``[t[i], t[i+1])``, consecutive equal samples form one segment, the last sample is
    unused."""
    change = np.flatnonzero(np.diff(u[:-1]) != 0) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [u.size - 1]])
    return starts, ends


@dataclass(frozen=True)
class SolverOptions:
    """The scipy solver of a run and its settings."""

    method: str
    rtol: float
    atol: np.ndarray
    max_step: float

    @classmethod
    def build(cls, method: str, rtol: float, atol, max_step: float,
              scale: np.ndarray, tau_i: float = 0.0) -> SolverOptions:
        """Check ``method``; ``atol`` defaults to ``rtol`` times the component scales;
        an explicit method's steps behind a current loop of lag ``tau_i`` (s) stay
        within :data:`LOOP_MAX_STEP` lags."""
        if method not in SOLVERS:
            raise InputError(f"method must be one of {sorted(SOLVERS)}, got {method!r}")
        atol_arr = rtol * scale if atol is None else np.broadcast_to(
            np.asarray(atol, float), scale.shape).copy()
        if tau_i > 0 and method not in _IMPLICIT:
            max_step = min(max_step, LOOP_MAX_STEP * tau_i)
        return cls(method, rtol, atol_arr, max_step)

    def start(self, a: np.ndarray, c: np.ndarray, t0: float, x: np.ndarray,
              t_end: float) -> integrate.OdeSolver:
        """A solver of ``dx/dt = A x + c`` from ``(t0, x)`` towards ``t_end``."""
        def fun(_t, y, a=a, c=c):
            return a @ y + c

        kwargs = dict(rtol=self.rtol, atol=self.atol, max_step=self.max_step)
        if self.method in _IMPLICIT:
            kwargs["jac"] = a
        return SOLVERS[self.method](fun, t0, x, t_end, **kwargs)


# --------------------------------------------------------------------------- run


@dataclass
class Trace:
    """What a run records: the states and modes on the grid, the events with the state
    at each, the grazes and the solver statistics."""

    t: np.ndarray
    states: np.ndarray
    modes: np.ndarray
    events: list = field(default_factory=list)
    event_states: list = field(default_factory=list)
    grazes: list = field(default_factory=list)
    filled: int = 1  # grid points [0, filled) are done
    n_steps: int = 0
    n_restarts: int = 0
    nfev: int = 0

    def fill(self, dense, t_stop: float, last: int, modes: tuple[int, ...]) -> None:
        """Sample the grid points in ``[filled, t_stop)`` (before index ``last``, which
        belongs to what follows) from the dense output of a solver step."""
        stop = int(np.searchsorted(self.t, t_stop, side="left"))
        stop = min(stop, last)
        if stop > self.filled:
            pts = self.t[self.filled:stop]
            self.states[self.filled:stop] = dense(pts).T
            self.modes[self.filled:stop] = modes
            self.filled = stop


def run(model: ReferenceModel, t_arr: np.ndarray, u: np.ndarray, x0: np.ndarray,
        options: SolverOptions) -> Trace:
    """Integrate the model under the zero-order-hold torque ``u`` on the grid
    ``t_arr`` from ``x0``, restarting at every torque change and every switch."""
    n_grid = t_arr.size
    trace = Trace(
        t=t_arr,
        states=np.empty((n_grid, model.s)),
        modes=np.empty((n_grid, model.n - 1 + len(model.sticky)), dtype=np.int8),
    )
    x = x0.copy()
    modes = model.classify(x, float(u[0]))
    trace.states[0] = x
    trace.modes[0] = modes
    t_cur = float(t_arr[0])
    for i0, i1 in zip(*segments(u), strict=True):
        x, modes, t_cur = _run_segment(model, trace, options, x, modes, t_cur, float(u[i0]), i1)
    # the grid points of each segment up to (not including) its end are filled by it
    trace.states[-1] = x
    trace.modes[-1] = modes
    if trace.filled < n_grid - 1:  # pragma: no cover - defensive
        raise RuntimeError("internal error: grid not filled")
    return trace


def _run_segment(model, trace, options, x, modes, t_cur, ui, last):
    """Integrate one constant-torque segment up to grid index ``last``, switch by
    switch; returns the state, modes and time at its end."""
    t_end = float(trace.t[last])
    modes = _settle(model, t_cur, x, modes, ui, trace, _ON_BOUNDARY_RTOL)
    zero_len = 0
    while t_cur < t_end:
        hit, x = _integrate_to_switch(model, trace, options, x, modes, t_cur, ui, t_end, last)
        if hit is None:
            t_cur = t_end
            break
        te, shaft, target = hit
        zero_len = zero_len + 1 if te <= t_cur else 0
        if zero_len > _MAX_ZERO_LENGTH_RESTARTS:
            raise RuntimeError(f"contact chatter at t = {te!r} s")
        t_cur = te
        modes = _switch(model, modes, shaft, target, te, x, ui, trace)
        modes = _settle(model, t_cur, x, modes, ui, trace, _ON_BOUNDARY_RTOL)
    return x, modes, t_cur


def _integrate_to_switch(model, trace, options, x, modes, t_cur, ui, t_end, last):
    """Step one solver from ``(t_cur, x)`` in ``modes`` until the first switch or
    ``t_end``; returns the switch ``(time, shaft, target)`` or ``None``, and the state
    there."""
    a, c = model.field(modes, ui)
    guards = model.guards(modes, ui)
    solver = options.start(a, c, t_cur, x, t_end)
    trace.n_restarts += 1
    hit = None
    first = True
    while solver.status == "running":
        msg = solver.step()
        if solver.status == "failed":
            raise RuntimeError(f"{options.method} failed at t = {solver.t!r} s: {msg}")
        trace.n_steps += 1
        t_old, t_new = float(solver.t_old), float(solver.t)
        dense = solver.dense_output()
        hit = _scan_step(model, guards, a, c, dense, t_old, t_new, first, trace.grazes,
                         _ON_BOUNDARY_RTOL)
        first = False
        trace.fill(dense, hit[0] if hit is not None else t_new, last, modes)
        if hit is not None:
            break
    trace.nfev += int(solver.nfev)
    if hit is None:
        return None, np.asarray(solver.y, dtype=float).copy()
    return hit, np.asarray(dense(hit[0]), dtype=float).copy()


# --------------------------------------------------------------------------- switches


def _lie_sign(h: np.ndarray, a: np.ndarray, c: np.ndarray, x: np.ndarray,
              eps: float, rate: float) -> int:
    """Sign of the motion of ``h @ x + h0`` at ``x`` under ``dx/dt = A x + c``: the
    sign of the first Lie derivative that is not negligible (0 when the function is
    stationary to the order examined)."""
    v = a @ x + c
    for order in range(1, _MAX_LIE_ORDER + 1):
        g = float(h @ v)
        if abs(g) > eps * rate**order:
            return 1 if g > 0 else -1
        v = a @ v
    return 0


def _fires_now(model, guard, x, a, c, rate, eps_rel) -> bool:
    """Whether a switching function is positive at ``x``, or on zero (within
    ``eps_rel`` of its scale) and increasing under ``dx/dt = A x + c``."""
    shaft, _target, hmat, h0 = guard
    eps = eps_rel * model.scale(shaft)
    vals = hmat @ x + h0
    if vals.min() > eps:
        return True
    if vals.min() >= -eps:
        signs = [
            _lie_sign(hmat[r], a, c, x, eps, rate)
            for r in range(vals.size)
            if vals[r] <= eps
        ]
        return bool(signs) and all(sg > 0 for sg in signs)
    return False


def _settle(model: ReferenceModel, t: float, x: np.ndarray, modes: tuple[int, ...], u: float,
            trace: Trace, eps_rel: float) -> tuple[int, ...]:
    """Apply every contact change that takes place at ``t`` itself.

    A switching function that fires at once (:func:`_fires_now`) switches. This covers
    the initial state, flank-to-flank switches of a shaft without backlash and
    tangencies; repeated until the configuration is consistent.
    """
    for _ in range(4 * model.n + 4):
        a, c = model.field(modes, u)
        rate = max(float(np.max(np.abs(np.linalg.eigvals(a)))), 1.0)
        fired = next((g for g in model.guards(modes, u)
                      if _fires_now(model, g, x, a, c, rate, eps_rel)), None)
        if fired is None:
            return modes
        shaft, target = fired[0], fired[1]
        modes = _switch(model, modes, shaft, target, t, x, u, trace)
    raise RuntimeError(f"contact configuration does not settle at t = {t!r} s (chatter)")


def _switch(model, modes, index, target, t, x, u, trace: Trace) -> tuple[int, ...]:
    """Apply a switch (the model may set a stuck speed to 0 in ``x``); record its
    events and the state at each."""
    modes, new = model.switch(modes, index, target, t, x, u)
    for e in new:
        trace.events.append(e)
        trace.event_states.append(np.array(x, dtype=float))
    return modes


# --------------------------------------------------------------------------- location


def _guard_fn(dense, hmat, h0):
    def q(tt: float) -> float:
        return float(np.min(hmat @ dense(tt) + h0))

    return q


def _guard_rate_fn(dense, hmat, h0, a, c):
    def dq(tt: float) -> float:
        x = dense(tt)
        vals = hmat @ x + h0
        r = int(np.argmin(vals))
        return float(hmat[r] @ (a @ x + c))

    return dq


def _root(fun, lo: float, hi: float) -> float:
    """First-found root of ``fun`` on ``[lo, hi]`` with ``fun(lo) <= 0 < fun(hi)``:
    the returned point has ``fun > 0`` or is within a few ulp of the crossing."""
    flo, fhi = fun(lo), fun(hi)
    if flo > 0:
        return lo
    if fhi <= 0:
        return hi
    r = optimize.brentq(fun, lo, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=400)
    return float(r)


@dataclass
class _GuardScan:
    """One switching function ``q = min_r (H[r] @ x + h0[r])`` and its rate ``dq``
    sampled at the scan points ``taus`` of a solver step."""

    taus: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    scale: float
    eps: float
    on_zero: bool
    cross: np.ndarray
    turn: np.ndarray

    @classmethod
    def sample(cls, hmat, h0, xs, dxs, taus, scale, eps_rel, first_step) -> _GuardScan:
        vals = hmat @ xs + h0[:, None]
        arg = np.argmin(vals, axis=0)
        q = vals[arg, np.arange(taus.size)]
        dq = (hmat @ dxs)[arg, np.arange(taus.size)]
        eps = eps_rel * scale
        # On zero right after a restart (the switch that caused it, or a tangency that
        # _settle judged not to enter): the crossing sought is a later one.
        on_zero = first_step and abs(q[0]) <= eps
        if on_zero:
            q = q.copy()
            q[0] = 0.0
        dt = taus[1] - taus[0]
        bound = np.maximum(q[:-1], q[1:]) + dt * np.maximum(np.abs(dq[:-1]), np.abs(dq[1:]))
        cross = q[1:] > 0
        turn = (dq[:-1] > 0) & (dq[1:] < 0) & (bound > -_GRAZE_RTOL * scale)
        return cls(taus, q, dq, scale, eps, on_zero, cross, turn)

    def first_hit(self, qf, dqf, shaft: int, t_best: float, grazes: list) -> float | None:
        """Time of the first crossing before ``t_best``, or ``None``; records grazes."""
        for i in range(_SCAN_POINTS):
            lo, hi = self.taus[i], self.taus[i + 1]
            if lo >= t_best:
                break
            hit = self._hit_in(i, lo, hi, qf, dqf, shaft, grazes)
            if hit is not None:
                return hit
        return None

    def _hit_in(self, i, lo, hi, qf, dqf, shaft, grazes):
        """Crossing inside scan interval ``i = [lo, hi]``, or ``None``."""
        q, dq = self.q, self.dq
        if i == 0 and self.on_zero and self.cross[0]:
            # q leaves zero downwards (or stays), dips, then crosses: find the dip
            # (minimum) first, then the crossing after it; without a dip below
            # zero, fire where q clears eps
            a_ = lo
            if dq[0] <= 0 < dq[1]:
                a_ = optimize.brentq(dqf, lo, hi, xtol=1e-300)
            if a_ > lo and qf(a_) < 0:
                return _root(qf, a_, hi)
            return _root(lambda s, qf=qf, eps=self.eps: qf(s) - eps, lo, hi)
        if q[i] > 0:
            # cannot happen after _settle; fire at once rather than lose the event
            return lo
        if self.cross[i]:
            return _root(qf, lo, hi)
        if self.turn[i]:
            tm = optimize.brentq(dqf, lo, hi, xtol=1e-300)
            qm = qf(tm)
            hit = _root(qf, lo, tm) if qm > 0 else None
            if abs(qm) < _GRAZE_RTOL * self.scale:
                grazes.append((float(tm), int(shaft), float(qm)))
            return hit
        return None


def _scan_step(model, guards, a, c, dense, t_old, t_new, first_step, grazes, eps_rel):
    """Earliest crossing of a switching function inside ``(t_old, t_new]``.

    Returns ``(time, shaft, target)`` or ``None``. Records grazes in ``grazes``.
    """
    taus = np.linspace(t_old, t_new, _SCAN_POINTS + 1)
    xs = dense(taus)  # (s, M+1)
    dxs = a @ xs + c[:, None]
    best = None
    for shaft, target, hmat, h0 in guards:
        scan = _GuardScan.sample(hmat, h0, xs, dxs, taus, model.scale(shaft), eps_rel,
                                 first_step)
        if not (scan.cross.any() or scan.turn.any()):
            continue
        qf = _guard_fn(dense, hmat, h0)
        dqf = _guard_rate_fn(dense, hmat, h0, a, c)
        t_best = math.inf if best is None else best[0]
        hit = scan.first_hit(qf, dqf, shaft, t_best, grazes)
        if hit is not None and (best is None or hit < best[0]):
            best = (hit, shaft, target)
    return best
