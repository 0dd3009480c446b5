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

import functools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from . import _validate as v
from .errors import InputError, SensitivityWarning
from .laws import ShaftLaw

if TYPE_CHECKING:
    import matplotlib.figure
    import pandas

    from .plants import DriveChain, TwoMassDrive

__all__ = [
    "ContactEvent",
    "DriveResponse",
    "NearGrazing",
    "Sensitivity",
    "assess_sensitivity",
    "simulate_batch",
    "simulate_drive",
]

Backend = Literal["rust", "numpy"]

#: Mode codes used by the kernels for each shaft.
GAP, POSITIVE, NEGATIVE = 0, 1, -1
_FLANK = {POSITIVE: "positive", NEGATIVE: "negative"}


@dataclass(frozen=True)
class ContactEvent:
    """A change of contact of one shaft.

    Parameters
    ----------
    time : float
        Instant of the change in s, located inside the sample (not on the grid).
    shaft : int
        Index of the shaft (0 for the two-mass drive's only shaft).
    kind : {"contact_made", "contact_lost"}
        Whether the flanks met or separated.
    flank : {"positive", "negative"}
        The flank met or left: ``"positive"`` is ``phi = +theta``.
    """

    time: float
    shaft: int
    kind: str
    flank: str


@dataclass(frozen=True)
class NearGrazing:
    """A pass of a shaft's twist close to a contact boundary with little speed.

    Parameters
    ----------
    time : float
        Instant of the closest approach in s.
    shaft : int
        Index of the shaft.
    margin : float
        Signed distance of the closest approach relative to the boundary's scale (the
        half-width ``theta`` for the twist; ``k theta`` for the no-pull torque
        condition; 1e-6 rad when ``theta = 0``): negative when the boundary was missed,
        positive when it was barely crossed. Passes with ``|margin| < 1e-6`` are
        reported.
    """

    time: float
    shaft: int
    margin: float


class StateColumns:
    """Named views of a ``states`` array ``[w_1 .. w_N, phi_1 .. phi_{N-1}]``.

    Mixed into result classes that have ``states`` (shape ``(n, 2N - 1)``) and
    ``n_inertias``.
    """

    states: np.ndarray
    n_inertias: int

    @property
    def speeds(self) -> np.ndarray:
        """Speeds of all inertias in rad/s, shape ``(n, N)``."""
        return self.states[:, : self.n_inertias]

    @property
    def twists(self) -> np.ndarray:
        """Twists ``phi_j`` of all shafts in rad, shape ``(n, N - 1)``."""
        return self.states[:, self.n_inertias :]

    @property
    def w_motor(self) -> np.ndarray:
        """Motor speed (inertia 1) in rad/s."""
        return self.states[:, 0]

    @property
    def w_load(self) -> np.ndarray:
        """Load speed (last inertia) in rad/s."""
        return self.states[:, self.n_inertias - 1]

    @property
    def phi_d(self) -> np.ndarray:
        """Twist of the first shaft (``phi_M - phi_L`` for a two-mass drive) in rad."""
        return self.states[:, self.n_inertias]


