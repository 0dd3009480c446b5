"""Forward sensitivities of a two-mass drive with backlash, compiled (issue 24).

The compiled twin of :mod:`backlashkit._numpy_sensitivity` (``crates/core``'s
``sensitivity`` module): the same recurrence, with the contact and stick-slip changes
the compiled simulator locates. :func:`backlashkit.identify.cramer_rao_bound` uses
them, for its estimated parameters only, where its model is theirs, and so do the
joint fit's iterations, uncertainty and profile refits
(``identify._problem.Residual.exact_jacobian``).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from . import validate as v
from .actuator import CurrentLoop
from .errors import InputError, SensitivityWarning
from .plants import TwoMassDrive
from .simulate import PackedRun

#: The parameters a sensitivity may be taken with respect to, in the kernel's order:
#: paper A's model, then the Coulomb torques (the breakaway torques tied to them), then
#: the current loop's time constant.
PARAMS = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh", "theta", "fc_M", "fc_L", "tau_i")
#: Paper A's model: the parameters of every drive's sensitivities.
LINEAR_AND_THETA = PARAMS[:7]
#: The Coulomb torques: a sensitivity to one needs it positive.
COULOMB = ("fc_M", "fc_L")
#: The kernel's state: the speeds, the twist, and behind a current loop the motor torque
#: (a run along the simulator's that tracks the motor's angle carries it last).
STATES = ("w_M", "w_L", "phi", "T")


def default_params(drive: TwoMassDrive, actuator: CurrentLoop | None = None
                   ) -> tuple[str, ...]:
    """The parameters whose sensitivities exist for ``drive`` (behind ``actuator``):
    paper A's seven, each Coulomb torque that is positive (at 0 the inertia has no
    friction switch, and the derivative is one-sided), and the current loop's
    ``tau_i`` where there is one."""
    loop = ("tau_i",) if actuator is not None and not actuator.exact else ()
    return (*LINEAR_AND_THETA, *(n for n in COULOMB if getattr(drive, n) > 0), *loop)


def sensitivities(
    drive: TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    initial_state: Sequence[float] | np.ndarray | None = None,
    initial_sensitivity: np.ndarray | None = None,
    states: bool = False,
    params: Sequence[str] | None = None,
    actuator: CurrentLoop | None = None,
) -> np.ndarray:
    """Derivatives of ``(w_M, w_L)`` at ``t`` with respect to ``params``.

    Parameters
    ----------
    drive : TwoMassDrive
        With ``theta > 0``, and Coulomb friction whose breakaway torque is the Coulomb
        torque (``fs_M`` None or ``fc_M``, and so for the load) or none; paper A's
        contact law.
    t : array_like
        Uniform, strictly increasing time grid in s.
    torque : array_like
        Motor torque in N m (the current loop's set-point behind one), one sample per
        entry of ``t``, held over the sample.
    initial_state : array_like, optional
        ``[w_M, w_L, phi]`` at ``t[0]`` (``[w_M, w_L, phi, T]`` behind a current loop,
        ``T`` the motor torque in N m); default rest (behind a loop with ``T`` at
        ``torque[0]``, as the simulator's default).
    initial_sensitivity : array_like, optional
        ``d x / d p`` at ``t[0]``, ``(n, len(params))`` (``n`` the state's size, the
        twist's row included), in the parameters' SI units: where the run continues
        another (a held torque's) or starts from a state that moves with the
        parameters; default zero.
    states : bool, optional
        Return the twist's (and the motor torque's) sensitivity too; default False.
    params : sequence of str, optional
        The parameters, distinct names of :data:`PARAMS` in the order wanted, a Coulomb
        torque only where it is positive, ``tau_i`` only behind a current loop;
        default :func:`default_params`. The kernel carries only these (each adds work
        per sample).
    actuator : CurrentLoop, optional
        The current loop between the torque set-point and the motor (default none).

    Returns
    -------
    numpy.ndarray
        ``(len(t), 2, len(params))`` (``(len(t), n, len(params))`` with ``states``):
        ``d x / d p`` in the parameters' SI units, as
        :func:`backlashkit._numpy_sensitivity.sensitivities`.

    Raises
    ------
    InputError
        For a drive without ``theta``, with a breakaway torque other than its Coulomb
        torque, mismatched inputs, an unknown or repeated parameter, a Coulomb torque
        wanted where it is 0, or ``tau_i`` without a current loop.
    ValueError
        From the kernel: invalid parameters, or a contact change that grazes a flank.

    Warns
    -----
    SensitivityWarning
        When the run passes close to a grazing contact, as the simulator warns: after
        it the sensitivities are ill-conditioned.
    """
    out = trajectory_and_sensitivities(drive, t, torque, initial_state=initial_state,
                                       initial_sensitivity=initial_sensitivity,
                                       params=params, actuator=actuator)[1]
    return out if states else out[:, :2, :]


def trajectory_and_sensitivities(
    drive: TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    initial_state: Sequence[float] | np.ndarray | None = None,
    initial_sensitivity: np.ndarray | None = None,
    params: Sequence[str] | None = None,
    actuator: CurrentLoop | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The states ``(len(t), n)`` (``w_M``, ``w_L`` in rad/s, the twist in rad, and
    behind a current loop the motor torque in N m) and their sensitivities ``(len(t),
    n, len(params))``, from one run.

    The kernel simulates the drive first (it walks along the located contact
    changes), and these are that simulation's states, so a caller needing both pays
    for one run. Arguments, errors and warnings as :func:`sensitivities`.
    """
    from . import _core

    names = check_scope(drive, params, actuator)
    p = _param_values(drive, actuator)
    t0, ts, u, x0 = _grid_and_start(t, torque, initial_state, state_count(p))
    s0 = _checked_sensitivity(initial_sensitivity, x0.size, len(names))
    x, out, grazes = _core.drive_sensitivities(p, t0, ts, u, x0,
                                               [PARAMS.index(n) for n in names], s0)
    _warn_near_grazing(grazes)
    return x, out


def trajectory_and_information(
    drive: TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    initial_state: Sequence[float] | np.ndarray | None = None,
    initial_sensitivity: np.ndarray | None = None,
    params: Sequence[str] | None = None,
    actuator: CurrentLoop | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The states ``(len(t), n)`` and the sums ``G_c = sum_k s_c(k) s_c(k)^T`` of the
    outer products of each speed's sensitivities ``s_c`` (``w_M``, then ``w_L``),
    ``(2, len(params), len(params))`` in the parameters' SI units, from one run.

    The products that white noise's Fisher information weighs
    (``G_M / s_M^2 + G_L / s_L^2``), summed in the kernel as it walks: the
    sensitivities themselves are never written out. The same values as the products
    of :func:`trajectory_and_sensitivities`'s, to rounding (the order of the sums).
    Arguments, errors and warnings as :func:`sensitivities`.
    """
    from . import _core

    names = check_scope(drive, params, actuator)
    p = _param_values(drive, actuator)
    t0, ts, u, x0 = _grid_and_start(t, torque, initial_state, state_count(p))
    s0 = _checked_sensitivity(initial_sensitivity, x0.size, len(names))
    x, gram, grazes = _core.drive_information(p, t0, ts, u, x0,
                                              [PARAMS.index(n) for n in names], s0)
    _warn_near_grazing(grazes)
    return x, gram


def _grid_and_start(t, torque, initial_state, n_states: int
                    ) -> tuple[float, float, np.ndarray, np.ndarray]:
    """The kernel's start time, sample time, torques and initial state (of
    ``n_states`` entries), checked."""
    t_arr, ts = v.time_grid(t)
    u = v.finite_array("torque", torque)
    if u.shape != t_arr.shape:
        raise InputError(f"torque must have one sample per time step ({t_arr.size}), "
                         f"got {u.size}")
    if initial_state is None:  # rest; behind a loop, settled at the first set-point
        x0 = np.zeros(n_states)
        if n_states == len(STATES):
            x0[-1] = u[0]
    else:
        x0 = v.finite_array("initial_state", initial_state)
    if x0.shape != (n_states,):
        raise InputError(f"initial_state must hold the {n_states} states "
                         f"({', '.join(STATES[:n_states])}), got shape {x0.shape}")
    return float(t_arr[0]), ts, u, np.ascontiguousarray(x0)


def _checked_sensitivity(initial_sensitivity, n_states: int, m: int) -> np.ndarray | None:
    """The initial sensitivity ``(n_states, m)`` (states by parameters), checked; None:
    zero."""
    if initial_sensitivity is None:
        return None
    s0 = v.finite_array("initial_sensitivity", initial_sensitivity, ndim=2)
    if s0.shape != (n_states, m):
        raise InputError(f"initial_sensitivity must have shape ({n_states}, {m}) "
                         f"(states by parameters), got {s0.shape}")
    return np.ascontiguousarray(s0)


def _param_values(drive: TwoMassDrive, actuator: CurrentLoop | None) -> np.ndarray:
    """The values of :data:`PARAMS`, in order: the drive's, then the loop's ``tau_i``
    (0 without one)."""
    tau_i = 0.0 if actuator is None else actuator.tau_i
    return np.array([*(getattr(drive, n) for n in PARAMS[:-1]), tau_i], float)


def state_count(p: np.ndarray) -> int:
    """The size of the kernel's state for parameter values ``p``: 3, or 4 behind a
    current loop (``tau_i > 0``)."""
    return len(STATES) if p[-1] > 0 else len(STATES) - 1


def _warn_near_grazing(grazes: np.ndarray) -> None:
    """A :class:`SensitivityWarning` where the run passed near a grazing contact."""
    if len(grazes):
        time, _, margin = grazes[0]
        warnings.warn(
            f"the run passed within {abs(margin):.3g} (relative) of a grazing contact "
            f"(t = {time:.6g} s; {len(grazes)} such pass(es)): the sensitivities after it "
            "are ill-conditioned (the derivative barely exists there)",
            SensitivityWarning, stacklevel=4)


def sensitivities_along(
    drive: TwoMassDrive,
    run: PackedRun,
    *,
    initial_sensitivity: np.ndarray | None = None,
    params: Sequence[str] | None = None,
    out: np.ndarray | None = None,
    actuator: CurrentLoop | None = None,
) -> np.ndarray:
    """The sensitivities ``(n, s, len(params))`` of the ``s`` states along ``run``, the
    simulator's run of ``drive`` behind ``actuator``
    (:func:`backlashkit.simulate.simulate_packed_runs`, paper A's law), from its first
    state. A run that tracks the motor's angle (``track_angle``: its states end with
    it, one more than the drive's) gives the angle's sensitivity too, last: the
    speed's integral, which no jump moves (the speeds are continuous at every
    change).

    The same values to the bit as :func:`trajectory_and_sensitivities` from that state
    on that grid and torque, without simulating the drive again: the joint fit has
    just simulated the point whose Jacobian it wants. ``initial_sensitivity`` and
    ``params`` as there; no warning (the run's near-grazing passes are its
    simulator's). ``out``: a C-contiguous float array of that shape to write them
    into and return (a caller asking again and again for runs of one size keeps one,
    where a new array each time costs its fresh pages).

    Raises
    ------
    InputError
        As :func:`sensitivities`.
    ValueError
        From the kernel: a run that does not fit the drive (another switch count,
        states not finite, changes out of order or off the grid), or a change that
        grazes a flank.
    """
    from . import _core

    args, wanted, s0 = _along(drive, run, params, initial_sensitivity, actuator)
    return _core.drive_sensitivities_along(*args, wanted, s0, out)


def sensitivity_at_end_along(
    drive: TwoMassDrive,
    run: PackedRun,
    *,
    initial_sensitivity: np.ndarray | None = None,
    params: Sequence[str] | None = None,
    actuator: CurrentLoop | None = None,
) -> np.ndarray:
    """The last row ``(s, len(params))`` of :func:`sensitivities_along`, to the bit,
    without the others written out: a held torque's run, whose end alone the window
    after it starts from. Arguments and errors as :func:`sensitivities_along` (and a
    run of no sample is refused)."""
    from . import _core

    args, wanted, s0 = _along(drive, run, params, initial_sensitivity, actuator)
    return _core.drive_sensitivity_at_end_along(*args, wanted, s0)


def jacobian_rows_along(
    drive: TwoMassDrive,
    run: PackedRun,
    *,
    selected: np.ndarray,
    factor: np.ndarray,
    level: tuple[float, float],
    out: np.ndarray,
    initial_sensitivity: np.ndarray | None = None,
    params: Sequence[str] | None = None,
    actuator: CurrentLoop | None = None,
) -> np.ndarray:
    """The joint fit's Jacobian rows of the speeds' sensitivities along ``run``, written
    into ``out`` and returned: :func:`jacobian_rows` of :func:`sensitivities_along`'s
    values, to the bit, without those values written out.

    ``selected``: the samples (int64, strictly increasing) whose rows are wanted;
    ``factor``: one multiplier per parameter of ``params`` (the fit's ``-dp/dz``);
    ``level``: the two speeds' noise levels in rad/s, which the products are divided
    by; ``out``: a C-contiguous, writeable float array ``(2 len(selected),
    len(params))``. ``run``, ``initial_sensitivity``, ``params`` and ``actuator`` as
    :func:`sensitivities_along`.

    Raises
    ------
    InputError
        As :func:`sensitivities`.
    ValueError
        From the kernel: as :func:`sensitivities_along`, and samples, factors, levels
        or ``out`` that do not fit.
    """
    from . import _core

    args, wanted, s0 = _along(drive, run, params, initial_sensitivity, actuator)
    _core.drive_jacobian_rows_along(*args, wanted, np.ascontiguousarray(selected, np.int64),
                                    np.ascontiguousarray(factor, float),
                                    (float(level[0]), float(level[1])), out, s0)
    return out


def jacobian_rows(sens: np.ndarray, selected, factor: np.ndarray,
                  level: tuple[float, float]) -> np.ndarray:
    """The NumPy twin of :func:`jacobian_rows_along`'s rows, from sensitivities ``sens``
    ``(n, 3, m)``: the motor speed's rows ``(sens[k, 0, :] * factor) / level[0]`` for
    the samples ``selected`` (indices or a slice), then the load speed's; the same two
    operations in the same order, so the same values to the bit from the same
    sensitivities."""
    return np.concatenate([sens[selected, c, :] * factor / level[c] for c in (0, 1)])


def _along(drive: TwoMassDrive, run: PackedRun, params: Sequence[str] | None,
           initial_sensitivity: np.ndarray | None, actuator: CurrentLoop | None
           ) -> tuple[tuple, list[int], np.ndarray | None]:
    """The kernel's arguments for a walk along ``run``: its first ones (the drive's
    parameter values, the grid, the torque, the run's states, first modes and
    changes), the indices of ``params`` (checked, :func:`check_scope`) and the
    initial sensitivity (None: zero)."""
    names = check_scope(drive, params, actuator)
    s0 = None if initial_sensitivity is None else np.ascontiguousarray(
        initial_sensitivity, float)
    args = (_param_values(drive, actuator), run.t0, run.ts, np.ascontiguousarray(run.torque, float),
            np.ascontiguousarray(run.states, float),
            np.ascontiguousarray(run.first_modes, np.int8),
            np.ascontiguousarray(run.events, float).reshape(-1, 4))
    return args, [PARAMS.index(n) for n in names], s0


def check_scope(drive: TwoMassDrive, params: Sequence[str] | None,
                actuator: CurrentLoop | None = None) -> list[str]:
    """The names of ``params`` (None: :func:`default_params`), checked against the
    sensitivities' scope (the twin's too); a one-line :class:`InputError` otherwise."""
    if not isinstance(drive, TwoMassDrive):
        raise InputError(f"drive must be a TwoMassDrive, got {type(drive).__name__}")
    if actuator is not None and not isinstance(actuator, CurrentLoop):
        raise InputError(f"actuator must be None or a CurrentLoop, got {actuator!r}")
    if drive.theta is None:
        raise InputError("the sensitivities need theta set (a drive with backlash)")
    for side in ("M", "L"):
        fc, fs = getattr(drive, f"fc_{side}"), getattr(drive, f"fs_{side}")
        if fs is not None and fs != fc:
            raise InputError(f"the sensitivities need fs_{side} equal to fc_{side} "
                             f"(got {fs!r} and {fc!r} N m): no static friction beyond "
                             "the Coulomb torque")
    names = list(default_params(drive, actuator) if params is None else params)
    unknown = [n for n in names if n not in PARAMS]
    if unknown or len(set(names)) != len(names):
        raise InputError(f"params must be distinct names among {', '.join(PARAMS)}, got "
                         f"{params!r}")
    zero = [n for n in names if n in COULOMB and getattr(drive, n) == 0]
    if zero:
        raise InputError(f"the sensitivity to {zero[0]} needs {zero[0]} > 0, got 0 (no "
                         "friction switch to move)")
    if "tau_i" in names and _param_values(drive, actuator)[-1] == 0:
        raise InputError("the sensitivity to tau_i needs a current loop with tau_i > 0 "
                         "(pass actuator=CurrentLoop(tau_i))")
    return names
