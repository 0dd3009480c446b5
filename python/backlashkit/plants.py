"""Drive-train models with backlash.

Two models share one compiled kernel:

* :class:`TwoMassDrive` -- paper A, eq. 2: a motor and a load joined by an elastic
  shaft with backlash.
* :class:`DriveChain` -- ``N`` inertias joined by ``N - 1`` elastic shafts, each with
  its own backlash. ``TwoMassDrive`` is its ``N = 2`` case.

Conventions (SI throughout): inertias in kg m^2, viscous frictions and shaft damping
in N m s/rad, stiffness in N m/rad, angles in rad, speeds in rad/s, torques in N m.
Every backlash figure named ``theta`` is the **half-width** of the dead zone (the
paper's convention): the total gap is ``2 * theta``. python-control's
``friction_backlash_nonlinearity(b)`` and Modelica's ``ElastoBacklash(b=...)`` use the
total gap ``b = 2 * theta``.

The state vector of a chain is ``[w_1, ..., w_N, phi_1, ..., phi_{N-1}]`` with
``phi_j`` the twist of shaft ``j`` (angle of inertia ``j`` minus angle of inertia
``j + 1``); for the two-mass drive that is ``[w_M, w_L, phi_d]``. The input torque acts
on inertia 1 (the motor).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING

import numpy as np

from . import validate as v
from .errors import InputError

if TYPE_CHECKING:
    from .actuator import CurrentLoop
    from .laws import ShaftLaw
    from .simulate import DriveResponse

__all__ = ["DriveChain", "TwoMassDrive"]

#: Largest chain the compiled kernel handles (state dimension 2 N - 1 = 15).
MAX_INERTIAS = 8


def _breakaway(fs_name: str, fs: float | None, fc_name: str, fc: float) -> float:
    """The breakaway torque ``fs`` (``None``: equal to ``fc``), checked ``>= fc``."""
    if fs is None:
        return fc
    fs = v.nonnegative(fs_name, fs)
    if fs < fc:
        raise InputError(
            f"{fs_name} must be >= {fc_name} = {fc!r} N m (the breakaway torque is at least "
            f"the Coulomb torque), got {fs!r}"
        )
    return fs


def _vector(name: str, values: Sequence[float], size: int | None, check) -> tuple[float, ...]:
    arr = np.atleast_1d(np.asarray(values, dtype=object))
    if arr.ndim != 1:
        raise InputError(f"{name} must be a sequence of numbers, got {values!r}")
    if size is not None and arr.size != size:
        raise InputError(f"{name} must have {size} entries, got {arr.size}")
    return tuple(check(f"{name}[{i}]", x) for i, x in enumerate(arr))


class _Simulates:
    """The ``simulate`` method shared by the drive models."""

    def simulate(
        self,
        t: Sequence[float] | np.ndarray,
        torque: Sequence[float] | np.ndarray,
        *,
        law: ShaftLaw | str = "paper",
        initial_state: Sequence[float] | np.ndarray | None = None,
        actuator: CurrentLoop | None = None,
        positions: bool = False,
    ) -> DriveResponse:
        """Simulate the drive under a zero-order-hold motor torque.

        Parameters
        ----------
        t : array_like
            Uniform, strictly increasing time grid in s.
        torque : array_like
            Motor torque set-point in N m, one sample per entry of ``t`` (held over the
            sample).
        law : {"paper", "no-pull", "modelica"} or ShaftLaw, optional
            Contact law of the shafts, default ``"paper"``.
        initial_state : array_like, optional
            State at ``t[0]``; default rest with every twist 0.
        actuator : CurrentLoop, optional
            Current loop between set-point and motor torque; default none (exact).
        positions : bool, optional
            Track the absolute angles in the same run (see
            :attr:`~backlashkit.simulate.DriveResponse.phi_motor`); default False.

        Returns
        -------
        DriveResponse
            See :func:`backlashkit.simulate.simulate_drive`, which this calls.
        """
        from .simulate import simulate_drive

        return simulate_drive(
            self, t, torque, law=law, initial_state=initial_state, actuator=actuator,
            positions=positions,
        )


@dataclass(frozen=True)
class DriveChain(_Simulates):
    """A chain of ``N`` inertias joined by ``N - 1`` elastic shafts with backlash.

    Inertia ``i`` obeys ``J_i dw_i/dt = -f_i w_i - fc_i sign(w_i) + T_{i-1} - T_i``
    (plus the input torque on inertia 1), where ``T_j`` is the torque carried by shaft
    ``j``: zero while the twist ``phi_j`` is inside the gap ``(-theta_j, theta_j)``, and
    ``k_j (phi_j -+ theta_j) + d_j dphi_j/dt`` in contact (see :class:`ShaftLaw` for the
    contact laws). An inertia with a breakaway torque ``fs_i > 0`` sticks (``w_i = 0``)
    when its speed reaches zero with the rest of its torque within ``fs_i``.

    Parameters
    ----------
    J : sequence of float
        Inertias ``J_1 .. J_N`` in kg m^2, each > 0. ``2 <= N <= 8``.
    f : sequence of float
        Viscous frictions to ground ``f_1 .. f_N`` in N m s/rad, each >= 0.
    k : sequence of float
        Shaft stiffnesses ``k_1 .. k_{N-1}`` in N m/rad, each > 0.
    d : sequence of float
        Shaft damping coefficients ``d_1 .. d_{N-1}`` in N m s/rad, each >= 0.
    theta : sequence of float
        Backlash half-widths ``theta_1 .. theta_{N-1}`` in rad, each >= 0 (the total
        gap of shaft ``j`` is ``2 theta_j``).
    fc : sequence of float, optional
        Coulomb friction torques ``fc_1 .. fc_N`` in N m, each >= 0: a slipping inertia
        feels ``-fc_i sign(w_i)``. Default none (all 0).
    fs : sequence of float, optional
        Breakaway (static friction) torques ``fs_1 .. fs_N`` in N m, ``fs_i >= fc_i``.
        An inertia whose speed crosses zero sticks while the torque on it stays within
        ``fs_i`` and breaks away when it exceeds it. Default ``fc``.
    """

    J: tuple[float, ...]
    f: tuple[float, ...]
    k: tuple[float, ...]
    d: tuple[float, ...]
    theta: tuple[float, ...] = field(default=())
    fc: tuple[float, ...] = field(default=())
    fs: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        J = _vector("J", self.J, None, v.positive)
        n = len(J)
        if not 2 <= n <= MAX_INERTIAS:
            raise InputError(f"J must have between 2 and {MAX_INERTIAS} inertias, got {n}")
        object.__setattr__(self, "J", J)
        object.__setattr__(self, "f", _vector("f", self.f, n, v.nonnegative))
        object.__setattr__(self, "k", _vector("k", self.k, n - 1, v.positive))
        object.__setattr__(self, "d", _vector("d", self.d, n - 1, v.nonnegative))
        object.__setattr__(self, "theta", _vector("theta", self.theta, n - 1, v.nonnegative))
        fc = _vector("fc", self.fc, n, v.nonnegative) if len(self.fc) else (0.0,) * n
        object.__setattr__(self, "fc", fc)
        fs = (None,) * n if self.fs is None else _vector("fs", self.fs, n, lambda _n, x: x)
        fs = tuple(_breakaway(f"fs[{i}]", x, f"fc[{i}]", fc[i]) for i, x in enumerate(fs))
        object.__setattr__(self, "fs", fs)

    @property
    def has_friction(self) -> bool:
        """Whether some inertia has Coulomb or static friction."""
        return any(x > 0 for x in self.fs)

    @property
    def n_inertias(self) -> int:
        """Number of inertias ``N``."""
        return len(self.J)

    @property
    def n_states(self) -> int:
        """Dimension ``2 N - 1`` of the state vector."""
        return 2 * len(self.J) - 1

    def to_chain(self) -> DriveChain:
        """The chain itself (for symmetry with :meth:`TwoMassDrive.to_chain`).

        Returns
        -------
        DriveChain
            ``self``.
        """
        return self

    def steady_state(self, torque: float) -> np.ndarray:
        """State reached under a constant motor torque.

        All inertias turn at ``w = torque / sum(f)``; shaft ``j`` carries the friction
        torque of the inertias beyond it, ``T_j = w * sum(f[j+1:])``, so its twist is
        ``theta_j + T_j / k_j`` (``-theta_j + T_j / k_j`` when ``T_j < 0``). A shaft
        carrying no torque is placed in the middle of its gap (twist 0): with zero
        torque the twist is not determined by the dynamics.

        Parameters
        ----------
        torque : float
            Constant motor torque in N m.

        Returns
        -------
        numpy.ndarray
            State ``[w_1 .. w_N, phi_1 .. phi_{N-1}]``.
        """
        u = v.finite_scalar("torque", torque)
        f = np.asarray(self.f)
        total = f.sum()
        fc = np.asarray(self.fc)
        if self.has_friction:
            if abs(u) <= fc.sum():
                if u == 0:
                    return np.zeros(self.n_states)
                raise InputError(
                    f"steady_state: the torque {float(u)!r} N m does not overcome the "
                    f"Coulomb friction (sum of fc = {float(fc.sum())!r} N m): the drive comes "
                    "to rest with a twist its dynamics do not determine"
                )
            # Slipping in the direction of the torque: the Coulomb torques act as a
            # constant load opposing the motion.
            u_net = u - np.sign(u) * fc.sum()
        else:
            u_net = u
        if total <= 0:
            if u == 0:
                return np.zeros(self.n_states)
            raise InputError(
                "steady_state needs some viscous friction (sum of f > 0): without it a "
                f"constant torque {u!r} N m accelerates the drive forever"
            )
        w = u_net / total
        torques = w * np.cumsum(f[::-1])[::-1][1:]
        if self.has_friction:
            torques = torques + np.sign(w) * np.cumsum(fc[::-1])[::-1][1:]
        theta = np.asarray(self.theta)
        phi = np.where(torques > 0, theta, np.where(torques < 0, -theta, 0.0))
        phi = phi + torques / np.asarray(self.k)
        return np.concatenate([np.full(self.n_inertias, w), phi])


#: What a drive's ``repr`` always shows; the friction terms only where not their default.
_LINEAR_AND_THETA = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh", "theta")


@dataclass(frozen=True)
class TwoMassDrive(_Simulates):
    """Motor and load joined by an elastic shaft with backlash (paper A, eq. 2).

    ::

        J_M dw_M/dt + f_M w_M = C_M - C_sh
        J_L dw_L/dt + f_L w_L = C_sh
        dphi_d/dt = w_M - w_L
        C_sh = k_sh (phi_d -+ theta) + f_sh (w_M - w_L)   in contact, 0 in the gap

    Parameters
    ----------
    J_M, J_L : float
        Motor and load inertias in kg m^2, > 0.
    k_sh : float
        Shaft stiffness in N m/rad, > 0.
    f_M, f_L : float
        Motor and load viscous frictions in N m s/rad, >= 0.
    f_sh : float
        Shaft damping in N m s/rad, >= 0.
    theta : float or None
        Backlash **half-width** in rad, >= 0 (total gap ``2 theta``). ``None`` for a
        drive whose backlash is unknown (e.g. a prior for identification); such a drive
        cannot be simulated until a value is given with :meth:`with_theta`.
    fc_M, fc_L : float, optional
        Coulomb friction torques of motor and load in N m, >= 0; default 0.
    fs_M, fs_L : float or None, optional
        Breakaway (static friction) torques in N m, ``fs >= fc``; ``None`` (default)
        means equal to the Coulomb torque. See :class:`DriveChain` for stick-slip.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashkit import TwoMassDrive
    >>> drive = TwoMassDrive(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2,
    ...                      f_L=0.5e-2, f_sh=1.575e-2, theta=np.deg2rad(2.0))
    >>> t = np.arange(0.0, 2.0, 1e-3)
    >>> response = drive.simulate(t, np.full(t.size, 0.157))
    >>> response.w_motor.shape
    (2000,)
    """

    J_M: float
    J_L: float
    k_sh: float
    f_M: float
    f_L: float
    f_sh: float
    theta: float | None = None
    fc_M: float = 0.0
    fc_L: float = 0.0
    fs_M: float | None = None
    fs_L: float | None = None

    def __repr__(self) -> str:
        # the friction terms only where given: most drives have none of them
        shown = [f.name for f in fields(self)
                 if f.name in _LINEAR_AND_THETA or getattr(self, f.name) != f.default]
        return f"TwoMassDrive({', '.join(f'{n}={getattr(self, n)!r}' for n in shown)})"

    def __post_init__(self) -> None:
        for name in ("J_M", "J_L", "k_sh"):
            object.__setattr__(self, name, v.positive(name, getattr(self, name)))
        for name in ("f_M", "f_L", "f_sh", "fc_M", "fc_L"):
            object.__setattr__(self, name, v.nonnegative(name, getattr(self, name)))
        for side in ("M", "L"):
            fs = _breakaway(f"fs_{side}", getattr(self, f"fs_{side}"), f"fc_{side}",
                            getattr(self, f"fc_{side}"))
            if getattr(self, f"fs_{side}") is not None:
                object.__setattr__(self, f"fs_{side}", fs)
        if self.theta is not None:
            object.__setattr__(self, "theta", v.nonnegative("theta", self.theta))

    @property
    def n_states(self) -> int:
        """Dimension of the state ``[w_M, w_L, phi_d]``: 3."""
        return 3

    @property
    def ringing_frequency(self) -> float:
        """Angular frequency in rad/s of the shaft's ringing in contact (undamped):
        ``sqrt(k_sh (1 / J_M + 1 / J_L))``."""
        return math.sqrt(self.k_sh * (1.0 / self.J_M + 1.0 / self.J_L))

    def with_theta(self, theta: float) -> TwoMassDrive:
        """A copy of the drive with another backlash.

        Parameters
        ----------
        theta : float
            Backlash half-width in rad, >= 0.

        Returns
        -------
        TwoMassDrive
            The same linear parameters with ``theta``.
        """
        return replace(self, theta=theta)

    def _require_theta(self) -> float:
        if self.theta is None:
            raise InputError(
                "this TwoMassDrive has no backlash value (theta is None); give one with "
                "drive.with_theta(theta) before simulating"
            )
        return self.theta

    def to_chain(self) -> DriveChain:
        """The equivalent two-inertia chain.

        Returns
        -------
        DriveChain
            ``J = (J_M, J_L)``, ``f = (f_M, f_L)``, ``k = (k_sh,)``, ``d = (f_sh,)``,
            ``theta = (theta,)``, ``fc = (fc_M, fc_L)``, ``fs = (fs_M, fs_L)``.
        """
        return DriveChain(
            J=(self.J_M, self.J_L),
            f=(self.f_M, self.f_L),
            k=(self.k_sh,),
            d=(self.f_sh,),
            theta=(self._require_theta(),),
            fc=(self.fc_M, self.fc_L),
            fs=(
                self.fc_M if self.fs_M is None else self.fs_M,
                self.fc_L if self.fs_L is None else self.fs_L,
            ),
        )

    def steady_state(self, torque: float) -> np.ndarray:
        """State reached under a constant motor torque (see :meth:`DriveChain.steady_state`).

        Parameters
        ----------
        torque : float
            Constant motor torque in N m.

        Returns
        -------
        numpy.ndarray
            ``[w_M, w_L, phi_d]``: both speeds ``(torque - fc_M - fc_L) / (f_M + f_L)``,
            the shaft twisted by ``theta + (f_L w + fc_L) / k_sh`` (mirrored for a
            negative torque). A torque within the Coulomb torques' sum (but 0, which
            gives rest) is refused: the drive stops with a twist its dynamics do not
            determine.
        """
        return self.to_chain().steady_state(torque)