@dataclass(frozen=True, eq=False)
class DriveResponse(StateColumns):
    """Result of a drive simulation, sampled on the input's time grid.

    Parameters
    ----------
    t : numpy.ndarray
        Time in s, shape ``(n,)``.
    torque : numpy.ndarray
        Motor torque in N m (zero-order hold: ``torque[i]`` acts on
        ``[t[i], t[i+1])``), shape ``(n,)``.
    states : numpy.ndarray
        States ``[w_1 .. w_N, phi_1 .. phi_{N-1}]`` at ``t``, shape ``(n, 2N - 1)``.
    modes : numpy.ndarray
        Contact mode of each shaft at ``t`` (0 gap, +1 positive flank, -1 negative
        flank), ``int8``, shape ``(n, N - 1)``.
    event_array : numpy.ndarray
        Contact changes as rows ``[time, shaft, mode before, mode after]``, shape
        ``(E, 4)``; :attr:`events` gives them as :class:`ContactEvent` objects.
    graze_array : numpy.ndarray
        Near-grazing passes as rows ``[time, shaft, margin]``, shape ``(G, 3)``;
        :attr:`near_grazing` gives them as :class:`NearGrazing` objects.
    law : ShaftLaw
        The shaft law used.
    drive : DriveChain
        The simulated chain (a two-mass drive is simulated as its chain).
    """

    t: np.ndarray
    torque: np.ndarray
    states: np.ndarray
    modes: np.ndarray
    event_array: np.ndarray
    graze_array: np.ndarray
    law: ShaftLaw
    drive: DriveChain

    # Built on first access: most runs never look at their events one by one.
    @functools.cached_property
    def events(self) -> tuple[ContactEvent, ...]:
        """Every contact change, in time order (from :attr:`event_array`)."""
        return tuple(
            ContactEvent(
                time=time,
                shaft=int(shaft),
                kind="contact_made" if src == GAP else "contact_lost",
                flank=_FLANK[int(dst)] if src == GAP else _FLANK[int(src)],
            )
            for time, shaft, src, dst in self.event_array.tolist()
        )

    @functools.cached_property
    def near_grazing(self) -> tuple[NearGrazing, ...]:
        """Passes close to grazing, where the trajectory is ill-conditioned."""
        return tuple(NearGrazing(a, int(b), c) for a, b, c in self.graze_array.tolist())

    @property
    def n_inertias(self) -> int:
        """Number of inertias ``N``."""
        return self.drive.n_inertias

    @property
    def shaft_torques(self) -> np.ndarray:
        """Torque carried by every shaft in N m, shape ``(n, N - 1)``."""
        return shaft_torques(self.drive, self.states, self.modes, self.law)

    @property
    def shaft_torque(self) -> np.ndarray:
        """Torque carried by the first shaft in N m."""
        return self.shaft_torques[:, 0]

    def plot(self, ax: Sequence[matplotlib.axes.Axes] | None = None) -> matplotlib.figure.Figure:
        """Plot speeds, twist and shaft torque against time, with contact changes.

        Parameters
        ----------
        ax : sequence of three matplotlib Axes, optional
            Axes for speeds, twist and shaft torque. New ones are created when omitted.

        Returns
        -------
        matplotlib.figure.Figure
            The figure holding the axes. The function never calls ``plt.show()``.
        """
        from .report import plot_drive_response

        return plot_drive_response(self, ax=ax)

    def to_pandas(self) -> pandas.DataFrame:
        """The response as a :class:`pandas.DataFrame` indexed by ``t``.

        Returns
        -------
        pandas.DataFrame
            The columns of :meth:`to_columns` but ``t``, indexed by ``t`` (requires
            pandas).
        """
        import pandas as pd

        return pd.DataFrame(self.to_columns()).set_index("t")

    def to_columns(self) -> dict[str, np.ndarray]:
        """The response as named 1-D columns.

        Returns
        -------
        dict of str to numpy.ndarray
            ``t``, ``torque`` and, for a two-mass drive, ``w_motor``, ``w_load``,
            ``phi_d``, ``shaft_torque``; for a longer chain ``w_1 .. w_N``,
            ``phi_1 .. phi_{N-1}`` and ``shaft_torque_1 .. shaft_torque_{N-1}``.
        """
        cols: dict[str, np.ndarray] = {"t": self.t, "torque": self.torque}
        if self.n_inertias == 2:
            cols.update(
                w_motor=self.w_motor,
                w_load=self.w_load,
                phi_d=self.phi_d,
                shaft_torque=self.shaft_torque,
            )
            return cols
        for i in range(self.n_inertias):
            cols[f"w_{i + 1}"] = self.speeds[:, i]
        for j in range(self.n_inertias - 1):
            cols[f"phi_{j + 1}"] = self.twists[:, j]
        for j in range(self.n_inertias - 1):
            cols[f"shaft_torque_{j + 1}"] = self.shaft_torques[:, j]
        return cols


