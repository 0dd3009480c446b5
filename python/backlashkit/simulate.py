"""Event-accurate simulation of drive trains with backlash.

The drive is piecewise affine: inside each contact configuration (every shaft either
in its gap, on its positive flank or on its negative flank) it is a linear
time-invariant system, so with a zero-order-hold input its flow over one sample has a
closed form (a matrix exponential). The compiled kernel advances the state sample by
sample with that closed form and, whenever a contact changes inside a sample, locates
the switching instant inside the sample (to about 1e-15 of the sample time) from the
Taylor expansion of the flow, switches the dynamics there, and finishes the sample.
Nothing is rounded to the grid, so the result is exact up to floating-point error.

A near-grazing contact (the twist comes within a hair of a flank with almost no
relative speed) makes the trajectory ill-conditioned; the kernel records every such
pass in :attr:`DriveResponse.near_grazing` and warns with
:class:`~backlashkit.errors.SensitivityWarning`.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, NamedTuple

import numpy as np

from . import validate as v
from .errors import InputError, SensitivityWarning
from .laws import ShaftLaw
from .response import ContactEvent, DriveResponse, FrictionEvent, NearGrazing

if TYPE_CHECKING:
    from .actuator import CurrentLoop
    from .plants import DriveChain, TwoMassDrive

__all__ = [
    "ContactEvent",
    "DriveResponse",
    "FrictionEvent",
    "NearGrazing",
    "PackedRun",
    "PackedRuns",
    "Sensitivity",
    "assess_sensitivity",
    "simulate_batch",
    "simulate_drive",
    "simulate_packed",
    "simulate_packed_runs",
]

Backend = Literal["rust", "numpy"]

def _as_chain(drive: DriveChain | TwoMassDrive) -> DriveChain:
    to_chain = getattr(drive, "to_chain", None)
    if to_chain is None:
        raise InputError(
            f"drive must be a TwoMassDrive or a DriveChain, got {type(drive).__name__}"
        )
    return to_chain()


def _initial_state(chain: DriveChain, initial_state, loop: bool = False) -> np.ndarray:
    """The initial state: ``2N - 1`` entries, and with a current loop optionally the
    motor torque as one more (``nan`` until filled in with the first set-point)."""
    if initial_state is None:
        x0 = np.zeros(chain.n_states)
    else:
        x0 = v.finite_array("initial_state", initial_state)
    if x0.size == chain.n_states + 1 and loop:
        return x0
    if x0.size != chain.n_states:
        n = chain.n_inertias
        names = ([f"w_{i}" for i in range(1, n + 1)] + [f"phi_{i}" for i in range(1, n)]
                 if n <= 3 else [f"w_1..w_{n}", f"phi_1..phi_{n - 1}"])
        extra = " (and optionally the motor torque, with a current loop)" if loop else ""
        raise InputError(
            f"initial_state must have {chain.n_states} entries [{', '.join(names)}]{extra}, "
            f"got {x0.size}"
        )
    return np.append(x0, np.nan) if loop else x0


def _actuator(actuator) -> CurrentLoop | None:
    if actuator is None:
        return None
    if not hasattr(actuator, "tau_i"):
        raise InputError(
            f"actuator must be a CurrentLoop or None, got {type(actuator).__name__}"
        )
    return None if actuator.tau_i == 0 else actuator


def _kernel_args(chain: DriveChain, actuator: CurrentLoop | None, positions: bool) -> dict:
    """Keyword arguments of the kernels beyond paper A's model (none for it, so its
    runs take exactly the historical path)."""
    kw: dict = {}
    if chain.has_friction:
        kw.update(fc=np.asarray(chain.fc, float), fs=np.asarray(chain.fs, float))
    if actuator is not None:
        kw["tau_i"] = actuator.tau_i
    if positions:
        kw["track_angle"] = True
    return kw


def _kernel(backend: Backend):
    if backend == "rust":
        from . import _core

        return _core
    if backend == "numpy":
        from . import _numpy_kernels

        return _numpy_kernels
    raise InputError(f"backend must be 'rust' or 'numpy', got {backend!r}")


def _response(chain, t, torque, law, raw, actuator=None, positions=False) -> DriveResponse:
    states, modes, ev, gr = raw
    if len(gr):
        time, shaft, margin = gr[0]
        warnings.warn(
            f"the simulation passed within {abs(margin):.3g} (relative) of a grazing "
            f"contact or stop (switch {int(shaft)}, t = {time:.6g} s; {len(gr)} such "
            "pass(es)): what happens after it is sensitive to tiny changes of the inputs "
            "and parameters; see response.near_grazing",
            SensitivityWarning,
            stacklevel=3,
        )
    n_base, n_shafts = chain.n_states, chain.n_inertias - 1
    extra = states[:, n_base:]
    loop_torque = extra[:, 0].copy() if actuator is not None else None
    angle = extra[:, -1].copy() if positions else None
    friction = modes[:, n_shafts:] if chain.has_friction else None
    return DriveResponse(
        t=t,
        torque=torque,
        states=states[:, :n_base] if states.shape[1] > n_base else states,
        modes=modes[:, :n_shafts] if modes.shape[1] > n_shafts else modes,
        event_array=ev,
        graze_array=gr,
        law=law,
        drive=chain,
        friction_modes=friction,
        loop_torque=loop_torque,
        angle=angle,
        actuator=actuator,
    )


def _check_inputs(drive, t, torque, law, initial_state, actuator=None):
    chain = _as_chain(drive)
    t_arr, ts = v.time_grid(t)
    u = v.finite_array("torque", torque)
    if u.shape != t_arr.shape:
        raise InputError(f"torque must have one sample per time step ({t_arr.size}), got {u.size}")
    act = _actuator(actuator)
    x0 = _initial_state(chain, initial_state, loop=act is not None)
    if act is not None and np.isnan(x0[-1]):
        x0[-1] = u[0]  # the loop settled at the first set-point
    return chain, t_arr, ts, u, ShaftLaw.parse(law), x0, act


def simulate_drive(
    drive: DriveChain | TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    law: ShaftLaw | str = "paper",
    initial_state: Sequence[float] | np.ndarray | None = None,
    backend: Backend = "rust",
    actuator: CurrentLoop | None = None,
    positions: bool = False,
) -> DriveResponse:
    """Simulate a drive with backlash under a zero-order-hold motor torque.

    Coulomb and static friction of the drive (``fc``, ``fs``) are simulated as modes:
    a sticking inertia has a zero speed row, and sticking, breakaway and reversal are
    located inside the sample like contact changes.

    Parameters
    ----------
    drive : TwoMassDrive or DriveChain
        The drive; its ``theta`` must be set.
    t : array_like
        Uniform, strictly increasing time grid in s, at least 2 samples.
    torque : array_like
        Motor torque (set-point, with an actuator) in N m, one sample per entry of
        ``t``, held constant over ``[t[i], t[i+1])`` (the last sample is not used).
    law : {"paper", "no-pull", "modelica"} or ShaftLaw, optional
        Contact law of the shafts; default ``"paper"`` (paper A, eq. 2).
    initial_state : array_like, optional
        State at ``t[0]``: ``[w_M, w_L, phi_d]`` for a two-mass drive. Default: rest,
        twist 0 (the middle of the gap). Use ``drive.steady_state(torque)`` to start
        from a steady state. With a current loop one more entry may give the initial
        motor torque; by default it is ``torque[0]`` (the loop settled).
    backend : {"rust", "numpy"}, optional
        ``"rust"`` (default) is the compiled kernel; ``"numpy"`` its plain-NumPy
        reference (same algorithm, about 100 times slower), for verification.
    actuator : CurrentLoop, optional
        First-order current loop between set-point and motor torque, simulated exactly
        (the motor torque is one more state). Default none: the torque is exact.
    positions : bool, optional
        Track the absolute motor angle as one more state of this run
        (:attr:`DriveResponse.phi_motor`); default False, in which case the angles are
        computed by a second run when first asked for.

    Returns
    -------
    DriveResponse
        States, contact modes and events on the grid ``t``.

    Warns
    -----
    SensitivityWarning
        When the run passes close to a grazing contact (see
        :attr:`DriveResponse.near_grazing`).
    """
    chain, t_arr, ts, u, law_, x0, act = _check_inputs(
        drive, t, torque, law, initial_state, actuator
    )
    if positions:
        x0 = np.append(x0, 0.0)  # the motor angle, 0 at t[0]
    raw = _kernel(backend).simulate_chain(
        np.asarray(chain.J),
        np.asarray(chain.f),
        np.asarray(chain.k),
        np.asarray(chain.d),
        np.asarray(chain.theta),
        law_.code,
        float(t_arr[0]),
        ts,
        u,
        x0,
        **_kernel_args(chain, act, positions),
    )
    return _response(chain, t_arr, u, law_, raw, act, positions)


def simulate_batch(
    drives: Sequence[DriveChain | TwoMassDrive],
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    law: ShaftLaw | str = "paper",
    initial_state: Sequence[float] | np.ndarray | None = None,
    workers: int | None = None,
    actuator: CurrentLoop | None = None,
    positions: bool = False,
) -> list[DriveResponse]:
    """Simulate many drives in parallel (compiled kernel, the GIL released).

    Parameters
    ----------
    drives : sequence of TwoMassDrive or DriveChain
        The drives, all with the same number of inertias (e.g. one drive per value of
        a ``theta`` grid).
    t : array_like
        Uniform time grid in s shared by all runs.
    torque : array_like
        Motor torque (set-point, with an actuator) in N m: shape ``(n,)`` shared by
        all runs, or ``(len(drives), n)``.
    law : {"paper", "no-pull", "modelica"} or ShaftLaw, optional
        Contact law, default ``"paper"``.
    initial_state : array_like, optional
        Shape ``(2N - 1,)`` shared, or ``(len(drives), 2N - 1)``; default rest. With a
        current loop each row may hold the motor torque as one more entry; by default
        it is the run's first set-point (the loop settled).
    workers : int, optional
        Number of threads; default all cores. The result does not depend on it.
    actuator : CurrentLoop, optional
        One current loop between set-point and motor torque for every run, as in
        :func:`simulate_drive`; default none.
    positions : bool, optional
        Track the absolute motor angle in every run (:attr:`DriveResponse.phi_motor`),
        as in :func:`simulate_drive`; default False.

    Returns
    -------
    list of DriveResponse
        One response per drive, in order; each the same as :func:`simulate_drive`'s of
        that drive.
    """
    from . import _core

    chains, t_arr, ts, law_, u = _batch_inputs(drives, t, torque, law)
    act = _actuator(actuator)
    x0 = _batch_initial_states(chains, initial_state, u, act is not None)
    if positions:
        x0 = np.column_stack([x0, np.zeros(len(chains))])
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    params = np.array([np.concatenate([c.J, c.f, c.k, c.d, c.theta]) for c in chains])
    if act is not None or any(c.has_friction for c in chains):  # the packed layout's tail
        tau_i = 0.0 if act is None else act.tau_i
        tail = np.array([np.concatenate([c.fc, c.fs, [tau_i]]) for c in chains])
        params = np.hstack([params, tail])
    states, modes, events = _core.simulate_chain_batch(
        chains[0].n_inertias, params, law_.code, float(t_arr[0]), ts, u,
        np.ascontiguousarray(x0), workers or 0, positions
    )
    return [
        _response(c, t_arr, u[i if u.shape[0] > 1 else 0], law_, (states[i], modes[i], *events[i]),
                  act, positions)
        for i, c in enumerate(chains)
    ]


def _batch_inputs(drives, t, torque, law):
    """:func:`simulate_batch`'s drives as chains, its grid, law and torque rows, checked."""
    if hasattr(drives, "to_chain"):  # one drive where a sequence is expected
        raise InputError(f"drives must be a sequence of drives, got one {type(drives).__name__}"
                         ": pass [drive], or call drive.simulate(t, torque)")
    chains = [_as_chain(d) for d in drives]
    if not chains:
        raise InputError("drives must contain at least one drive")
    b = len(chains)
    if any(c.n_inertias != chains[0].n_inertias for c in chains):
        raise InputError("drives must all have the same number of inertias")
    t_arr, ts = v.time_grid(t)
    law_ = ShaftLaw.parse(law)
    u = np.asarray(torque, dtype=np.float64)
    if u.ndim == 1:
        u = v.finite_array("torque", u)[np.newaxis, :]  # one row shared by every run
    else:
        u = v.finite_array("torque", u, ndim=2)
    if u.shape[1] != t_arr.size or u.shape[0] not in (1, b):
        raise InputError(
            f"torque must have shape ({t_arr.size},) or ({b}, {t_arr.size}), got {np.shape(torque)}"
        )
    return chains, t_arr, ts, law_, np.ascontiguousarray(u)


