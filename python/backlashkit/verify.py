"""Independent reference simulator for verifying the compiled drive kernel.

The compiled kernel (:func:`backlashkit.simulate.simulate_drive`) advances the
piecewise-affine drive with matrix exponentials and locates contact changes from Taylor
expansions of the flow. This module shares none of that: it integrates the ODE with an
adaptive Runge-Kutta solver of :mod:`scipy.integrate` (default ``DOP853``), locates every
contact change by root finding on the solver's dense output, and restarts the
integration exactly there and at every change of the zero-order-hold input.

It drives scipy's solver objects step by step (the machinery :func:`scipy.integrate.
solve_ivp` runs on) rather than calling ``solve_ivp(events=...)``, because
``solve_ivp`` only compares the sign of an event function at the two ends of each step:
a twist that pokes past a flank and comes back inside one step would be missed. Here
every step is scanned at interior points together with the exact time derivative of
each switching function, so a short excursion is caught (and a near miss is recorded
as a graze).

The engine is :mod:`backlashkit._reference_engine`; the model it integrates, written
from the physics, is :mod:`backlashkit._reference_model`.

Public functions
----------------
reference_simulate
    Event-located reference run of a :class:`~backlashkit.TwoMassDrive` or
    :class:`~backlashkit.DriveChain` under a zero-order-hold torque.
check_conditioning
    Runs two different tight references and says whether they agree; a case where they
    do not is ill-conditioned (near-grazing) and says nothing about a simulator.
compare_to_reference
    Speed error and contact-event timing of a simulator response against a reference.
naive_simulate
    The same ODE integrated *without* locating the contact changes (the switching is
    buried in the right-hand side), for demonstrating why event location matters.

Conventions as in :mod:`backlashkit.plants`: SI units, state
``[w_1 .. w_N, phi_1 .. phi_{N-1}]``, ``theta`` the half-width of each dead zone, the
input torque acting on inertia 1 and held on ``[t[i], t[i+1])``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import integrate

from . import validate as v
from ._reference_engine import SolverOptions, prepare, run, segments
from ._reference_model import ReferenceModel
from .errors import InputError
from .laws import ShaftLaw
from .response import FrictionEvent, StateColumns

if TYPE_CHECKING:
    from .actuator import CurrentLoop
    from .plants import DriveChain, TwoMassDrive

__all__ = [
    "AccuracyReport",
    "ConditioningReport",
    "ReferenceEvent",
    "ReferenceGraze",
    "ReferenceResult",
    "check_conditioning",
    "compare_to_reference",
    "naive_simulate",
    "reference_angles",
    "reference_simulate",
]

#: Substeps per sample of :func:`reference_angles`'s run: on paper A's drive with
#: Coulomb friction and a 1 ms current loop (8 s records, 1 ms samples) its angles
#: change by less than 1e-7 rad from 16 to 32 substeps, under 3e-4 of a 16 384-count
#: encoder's count (``tests/test_identify_real_drive.py::test_reference_angles``).
ANGLE_SUBSTEPS = 32


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class ReferenceEvent:
    """A contact change located by the reference.

    Parameters
    ----------
    time : float
        Instant of the change in s.
    shaft : int
        Index of the shaft (0-based).
    kind : {"contact_made", "contact_lost"}
        Whether the flanks met or separated.
    flank : {"positive", "negative"}
        The flank met or left (``"positive"`` is ``phi = +theta``).
    """

    time: float
    shaft: int
    kind: str
    flank: str


@dataclass(frozen=True)
class ReferenceGraze:
    """A local extremum of a switching function that came close to zero.

    Parameters
    ----------
    time : float
        Instant of the extremum in s.
    shaft : int
        Index of the shaft.
    margin : float
        Value of the switching function at the extremum, in rad (torques are divided by
        the shaft stiffness): negative when the boundary was missed by that much.
    """

    time: float
    shaft: int
    margin: float


@dataclass(frozen=True, eq=False)
class ReferenceResult(StateColumns):
    """Result of :func:`reference_simulate`, sampled on the input grid.

    Parameters
    ----------
    t : numpy.ndarray
        Time grid in s, shape ``(n,)``.
    torque : numpy.ndarray
        Motor torque in N m, shape ``(n,)`` (zero-order hold).
    states : numpy.ndarray
        States ``[w_1 .. w_N, phi_1 .. phi_{N-1}]`` at ``t``, shape ``(n, 2N - 1)``.
    modes : numpy.ndarray
        Contact mode of each shaft at ``t`` (0 gap, +1 positive flank, -1 negative
        flank), ``int8``, shape ``(n, N - 1)``. At ``t[0]`` the mode is the
        classification of the initial state, before any contact change at ``t[0]``.
    events : tuple of ReferenceEvent or FrictionEvent
        Every contact change and friction change (stick, breakaway, reversal), in
        time order.
    event_states : numpy.ndarray
        State at each event, shape ``(len(events), 2N - 1)``.
    grazes : tuple of ReferenceGraze
        Near misses and near-tangent passes seen by the reference.
    law : ShaftLaw
        Contact law used.
    method : str
        scipy solver used.
    rtol : float
        Relative tolerance of the solver.
    atol : numpy.ndarray
        Absolute tolerance per state component.
    n_steps : int
        Accepted solver steps.
    n_restarts : int
        Solver (re)starts: one per input segment and per located contact change.
    nfev : int
        Right-hand-side evaluations.
    n_inertias : int
        Number of inertias ``N``.
    stuck_array : numpy.ndarray or None
        Whether each inertia is stuck at ``t``, ``bool``, shape ``(n, N)``; ``None``
        without Coulomb or static friction.
    loop_torque : numpy.ndarray or None
        Motor torque of the current loop at ``t`` in N m; ``None`` without one.
    """

    t: np.ndarray
    torque: np.ndarray
    states: np.ndarray
    modes: np.ndarray
    events: tuple[ReferenceEvent, ...]
    event_states: np.ndarray
    grazes: tuple[ReferenceGraze, ...]
    law: ShaftLaw
    method: str
    rtol: float
    atol: np.ndarray
    n_steps: int
    n_restarts: int
    nfev: int
    n_inertias: int
    stuck_array: np.ndarray | None = None
    loop_torque: np.ndarray | None = None

    @property
    def event_times(self) -> np.ndarray:
        """Times of the contact changes in s."""
        return np.array([e.time for e in self.events], dtype=float)


@dataclass(frozen=True, eq=False)
class ConditioningReport:
    """Outcome of :func:`check_conditioning`.

    Parameters
    ----------
    well_conditioned : bool
        True when the two references agree within the tolerances.
    same_event_sequence : bool
        Same number of contact changes with the same shaft, kind and flank in order.
    max_event_time_diff : float
        Largest difference of matching event times in s (``inf`` when the sequences
        differ, 0 when there are no events).
    max_speed_rel_diff : float
        ``max |w_a - w_b| / max |w_b|`` over the grid and all inertias.
    reasons : tuple of str
        Why the references were judged to disagree (empty when they agree).
    reference : ReferenceResult
        The tighter of the two runs (the one to compare simulators with).
    check : ReferenceResult
        The other run.
    """

    well_conditioned: bool
    same_event_sequence: bool
    max_event_time_diff: float
    max_speed_rel_diff: float
    reasons: tuple[str, ...]
    reference: ReferenceResult
    check: ReferenceResult


@dataclass(frozen=True)
class AccuracyReport:
    """Outcome of :func:`compare_to_reference`.

    Parameters
    ----------
    max_speed_error : float
        ``max |w - w_ref|`` over the grid and all inertias, rad/s.
    speed_scale : float
        ``max |w_ref|`` over the grid and all inertias, rad/s.
    speed_error_ratio : float
        ``max_speed_error / speed_scale``.
    same_event_sequence : bool
        Same contact changes (shaft, kind, flank) in the same order.
    max_event_time_diff : float
        Largest difference of matched event times in s (``inf`` when the sequences
        differ, 0 without events).
    n_events : int
        Number of events of the reference.
    """

    max_speed_error: float
    speed_scale: float
    speed_error_ratio: float
    same_event_sequence: bool
    max_event_time_diff: float
    n_events: int

    def passes(self, speed_rtol: float = 1e-7, event_tol: float = 1e-6) -> bool:
        """Whether the speed error ratio and the event times are within the bars.

        Parameters
        ----------
        speed_rtol : float, optional
            Largest allowed :attr:`speed_error_ratio`; default 1e-7.
        event_tol : float, optional
            Largest allowed event-time difference in s; default 1e-6.

        Returns
        -------
        bool
            True when the event sequences agree and both bars hold.
        """
        return (
            self.same_event_sequence
            and self.speed_error_ratio <= speed_rtol
            and self.max_event_time_diff <= event_tol
        )


def reference_simulate(
    drive: DriveChain | TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    law: ShaftLaw | str = "paper",
    initial_state: Sequence[float] | np.ndarray | None = None,
    method: str = "DOP853",
    rtol: float = 1e-10,
    atol: float | Sequence[float] | np.ndarray | None = None,
    max_step: float = np.inf,
    actuator: CurrentLoop | None = None,
) -> ReferenceResult:
    """Reference simulation by adaptive ODE integration with located contact changes.

    Inside one contact configuration the drive is integrated with a scipy Runge-Kutta
    (or implicit) solver; every solver step is scanned for the zero crossings of the
    switching functions of the current configuration, the first one is located by
    Brent's method on the solver's dense output, and the integration restarts from
    there in the new configuration. The integration also restarts at every change of
    the zero-order-hold torque (consecutive equal samples form one segment). States on
    the grid come from the dense output.

    Switching functions, per shaft ``j`` (``theta = theta_j``):

    * ``"paper"``: contact on the positive flank iff ``phi_j >= theta``, on the
      negative one iff ``phi_j <= -theta``.
    * ``"no-pull"``: from the gap, the positive flank closes when both
      ``phi_j - theta >= 0`` and ``k_j (phi_j - theta) + d_j dphi_j/dt >= 0``; it opens
      when the spring-damper torque ``k_j (phi_j - theta) + d_j dphi_j/dt`` falls below
      zero (mirrored for the negative flank).
    * ``"modelica"``: the flanks close and open as under ``"no-pull"``; on a flank the
      branch of ``tau_c + min(tau_c, tau_d)`` changes where ``tau_d = tau_c`` (the
      spring's torque doubled beyond it), located like a contact change.

    An inertia with a breakaway torque ``fs > 0`` (the drive's ``fs``) slips with its
    Coulomb torque ``fc`` against its motion; where its speed crosses zero it sticks
    (speed exactly 0) if the torque on it from motor and shafts is within ``fs``, else
    it slips on the other way; a stuck inertia breaks away where that torque exceeds
    ``fs``. These are located like contact changes and reported as
    :class:`~backlashkit.simulate.FrictionEvent`. With ``actuator`` the motor torque
    is one more state, ``tau_i dT/dt = torque - T``.

    A state exactly on a boundary is resolved from the direction of motion (successive
    Lie derivatives of the switching function), so a restart never re-detects the
    change that caused it.

    Parameters
    ----------
    drive : TwoMassDrive or DriveChain
        The drive (``theta`` set), ``N`` inertias.
    t : array_like
        Strictly increasing time grid in s, at least 2 samples (need not be uniform).
    torque : array_like
        Motor torque in N m, one sample per entry of ``t``, held on ``[t[i], t[i+1])``.
    law : {"paper", "no-pull", "modelica"} or ShaftLaw, optional
        Contact law; default ``"paper"``.
    initial_state : array_like, optional
        State ``[w_1 .. w_N, phi_1 .. phi_{N-1}]`` at ``t[0]``; default rest, twists 0.
    method : {"DOP853", "RK45", "RK23", "Radau", "BDF", "LSODA"}, optional
        scipy solver; default ``"DOP853"``.
    rtol : float, optional
        Relative tolerance; default 1e-10.
    atol : float or array_like, optional
        Absolute tolerance (scalar or per component). Default ``rtol`` times a scale per
        component: for speeds the largest of the initial speeds and the speed the
        torque can reach in the record, for twists the largest of ``theta_j``, the
        initial twist and ``max|torque| / k_j``.
    max_step : float, optional
        Largest solver step in s; default unbounded (the interior scan of each step
        keeps long steps safe).
    actuator : CurrentLoop, optional
        First-order current loop between the torque set-point and the motor torque
        (its initial torque is ``torque[0]`` unless ``initial_state`` gives one more
        entry); default none.

    Returns
    -------
    ReferenceResult
        States and modes on ``t``, contact events, grazes and solver statistics.

    Raises
    ------
    InputError
        Invalid drive, grid, torque, law or initial state.
    RuntimeError
        The solver failed or the contact configuration chatters.
    """
    model, t_arr, u, x0, law_, scale = prepare(drive, t, torque, law, initial_state, actuator)
    options = SolverOptions.build(method, rtol, atol, max_step, scale, model.tau_i)
    trace = run(model, t_arr, u, x0, options)
    return _result(model, trace, t_arr, u, law_, options)


def reference_angles(drive: TwoMassDrive, t: Sequence[float] | np.ndarray,
                     torque: Sequence[float] | np.ndarray, *,
                     substeps: int = ANGLE_SUBSTEPS, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """The motor's and load's angles of a two-mass drive by the reference, for encoders.

    :func:`reference_simulate` runs on a grid ``substeps`` times finer than ``t``
    (uniform), the motor speed is integrated by Simpson's rule, and the load angle is
    the motor's less the change of the shaft's twist (a state, exact).

    Parameters
    ----------
    drive : TwoMassDrive
        The drive (``theta`` set).
    t : array_like
        Uniform time grid in s.
    torque : array_like
        Motor torque in N m on ``t`` (zero-order hold).
    substeps : int, optional
        Reference samples per sample of ``t`` (default :data:`ANGLE_SUBSTEPS`).
    **kwargs
        Passed to :func:`reference_simulate` (``initial_state``, ``actuator``, ...).

    Returns
    -------
    phi_motor, phi_load : numpy.ndarray
        Angles in rad on ``t``, both 0 at ``t[0]``.
    """
    t_arr, ts = v.time_grid(t)
    fine = int(v.integer("substeps", substeps, 1))
    u = np.repeat(v.finite_array("torque", torque), fine)[: (t_arr.size - 1) * fine + 1]
    tf = t_arr[0] + np.arange(u.size) * (ts / fine)
    ref = reference_simulate(drive, tf, u, **kwargs)
    phi_m = integrate.cumulative_simpson(ref.w_motor, x=tf, initial=0.0)
    phi_l = phi_m - (ref.states[:, 2] - ref.states[0, 2])
    return phi_m[::fine], phi_l[::fine]


def _as_event(e) -> ReferenceEvent | FrictionEvent:
    """An event of the model as the reference reports it."""
    if isinstance(e, FrictionEvent):
        return e
    return ReferenceEvent(float(e[0]), int(e[1]), e[2], e[3])


def _result(model, trace, t_arr, u, law_, options) -> ReferenceResult:
    """The reference's result from the engine's trace (the loop torque apart)."""
    n_base = 2 * model.n - 1
    n_grid = t_arr.size
    stuck = None
    if model.sticky:
        stuck = np.zeros((n_grid, model.n), dtype=bool)
        stuck[:, model.sticky] = trace.modes[:, model.n - 1 :] == 0
    return ReferenceResult(
        t=t_arr,
        torque=u,
        states=trace.states[:, :n_base],
        modes=np.sign(trace.modes[:, : model.n - 1]).astype(np.int8),
        events=tuple(_as_event(e) for e in trace.events),
        event_states=np.array(trace.event_states, dtype=float).reshape(-1, model.s),
        grazes=tuple(ReferenceGraze(*g) for g in trace.grazes),
        law=law_,
        method=options.method,
        rtol=float(options.rtol),
        atol=options.atol,
        n_steps=trace.n_steps,
        n_restarts=trace.n_restarts,
        nfev=trace.nfev,
        n_inertias=model.n,
        stuck_array=stuck,
        loop_torque=trace.states[:, n_base].copy() if model.tau_i > 0 else None,
    )


# --------------------------------------------------------------------------- checks


def _event_key(e) -> tuple:
    if isinstance(e, FrictionEvent):
        return ("friction", int(e.inertia), str(e.kind), str(e.direction))
    return (int(e.shaft), str(e.kind), str(e.flank))


def _event_diff(events_a, events_b) -> tuple[bool, float]:
    same = [_event_key(e) for e in events_a] == [_event_key(e) for e in events_b]
    if not same:
        return False, math.inf
    if not events_a:
        return True, 0.0
    ta = np.array([e.time for e in events_a])
    tb = np.array([e.time for e in events_b])
    return True, float(np.max(np.abs(ta - tb)))


def compare_to_reference(response, reference: ReferenceResult) -> AccuracyReport:
    """Speed error and event timing of a simulator response against a reference.

    Parameters
    ----------
    response : DriveResponse or ReferenceResult
        Anything with ``states`` (same grid as the reference) and ``events`` whose
        items have ``time``, ``shaft``, ``kind`` and ``flank``.
    reference : ReferenceResult
        The reference run.

    Returns
    -------
    AccuracyReport
        Maximum speed error (absolute and relative to ``max |w_ref|``) and event
        matching (one-to-one, in order).
    """
    n = reference.n_inertias
    w = np.asarray(response.states)[:, :n]
    w_ref = reference.speeds
    if w.shape != w_ref.shape:
        raise InputError(f"response has speeds of shape {w.shape}, reference {w_ref.shape}")
    err = float(np.max(np.abs(w - w_ref)))
    scale = float(np.max(np.abs(w_ref)))
    same, dt = _event_diff(tuple(response.events), reference.events)
    return AccuracyReport(
        max_speed_error=err,
        speed_scale=scale,
        speed_error_ratio=err / scale if scale > 0 else (0.0 if err == 0 else math.inf),
        same_event_sequence=same,
        max_event_time_diff=dt,
        n_events=len(reference.events),
    )


def check_conditioning(
    drive: DriveChain | TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    law: ShaftLaw | str = "paper",
    initial_state: Sequence[float] | np.ndarray | None = None,
    runs: Sequence[tuple[str, float]] = (("DOP853", 1e-12), ("DOP853", 1e-13)),
    event_tol: float = 1e-7,
    speed_rtol: float = 1e-8,
) -> ConditioningReport:
    """Judge whether a case is well-conditioned by running two different references.

    Two tight references that differ in tolerance (or method) must agree on a
    well-conditioned case. Near a grazing contact a perturbation of the order of the
    solver error decides whether an impact happens, and the two runs part ways; such a
    case says nothing about a simulator and must be excluded from accuracy comparisons
    (not compared with a looser tolerance).

    Parameters
    ----------
    drive, t, torque, law, initial_state
        As for :func:`reference_simulate`.
    runs : sequence of two (method, rtol) pairs, optional
        The two references; default DOP853 at ``rtol = 1e-12`` and at ``1e-13``. The
        last one is returned as :attr:`ConditioningReport.reference`.
    event_tol : float, optional
        Largest allowed difference of matching event times, s; default 1e-7.
    speed_rtol : float, optional
        Largest allowed ``max |w_a - w_b| / max |w_b|``; default 1e-8.

    Returns
    -------
    ConditioningReport
        Agreement flag, the differences and both runs.
    """
    if len(runs) != 2:
        raise InputError("runs must name exactly two (method, rtol) references")
    (m_a, r_a), (m_b, r_b) = runs
    kw = dict(law=law, initial_state=initial_state)
    check = reference_simulate(drive, t, torque, method=m_a, rtol=r_a, **kw)
    ref = reference_simulate(drive, t, torque, method=m_b, rtol=r_b, **kw)
    same, dt = _event_diff(check.events, ref.events)
    scale = float(np.max(np.abs(ref.speeds)))
    dw = float(np.max(np.abs(check.speeds - ref.speeds)))
    rel = dw / scale if scale > 0 else (0.0 if dw == 0 else math.inf)
    reasons = []
    if not same:
        reasons.append(
            f"event sequences differ ({len(check.events)} vs {len(ref.events)} events)"
        )
    elif dt > event_tol:
        reasons.append(f"event times differ by {dt:.3g} s > {event_tol:.3g} s")
    if rel > speed_rtol:
        reasons.append(f"speeds differ by {rel:.3g} (relative) > {speed_rtol:.3g}")
    return ConditioningReport(
        well_conditioned=not reasons,
        same_event_sequence=same,
        max_event_time_diff=dt,
        max_speed_rel_diff=rel,
        reasons=tuple(reasons),
        reference=ref,
        check=check,
    )


def naive_simulate(
    drive: DriveChain | TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    law: ShaftLaw | str = "paper",
    initial_state: Sequence[float] | np.ndarray | None = None,
    method: str = "RK45",
    rtol: float = 1e-8,
    atol: float | None = None,
) -> np.ndarray:
    """The drive integrated by :func:`scipy.integrate.solve_ivp` WITHOUT event location.

    The contact law is evaluated inside the right-hand side from the state (as a
    generic ODE user would write it), so the solver steps over the switches; it only
    restarts at changes of the input torque. The switches cut the order of the method
    to one, which is what the event-located :func:`reference_simulate` avoids.

    Parameters
    ----------
    drive, t, torque, law, initial_state
        As for :func:`reference_simulate`.
    method : str, optional
        ``solve_ivp`` method; default ``"RK45"``.
    rtol : float, optional
        Relative tolerance; default 1e-8.
    atol : float, optional
        Absolute tolerance; default ``rtol`` times the component scales of
        :func:`reference_simulate`.

    Returns
    -------
    numpy.ndarray
        States on ``t``, shape ``(n, 2N - 1)``.
    """
    model, t_arr, u, x0, law_, scale = prepare(drive, t, torque, law, initial_state)
    out = np.empty((t_arr.size, model.s))
    out[0] = x0
    x = x0
    tol = rtol * scale if atol is None else atol
    for i0, i1 in zip(*segments(u), strict=True):
        sol = integrate.solve_ivp(_naive_rhs, (t_arr[i0], t_arr[i1]), x, method=method,
                                  rtol=rtol, atol=tol, t_eval=t_arr[i0 : i1 + 1],
                                  args=(float(u[i0]), model, law_))
        if sol.status != 0:
            raise RuntimeError(sol.message)
        out[i0 : i1 + 1] = sol.y.T
        x = sol.y[:, -1]
    return out


def _naive_rhs(_t, x: np.ndarray, ui: float, model: ReferenceModel, law: ShaftLaw) -> np.ndarray:
    """Right-hand side with the contact law evaluated from the state (no modes)."""
    n = model.n
    k, d, theta = model.k, model.d, model.theta
    w, phi = x[:n], x[n:]
    dphi = w[:-1] - w[1:]
    pos = k * (phi - theta) + d * dphi
    neg = k * (phi + theta) + d * dphi
    if law is ShaftLaw.PAPER:
        torq = np.where(phi >= theta, pos, np.where(phi <= -theta, neg, 0.0))
    else:
        torq = np.where(phi >= theta, np.maximum(pos, 0.0),
                        np.where(phi <= -theta, np.minimum(neg, 0.0), 0.0))
    load = -model.f * w
    load[0] += ui
    load[:-1] -= torq
    load[1:] += torq
    return np.concatenate([load / model.J, dphi])