def shaft_torques(
    drive: DriveChain, states: np.ndarray, modes: np.ndarray, law: ShaftLaw
) -> np.ndarray:
    """Shaft torques (N m) from states and contact modes, shape ``(n, N - 1)``."""
    n = drive.n_inertias
    w = states[:, :n]
    phi = states[:, n:]
    k = np.asarray(drive.k)
    d = np.asarray(drive.d)
    theta = np.asarray(drive.theta)
    spring_damper = k * (phi - modes * theta) + d * (w[:, :-1] - w[:, 1:])
    torque = np.where(modes != GAP, spring_damper, 0.0)
    if law is ShaftLaw.NO_PULL:
        torque = np.where(modes == POSITIVE, np.maximum(torque, 0.0), torque)
        torque = np.where(modes == NEGATIVE, np.minimum(torque, 0.0), torque)
    return torque


def _as_chain(drive: DriveChain | TwoMassDrive) -> DriveChain:
    to_chain = getattr(drive, "to_chain", None)
    if to_chain is None:
        raise InputError(
            f"drive must be a TwoMassDrive or a DriveChain, got {type(drive).__name__}"
        )
    return to_chain()


def _initial_state(chain: DriveChain, initial_state) -> np.ndarray:
    if initial_state is None:
        return np.zeros(chain.n_states)
    x0 = v.finite_array("initial_state", initial_state)
    if x0.size != chain.n_states:
        n = chain.n_inertias
        names = ([f"w_{i}" for i in range(1, n + 1)] + [f"phi_{i}" for i in range(1, n)]
                 if n <= 3 else [f"w_1..w_{n}", f"phi_1..phi_{n - 1}"])
        raise InputError(
            f"initial_state must have {chain.n_states} entries [{', '.join(names)}], "
            f"got {x0.size}"
        )
    return x0


def _kernel(backend: Backend):
    if backend == "rust":
        from . import _core

        return _core
    if backend == "numpy":
        from . import _numpy_kernels

        return _numpy_kernels
    raise InputError(f"backend must be 'rust' or 'numpy', got {backend!r}")


def _response(chain, t, torque, law, raw) -> DriveResponse:
    states, modes, ev, gr = raw
    if len(gr):
        time, shaft, margin = gr[0]
        warnings.warn(
            f"the simulation passed within {abs(margin):.3g} (relative) of a grazing "
            f"contact (shaft {int(shaft)}, t = {time:.6g} s; {len(gr)} such pass(es)): "
            "what happens after it is sensitive to tiny changes of the inputs and "
            "parameters; see response.near_grazing",
            SensitivityWarning,
            stacklevel=3,
        )
    return DriveResponse(
        t=t,
        torque=torque,
        states=states,
        modes=modes,
        event_array=ev,
        graze_array=gr,
        law=law,
        drive=chain,
    )


def _check_inputs(drive, t, torque, law, initial_state):
    chain = _as_chain(drive)
    t_arr, ts = v.time_grid(t)
    u = v.finite_array("torque", torque)
    if u.shape != t_arr.shape:
        raise InputError(f"torque must have one sample per time step ({t_arr.size}), got {u.size}")
    return chain, t_arr, ts, u, ShaftLaw.parse(law), _initial_state(chain, initial_state)


def simulate_drive(
    drive: DriveChain | TwoMassDrive,
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    law: ShaftLaw | str = "paper",
    initial_state: Sequence[float] | np.ndarray | None = None,
    backend: Backend = "rust",
) -> DriveResponse:
    """Simulate a drive with backlash under a zero-order-hold motor torque.

    Parameters
    ----------
    drive : TwoMassDrive or DriveChain
        The drive; its ``theta`` must be set.
    t : array_like
        Uniform, strictly increasing time grid in s, at least 2 samples.
    torque : array_like
        Motor torque in N m, one sample per entry of ``t``, held constant over
        ``[t[i], t[i+1])`` (the last sample is not used).
    law : {"paper", "no-pull"} or ShaftLaw, optional
        Contact law of the shafts; default ``"paper"`` (paper A, eq. 2).
    initial_state : array_like, optional
        State at ``t[0]``: ``[w_M, w_L, phi_d]`` for a two-mass drive. Default: rest,
        twist 0 (the middle of the gap). Use ``drive.steady_state(torque)`` to start
        from a steady state.
    backend : {"rust", "numpy"}, optional
        ``"rust"`` (default) is the compiled kernel; ``"numpy"`` its plain-NumPy
        reference (same algorithm, about 100 times slower), for verification.

    Returns
    -------
    DriveResponse
        States, contact modes and contact events on the grid ``t``.

    Warns
    -----
    SensitivityWarning
        When the run passes close to a grazing contact (see
        :attr:`DriveResponse.near_grazing`).
    """
    chain, t_arr, ts, u, law_, x0 = _check_inputs(drive, t, torque, law, initial_state)
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
    )
    return _response(chain, t_arr, u, law_, raw)