def _batch_initial_states(chains, initial_state, u: np.ndarray, loop: bool) -> np.ndarray:
    """:func:`simulate_batch`'s initial states, one row per run: ``2N - 1`` entries, and
    with a current loop the motor torque (given, or the run's first set-point)."""
    b, n_states = len(chains), chains[0].n_states
    x0 = (np.zeros(n_states) if initial_state is None
          else np.atleast_1d(np.asarray(initial_state, float)))
    x0 = np.broadcast_to(x0, (b, x0.shape[-1])) if x0.ndim == 1 else x0
    x0 = v.finite_array("initial_state", x0, ndim=2)
    widths = (n_states, n_states + 1) if loop else (n_states,)
    if x0.shape[0] != b or x0.shape[1] not in widths:
        extra = " (and optionally the motor torque, with a current loop)" if loop else ""
        raise InputError(
            f"initial_state must have shape ({n_states},) or ({b}, {n_states}){extra}, "
            f"got {np.shape(initial_state)}"
        )
    if loop and x0.shape[1] == n_states:  # the loop settled at each run's first set-point
        x0 = np.column_stack([x0, np.broadcast_to(u[:, 0], (b,))])
    return np.array(x0, float)


def simulate_packed(
    n_inertias: int,
    params: np.ndarray,
    t0: float,
    ts: float,
    torque: np.ndarray,
    x0: np.ndarray,
    *,
    law: ShaftLaw | str,
    workers: int | None,
    track_angle: bool = False,
) -> np.ndarray:
    """States of a batch, shape ``(len(params), n, S)``: the kernel without wrappers.

    For the estimators' inner loops, which simulate thousands of parameter vectors.
    Nothing is validated here but by the kernel (``ValueError``).

    Parameters
    ----------
    n_inertias : int
        Number of inertias ``N`` of every chain.
    params : numpy.ndarray
        One row per chain, packed ``[J, f, k, d, theta]`` (the fields of a
        :class:`DriveChain`), optionally followed by ``[fc, fs, tau_i]``.
    t0 : float
        Time of the first sample in s.
    ts : float
        Sample time in s.
    torque : numpy.ndarray
        Motor torque in N m, shape ``(1, n)`` (shared) or ``(b, n)``.
    x0 : numpy.ndarray
        Initial states, shape ``(b, S)``.
    law : ShaftLaw or str
        Contact law.
    workers : int or None
        Number of threads; None uses all cores.
    track_angle : bool, optional
        Whether the state ends with the motor's angle in rad, integrated exactly (its
        initial value is the last column of ``x0``).

    Returns
    -------
    numpy.ndarray
        States of every run, shape ``(b, n, S)``: ``S = 2N - 1``, one more with a
        current loop (the motor torque), one more with ``track_angle``.
    """
    return simulate_packed_runs(n_inertias, params, t0, ts, torque, x0, law=law,
                                workers=workers, track_angle=track_angle).states


