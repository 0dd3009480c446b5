"""Results of drive simulations: states on the grid, contact and friction events.

:class:`DriveResponse` is what :func:`backlashkit.simulate.simulate_drive` returns; the
event classes describe its contact changes (:class:`ContactEvent`), stick-slip changes
(:class:`FrictionEvent`) and near-grazing passes (:class:`NearGrazing`).
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import SensitivityWarning
from .laws import ShaftLaw

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure
    import pandas

    from .actuator import CurrentLoop
    from .plants import DriveChain

__all__ = [
    "ContactEvent",
    "DriveResponse",
    "FrictionEvent",
    "NearGrazing",
    "StateColumns",
    "shaft_torques",
]

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
class FrictionEvent:
    """A change of friction state of one inertia (stick-slip).

    Parameters
    ----------
    time : float
        Instant of the change in s, located inside the sample.
    inertia : int
        Index of the inertia (0 the motor; 1 the load of a two-mass drive).
    kind : {"stuck", "breakaway", "reversal"}
        ``"stuck"``: the speed reached zero with the torque on the inertia within its
        breakaway torque, and it sticks; ``"breakaway"``: the torque exceeded the
        breakaway torque and a stuck inertia starts to slip; ``"reversal"``: the speed
        crossed zero with a torque beyond the breakaway torque, and it slips on the
        other way without sticking.
    direction : {"positive", "negative", "none"}
        Direction of slip after the change (``"none"`` when stuck).
    """

    time: float
    inertia: int
    kind: str
    direction: str


_DIRECTION = {1: "positive", -1: "negative", 0: "none"}


def _friction_event(time: float, inertia: int, src: int, dst: int) -> FrictionEvent:
    kind = "stuck" if dst == 0 else ("breakaway" if src == 0 else "reversal")
    return FrictionEvent(time, inertia, kind, _DIRECTION[dst])


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
    friction_modes : numpy.ndarray or None
        Friction state at ``t`` of each inertia with a breakaway torque ``fs > 0``, in
        order (+1 / -1 slipping forwards / backwards, 0 stuck), ``int8``; ``None`` for
        a drive without Coulomb or static friction. :attr:`stuck` spreads it over all
        inertias.
    loop_torque : numpy.ndarray or None
        Motor torque delivered by the current loop at ``t`` in N m, shape ``(n,)``;
        ``None`` without a current loop (the torque is then :attr:`torque`).
    angle : numpy.ndarray or None
        Absolute motor angle at ``t`` in rad (0 at ``t[0]``), when tracked in the run.
    actuator : CurrentLoop or None
        The current loop simulated, if any.
    """

    t: np.ndarray
    torque: np.ndarray
    states: np.ndarray
    modes: np.ndarray
    event_array: np.ndarray
    graze_array: np.ndarray
    law: ShaftLaw
    drive: DriveChain
    friction_modes: np.ndarray | None = None
    loop_torque: np.ndarray | None = None
    angle: np.ndarray | None = None
    actuator: CurrentLoop | None = None

    # Built on first access: most runs never look at their events one by one.
    @functools.cached_property
    def events(self) -> tuple[ContactEvent | FrictionEvent, ...]:
        """Every contact change and friction change, in time order (from
        :attr:`event_array`: rows ``[time, j, from, to]`` with ``j < N - 1`` a shaft and
        ``j = N - 1 + i`` inertia ``i``'s friction state, +1/-1 slipping, 0 stuck)."""
        n_shafts = self.drive.n_inertias - 1
        out: list[ContactEvent | FrictionEvent] = []
        for time, index, src, dst in self.event_array.tolist():
            j, src, dst = int(index), int(src), int(dst)
            if j >= n_shafts:
                out.append(_friction_event(time, j - n_shafts, src, dst))
                continue
            out.append(
                ContactEvent(
                    time=time,
                    shaft=j,
                    kind="contact_made" if src == GAP else "contact_lost",
                    flank=_FLANK[dst] if src == GAP else _FLANK[src],
                )
            )
        return tuple(out)

    @property
    def contact_events(self) -> tuple[ContactEvent, ...]:
        """The contact changes of :attr:`events` alone."""
        return tuple(e for e in self.events if isinstance(e, ContactEvent))

    @property
    def friction_events(self) -> tuple[FrictionEvent, ...]:
        """The friction changes (stick, breakaway, reversal) of :attr:`events` alone."""
        return tuple(e for e in self.events if isinstance(e, FrictionEvent))

    @functools.cached_property
    def stuck(self) -> np.ndarray:
        """Whether each inertia is stuck at ``t``, ``bool``, shape ``(n, N)``."""
        stuck = np.zeros((self.t.size, self.n_inertias), dtype=bool)
        if self.friction_modes is not None:
            sticky = [i for i, fs in enumerate(self.drive.fs) if fs > 0]
            stuck[:, sticky] = self.friction_modes == 0
        return stuck

    @property
    def motor_torque(self) -> np.ndarray:
        """Torque acting on the motor at ``t`` in N m: the current loop's output, or the
        set-point :attr:`torque` without a current loop."""
        return self.torque if self.loop_torque is None else self.loop_torque

    @functools.cached_property
    def phi_motor(self) -> np.ndarray:
        """Absolute motor angle in rad at ``t``, 0 at ``t[0]`` (integrated exactly).

        From the run itself when it tracked the angle (``positions=True``); otherwise
        computed on first access by a second run of the kernel with the angle as one
        more state (same inputs; its speeds agree with this run's to rounding).
        """
        if self.angle is not None:
            return self.angle
        x0 = self.states[0]
        if self.loop_torque is not None:
            x0 = np.append(x0, self.loop_torque[0])
        from .simulate import simulate_drive

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SensitivityWarning)
            again = simulate_drive(
                self.drive, self.t, self.torque, law=self.law, initial_state=x0,
                actuator=self.actuator, positions=True,
            )
        return again.phi_motor

    @property
    def phi_load(self) -> np.ndarray:
        """Absolute load angle (last inertia) in rad: :attr:`phi_motor` minus every
        shaft's twist, so ``-phi_d[0]`` at ``t[0]`` for a two-mass drive."""
        return self.phi_motor - self.twists.sum(axis=1)

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

    def __repr__(self) -> str:
        # the dataclass's would print every array
        law = getattr(self.law, "value", self.law)
        return (f"DriveResponse({self.t.size} samples, t = {self.t[0]:g} to {self.t[-1]:g} s, "
                f"{len(self.contact_events)} contact changes, law {law!r})")

    def plot(self, ax: Sequence[matplotlib.axes.Axes] | None = None, *,
             measured: Sequence[np.ndarray] | None = None) -> matplotlib.figure.Figure:
        """Plot speeds, torques (applied and shaft) and twist against time, with the
        contact changes (:func:`backlashkit.report.plot_drive_response`).

        Parameters
        ----------
        ax : sequence or array of three matplotlib Axes, optional
            Axes for the speeds, the torques and the twist (``plt.subplots(3, 1)[1]``
            serves). New ones are created when omitted, in a figure that pyplot does
            not manage: save it (``fig.savefig("run.png")``), or pass pyplot's axes to
            show it with ``plt.show()``.
        measured : sequence of numpy.ndarray, optional
            The speeds as measured (with noise, or an encoder's), one per inertia in
            rad/s, drawn faintly behind the simulated ones.

        Returns
        -------
        matplotlib.figure.Figure
            The figure holding the axes. The function never calls ``plt.show()``.
        """
        from .report import plot_drive_response

        return plot_drive_response(self, ax=ax, measured=measured)

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
            ``t``, ``torque``, ``motor_torque`` (behind a current loop only) and, for
            a two-mass drive, ``w_motor``, ``w_load``, ``phi_d``, ``shaft_torque``;
            for a longer chain ``w_1 .. w_N``, ``phi_1 .. phi_{N-1}`` and
            ``shaft_torque_1 .. shaft_torque_{N-1}``. Where the run tracked the
            angles (``positions=True``), ``phi_motor`` and ``phi_load`` last (rad).
        """
        cols: dict[str, np.ndarray] = {"t": self.t, "torque": self.torque}
        if self.loop_torque is not None:
            cols["motor_torque"] = self.loop_torque
        cols.update(self._chain_columns())
        if self.angle is not None:  # not computed here where the run did not track it
            cols.update(phi_motor=self.phi_motor, phi_load=self.phi_load)
        return cols

    def _chain_columns(self) -> dict[str, np.ndarray]:
        """The speeds, twists and shaft torques of :meth:`to_columns`."""
        cols: dict[str, np.ndarray] = {}
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
    """Shaft torques (N m) from states and contact modes.

    Parameters
    ----------
    drive : DriveChain
        The chain.
    states : numpy.ndarray
        States ``[w_1 .. w_N, phi_1 .. phi_{N-1}]``, shape ``(n, 2N - 1)``.
    modes : numpy.ndarray
        Contact mode of each shaft (0 gap, +1 / -1 flank), shape ``(n, N - 1)``.
    law : ShaftLaw
        The contact law (its torque on a closed flank).

    Returns
    -------
    numpy.ndarray
        Torque of every shaft in N m, shape ``(n, N - 1)``.
    """
    n = drive.n_inertias
    w = states[:, :n]
    phi = states[:, n : 2 * n - 1]
    k = np.asarray(drive.k)
    d = np.asarray(drive.d)
    theta = np.asarray(drive.theta)
    if law is ShaftLaw.PAPER:  # the historical formula, kept bit for bit
        spring_damper = k * (phi - modes * theta) + d * (w[:, :-1] - w[:, 1:])
        return np.where(modes != GAP, spring_damper, 0.0)
    spring = k * (phi - modes * theta)
    return law.contact_torque(spring, d * (w[:, :-1] - w[:, 1:]), modes)