def simulate_batch(
    drives: Sequence[DriveChain | TwoMassDrive],
    t: Sequence[float] | np.ndarray,
    torque: Sequence[float] | np.ndarray,
    *,
    law: ShaftLaw | str = "paper",
    initial_state: Sequence[float] | np.ndarray | None = None,
    workers: int | None = None,
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
        Motor torque in N m: shape ``(n,)`` shared by all runs, or ``(len(drives), n)``.
    law : {"paper", "no-pull"} or ShaftLaw, optional
        Contact law, default ``"paper"``.
    initial_state : array_like, optional
        Shape ``(2N - 1,)`` shared, or ``(len(drives), 2N - 1)``; default rest.
    workers : int, optional
        Number of threads; default all cores. The result does not depend on it.

    Returns
    -------
    list of DriveResponse
        One response per drive, in order.
    """
    from . import _core

    chains = [_as_chain(d) for d in drives]
    if not chains:
        raise InputError("drives must contain at least one drive")
    n_in, b = chains[0].n_inertias, len(chains)
    if any(c.n_inertias != n_in for c in chains):
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
    n_states = chains[0].n_states
    x0 = np.zeros(n_states) if initial_state is None else np.asarray(initial_state, float)
    x0 = np.broadcast_to(x0, (b, n_states)) if x0.ndim == 1 else x0
    x0 = v.finite_array("initial_state", x0, ndim=2)
    if x0.shape != (b, n_states):
        raise InputError(
            f"initial_state must have shape ({n_states},) or ({b}, {n_states}), "
            f"got {np.shape(initial_state)}"
        )
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    params = np.array([np.concatenate([c.J, c.f, c.k, c.d, c.theta]) for c in chains])
    states, modes, events = _core.simulate_chain_batch(
        n_in, params, law_.code, float(t_arr[0]), ts, u, x0, workers or 0
    )
    return [
        _response(c, t_arr, u[i if u.shape[0] > 1 else 0], law_, (states[i], modes[i], *events[i]))
        for i, c in enumerate(chains)
    ]


def _simulate_packed(
    n_inertias: int,
    params: np.ndarray,
    t0: float,
    ts: float,
    torque: np.ndarray,
    x0: np.ndarray,
    *,
    law: ShaftLaw | str,
    workers: int | None,
) -> np.ndarray:
    """States of a batch, shape ``(len(params), n, 2N - 1)``: the kernel without wrappers.

    For the estimators' inner loops, which simulate thousands of parameter vectors:
    ``params`` rows are packed ``[J, f, k, d, theta]`` (the fields of a
    :class:`DriveChain`); ``torque`` has shape ``(1, n)`` or ``(b, n)``; ``x0`` has
    shape ``(b, 2N - 1)``. Nothing is validated here but by the kernel (``ValueError``).
    """
    from . import _core

    states, _, _ = _core.simulate_chain_batch(
        n_inertias, np.ascontiguousarray(params, float), ShaftLaw.parse(law).code,
        float(t0), float(ts), np.ascontiguousarray(torque, float),
        np.ascontiguousarray(x0, float), workers or 0,
    )
    return states


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
    law : {"paper", "no-pull"} or ShaftLaw, optional
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
    chain, t_arr, ts, u, law_, x0 = _check_inputs(drive, t, torque, law, initial_state)
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
    key = [(e.shaft, e.kind, e.flank) for e in coarse.events]
    same = key == [(e.shaft, e.kind, e.flank) for e in fine.events]
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