class PackedRun(NamedTuple):
    """One run of :func:`simulate_packed_runs`: what the compiled sensitivities need to
    follow it without simulating it again
    (:func:`backlashkit._sensitivity.sensitivities_along`).

    Parameters
    ----------
    t0 : float
        Time of the first sample in s.
    ts : float
        Sample time in s.
    torque : numpy.ndarray
        Motor torque in N m, ``(n,)``.
    states : numpy.ndarray
        ``(n, S)``, as :func:`simulate_packed`.
    first_modes : numpy.ndarray
        The first sample's modes (int8): each shaft's contact, then each inertia's
        friction switch.
    events : numpy.ndarray
        ``(E, 4)``: ``[time in s, switch, from, to]`` of every change of mode.
    """

    t0: float
    ts: float
    torque: np.ndarray
    states: np.ndarray
    first_modes: np.ndarray
    events: np.ndarray


class PackedRuns(NamedTuple):
    """A batch of :func:`simulate_packed_runs`.

    Parameters
    ----------
    t0 : float
        Time of the first sample in s.
    ts : float
        Sample time in s.
    torque : numpy.ndarray
        Motor torque in N m, ``(1, n)`` (shared) or ``(b, n)``.
    states : numpy.ndarray
        ``(b, n, S)``, as :func:`simulate_packed`.
    modes : numpy.ndarray
        ``(b, n, M)`` (int8): each sample's modes, as :class:`PackedRun`'s first.
    events : list of numpy.ndarray
        Each run's changes of mode, ``(E, 4)`` as :class:`PackedRun`'s.
    """

    t0: float
    ts: float
    torque: np.ndarray
    states: np.ndarray
    modes: np.ndarray
    events: list[np.ndarray]

    def run(self, i: int) -> PackedRun:
        """Run ``i`` alone.

        Parameters
        ----------
        i : int
            Index of the run in the batch.

        Returns
        -------
        PackedRun
            Its grid, torque, states, first modes and changes (views, not copies).
        """
        u = self.torque[i if self.torque.shape[0] > 1 else 0]
        return PackedRun(self.t0, self.ts, u, self.states[i], self.modes[i, 0],
                         self.events[i])


def simulate_packed_runs(
    n_inertias: int,
    params: np.ndarray,
    t0: float,
    ts: float,
    torque: np.ndarray,
    x0: np.ndarray,
    *,
    law: ShaftLaw | str,
    workers: int | None,
    track_angle: bool = False,
) -> PackedRuns:
    """As :func:`simulate_packed`, with each run's modes and changes of mode: a run the
    compiled sensitivities may follow afterwards.

    Parameters
    ----------
    n_inertias, params, t0, ts, torque, x0, law, workers, track_angle
        As :func:`simulate_packed`.

    Returns
    -------
    PackedRuns
        The grid, the torque, the states ``(b, n, S)``, the modes and each run's
        changes; ``.run(i)`` gives run ``i`` alone.
    """
    from . import _core

    torque = np.ascontiguousarray(torque, float)
    states, modes, events = _core.simulate_chain_batch(
        n_inertias, np.ascontiguousarray(params, float), ShaftLaw.parse(law).code,
        float(t0), float(ts), torque, np.ascontiguousarray(x0, float), workers or 0,
        track_angle,
    )
    return PackedRuns(float(t0), float(ts), torque, states, modes, [e for e, _ in events])


@dataclass(frozen=True)
class Sensitivity:
    """How much a simulation's result depends on rounding (see :func:`assess_sensitivity`).

    Parameters
    ----------
    speed_rel_diff : float
        Largest difference of any speed between the two runs, relative to the largest
        speed magnitude.
    event_time_diff : float
        Largest difference of matching contact-change times in s (``inf`` when the
        sequences of contact changes differ).
    same_events : bool
        Whether both runs have the same sequence of contact changes.
    sensitive : bool
        Whether the differences exceed the thresholds the check was run with: the result
        after the first divergence is not determined by the inputs to working precision.
    """

    speed_rel_diff: float
    event_time_diff: float
    same_events: bool
    sensitive: bool


def assess_sensitivity(
    drive: DriveChain | TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    law: ShaftLaw | str = "paper",
    initial_state: Sequence[float] | np.ndarray | None = None,
    refine: int = 7,
    speed_rtol: float = 1e-8,
    event_atol: float = 1e-7,
) -> Sensitivity:
    """Check whether a simulation is ill-conditioned, by running it twice.

    The same experiment is simulated on ``t`` and on a grid ``refine`` times finer
    carrying the same zero-order-hold torque. In exact arithmetic both give the same
    trajectory, so any difference is rounding amplified by the dynamics: near-grazing
    contacts (see :attr:`DriveResponse.near_grazing`) and long trains of impacts can
    amplify it until the contact sequence itself changes. Costs about ``refine + 1``
    simulations.

    Parameters
    ----------
    drive : TwoMassDrive or DriveChain
        The drive.
    t : array_like
        Uniform time grid in s.
    torque : array_like
        Motor torque in N m on ``t`` (zero-order hold).
    law : {"paper", "no-pull", "modelica"} or ShaftLaw, optional
        Contact law, default ``"paper"``.
    initial_state : array_like, optional
        State at ``t[0]``; default rest.
    refine : int, optional
        Subdivision of the second run's grid, >= 2 (default 7).
    speed_rtol : float, optional
        Relative speed difference above which the run counts as sensitive.
    event_atol : float, optional
        Contact-time difference in s above which the run counts as sensitive.

    Returns
    -------
    Sensitivity
        The differences and the verdict.
    """
    if not isinstance(refine, int) or refine < 2:
        raise InputError(f"refine must be an integer >= 2, got {refine!r}")
    chain, t_arr, ts, u, law_, x0, _ = _check_inputs(drive, t, torque, law, initial_state)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SensitivityWarning)
        coarse = simulate_drive(chain, t_arr, u, law=law_, initial_state=x0)
        t_fine = t_arr[0] + np.arange((t_arr.size - 1) * refine + 1) * (ts / refine)
        u_fine = np.append(np.repeat(u[:-1], refine), u[-1])
        fine = simulate_drive(chain, t_fine, u_fine, law=law_, initial_state=x0)
    n = chain.n_inertias
    speeds = coarse.states[:, :n]
    scale = max(float(np.abs(speeds).max()), np.finfo(float).tiny)
    speed_diff = float(np.abs(fine.states[::refine, :n] - speeds).max()) / scale
    # An event's identity is everything but its time (shaft or inertia, kind, side).
    key = [dataclasses.astuple(e)[1:] for e in coarse.events]
    same = key == [dataclasses.astuple(e)[1:] for e in fine.events]
    if not same:
        event_diff = float("inf")
    elif key:
        event_diff = max(
            abs(a.time - b.time) for a, b in zip(coarse.events, fine.events, strict=True)
        )
    else:
        event_diff = 0.0
    sensitive = not same or speed_diff > speed_rtol or event_diff > event_atol
    return Sensitivity(speed_diff, event_diff, same, sensitive)
