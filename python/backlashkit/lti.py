"""Linear time-invariant plants and the plant with input backlash ``y = G[B(v)]``.

A plant ``G`` may be given as

* a ``(num, den)`` pair of coefficient lists, highest power first;
* a python-control ``TransferFunction`` or ``StateSpace`` (SISO, continuous time);
* a ``scipy.signal.lti`` (``TransferFunction``, ``StateSpace`` or ``ZerosPolesGain``).

python-control is optional: its objects are recognised by their attributes, it is
never imported here.

Simulation uses a zero-order-hold input on a uniform grid. Because the play operator
maps a piecewise-constant ``v`` to a piecewise-constant ``u = B(v)``, the ZOH
discretisation ``x_{k+1} = A_d x_k + B_d u_k`` is exact at the samples.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from . import validate as _v
from .errors import InputError
from .nonlinearities import Backlash

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure

__all__ = [
    "LinearPlantWithBacklash",
    "PlantResponse",
    "as_state_space",
    "as_transfer_function",
    "zoh_discretize",
]

#: Relative size under which a leading numerator coefficient counts as zero.
_TRIM_RTOL = 1e-10


def _poly(name: str, coeffs: Any) -> np.ndarray:
    _v.real_numbers(name, coeffs)
    arr = np.atleast_1d(np.asarray(coeffs, dtype=float))
    if arr.ndim > 1 and arr.size != arr.shape[-1]:  # a row, as scipy's to_tf gives, is fine
        raise InputError(f"{name} must be one list of coefficients (highest power first), "
                         f"got shape {arr.shape}")
    arr = _v.finite_array(name, arr.ravel())
    if arr.size == 0:
        raise InputError(f"{name} must have at least one coefficient, got none")
    nz = np.flatnonzero(arr)
    if nz.size == 0:
        raise InputError(f"{name} must not be the zero polynomial, got {arr.tolist()!r}")
    return arr[nz[0] :]


def _trim(num: np.ndarray) -> np.ndarray:
    scale = np.max(np.abs(num)) if num.size else 0.0
    keep = np.flatnonzero(np.abs(num) > _TRIM_RTOL * scale)
    if keep.size == 0:
        raise InputError("the plant's numerator is zero (the plant has no gain)")
    return num[keep[0] :]


def _is_control_tf(obj: Any) -> bool:
    return (
        type(obj).__module__.startswith("control") and hasattr(obj, "num") and hasattr(obj, "den")
    )


def _is_control_ss(obj: Any) -> bool:
    return type(obj).__module__.startswith("control") and all(
        hasattr(obj, a) for a in ("A", "B", "C", "D")
    )


def _check_continuous(obj: Any, name: str) -> None:
    dt = getattr(obj, "dt", None)
    if dt not in (None, 0) and dt is not False:
        raise InputError(f"{name} must be a continuous-time system, got dt={dt!r}")


def _siso(name: str, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray):
    a = np.atleast_2d(np.asarray(a, dtype=float))
    b = np.asarray(b, dtype=float).reshape(a.shape[0], -1) if a.size else np.zeros((0, 1))
    c = np.asarray(c, dtype=float).reshape(-1, a.shape[0]) if a.size else np.zeros((1, 0))
    d = np.atleast_2d(np.asarray(d, dtype=float))
    if b.shape[1] != 1 or c.shape[0] != 1 or d.shape != (1, 1):
        raise InputError(
            f"{name} must be single-input single-output, got {b.shape[1]} inputs and "
            f"{c.shape[0]} outputs"
        )
    return a, b[:, 0].copy(), c[0].copy(), float(d[0, 0])


def _signal():
    # scipy.signal takes about a second to import: only load it when a plant needs it.
    import scipy.signal

    return scipy.signal


def _from_scipy_signal(obj: Any) -> bool:
    return type(obj).__module__.startswith("scipy.signal")


def as_transfer_function(plant: Any, *, name: str = "plant") -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of a SISO continuous-time plant.

    Parameters
    ----------
    plant : tuple or python-control or scipy.signal LTI object
        ``(num, den)`` (highest power first), a python-control ``TransferFunction`` /
        ``StateSpace``, or a ``scipy.signal.lti``.
    name : str
        Name used in error messages.

    Returns
    -------
    num, den : numpy.ndarray
        Coefficients, highest power first, leading zeros removed (numerically zero
        leading numerator coefficients, below ``1e-10`` of the largest, too).
    """
    if isinstance(plant, (tuple, list)):
        if len(plant) != 2:
            raise InputError(
                f"{name} given as a sequence must be (num, den), got {len(plant)} items"
            )
        num, den = _poly(f"{name} numerator", plant[0]), _poly(f"{name} denominator", plant[1])
    elif _from_scipy_signal(plant) and isinstance(plant, _signal().lti):
        tf = plant.to_tf()
        num, den = _poly(f"{name} numerator", tf.num), _poly(f"{name} denominator", tf.den)
    elif _from_scipy_signal(plant) and isinstance(plant, _signal().dlti):
        raise InputError(f"{name} must be a continuous-time system, got a scipy.signal.dlti")
    elif _is_control_ss(plant):
        _check_continuous(plant, name)
        a, b, c, d = _siso(name, plant.A, plant.B, plant.C, plant.D)
        return _ss_to_tf(a, b, c, d, name)
    elif _is_control_tf(plant):
        _check_continuous(plant, name)
        numl, denl = plant.num, plant.den
        if getattr(plant, "ninputs", 1) != 1 or getattr(plant, "noutputs", 1) != 1:
            raise InputError(f"{name} must be single-input single-output")
        while isinstance(numl, (list, tuple)) or (
            isinstance(numl, np.ndarray) and numl.dtype == object
        ):
            numl, denl = numl[0], denl[0]
        num, den = _poly(f"{name} numerator", numl), _poly(f"{name} denominator", denl)
    else:
        raise InputError(
            f"{name} must be (num, den), a python-control TransferFunction/StateSpace or "
            f"a scipy.signal.lti, got {type(plant).__name__}"
        )
    num = _trim(num)
    return num / den[0], den / den[0]


def _ss_to_tf(a, b, c, d, name):
    if a.shape[0] == 0:
        return np.array([d]), np.array([1.0])
    num, den = _signal().ss2tf(a, b[:, None], c[None, :], np.array([[d]]))
    return _trim(np.asarray(num[0], dtype=float)), np.asarray(den, dtype=float)


def as_state_space(
    plant: Any, *, name: str = "plant"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """State-space realisation ``(A, b, c, d)`` of a SISO continuous-time plant.

    Parameters
    ----------
    plant : tuple or python-control or scipy.signal LTI object
        See :func:`as_transfer_function`.
    name : str
        Name used in error messages.

    Returns
    -------
    A : numpy.ndarray, shape (n, n)
        State matrix.
    b : numpy.ndarray, shape (n,)
        Input vector.
    c : numpy.ndarray, shape (n,)
        Output vector.
    d : float
        Feedthrough: ``dx/dt = A x + b u``, ``y = c x + d u``. State-space inputs keep their own
        realisation; transfer functions get scipy's controllable canonical form.

    Raises
    ------
    InputError
        If the plant is improper, not SISO, or discrete-time.
    """
    if _from_scipy_signal(plant) and isinstance(plant, _signal().StateSpace) and not isinstance(
        plant, _signal().dlti
    ):
        return _siso(name, plant.A, plant.B, plant.C, plant.D)
    if _is_control_ss(plant) and not _is_control_tf(plant):
        _check_continuous(plant, name)
        return _siso(name, plant.A, plant.B, plant.C, plant.D)
    num, den = as_transfer_function(plant, name=name)
    if num.size > den.size:
        raise InputError(
            f"{name} must be proper (numerator degree <= denominator degree), got degrees "
            f"{num.size - 1} > {den.size - 1}"
        )
    if den.size == 1:
        return np.zeros((0, 0)), np.zeros(0), np.zeros(0), float(num[0] / den[0])
    a, b, c, d = _signal().tf2ss(num, den)
    return _siso(name, a, b, c, d)


def zoh_discretize(a: np.ndarray, b: np.ndarray, ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation of ``dx/dt = A x + b u``.

    Parameters
    ----------
    a : numpy.ndarray, shape (n, n)
    b : numpy.ndarray, shape (n,)
    ts : float
        Sample time in s.

    Returns
    -------
    A_d, b_d : numpy.ndarray
        ``A_d = exp(A ts)``, ``b_d = int_0^ts exp(A s) ds b``.
    """
    n = a.shape[0]
    blk = np.zeros((n + 1, n + 1))
    blk[:n, :n] = a * ts
    blk[:n, n] = b * ts
    from scipy.linalg import expm

    e = expm(blk)
    return e[:n, :n].copy(), e[:n, n].copy()


@dataclass(frozen=True)
class PlantResponse:
    """Response of :meth:`LinearPlantWithBacklash.simulate`.

    Attributes
    ----------
    t : numpy.ndarray
        Sample instants in s.
    v : numpy.ndarray
        Backlash input (held constant over each sample).
    u : numpy.ndarray
        Backlash output ``B(v)`` (plant input), held constant over each sample.
    y : numpy.ndarray
        Plant output at the sample instants.
    x : numpy.ndarray, shape (N, n)
        Plant state at the sample instants.
    """

    t: np.ndarray
    v: np.ndarray
    u: np.ndarray
    y: np.ndarray
    x: np.ndarray

    def plot(self, ax: matplotlib.axes.Axes | None = None) -> matplotlib.figure.Figure:
        """Plot ``v``, ``u`` and ``y`` against time.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Axes to draw into; a new figure is created when omitted.

        Returns
        -------
        matplotlib.figure.Figure
            The figure holding the axes.
        """
        if ax is None:
            from matplotlib.figure import Figure

            fig = Figure(figsize=(7, 4))
            ax = fig.add_subplot()
        else:
            fig = ax.figure
        ax.step(self.t, self.v, where="post", label="v (backlash input)")
        ax.step(self.t, self.u, where="post", label="u = B(v)")
        ax.plot(self.t, self.y, label="y")
        ax.set_xlabel("t [s]")
        ax.legend(loc="best")
        return fig


class LinearPlantWithBacklash:
    """LTI plant with a backlash at its input, ``y = G[B(v)]`` (paper B, eq. (3.1)).

    Parameters
    ----------
    plant : tuple or python-control or scipy.signal LTI object
        The linear part ``G`` (see :func:`as_state_space`).
    backlash : Backlash
        The input backlash.
    """

    def __init__(self, plant: Any, backlash: Backlash) -> None:
        if not isinstance(backlash, Backlash):
            raise InputError(f"backlash must be a Backlash, got {type(backlash).__name__}")
        self.backlash = backlash
        self.a, self.b, self.c, self.d = as_state_space(plant)

    @property
    def order(self) -> int:
        """Number of states of the linear part."""
        return int(self.a.shape[0])

    def simulate(
        self,
        t: np.ndarray,
        v: np.ndarray,
        *,
        initial_state: np.ndarray | None = None,
        u0: float | None = None,
        backend: str = "rust",
    ) -> PlantResponse:
        """Simulate with a zero-order-hold ``v`` on a uniform grid.

        Parameters
        ----------
        t : array_like, shape (N,)
            Uniform, increasing sample instants in s.
        v : array_like, shape (N,)
            Backlash input, held constant on ``[t_k, t_{k+1})``.
        initial_state : array_like, shape (n,), optional
            Plant state at ``t[0]`` (default zero).
        u0 : float, optional
            Backlash output before ``t[0]`` (default 0, see :meth:`Backlash.apply`).
        backend : {"rust", "numpy"}
            Compiled kernel or the NumPy reference.

        Returns
        -------
        PlantResponse
            Samples of ``v``, ``u``, ``y`` and the state; exact at the samples.
        """
        tt, ts = _v.time_grid(t)
        vv = _v.finite_array("v", v)
        if vv.size != tt.size:
            raise InputError(f"v must have as many samples as t ({tt.size}), got {vv.size}")
        n = self.order
        x0 = (
            np.zeros(n)
            if initial_state is None
            else _v.finite_array("initial_state", initial_state)
        )
        if x0.size != n:
            raise InputError(
                f"initial_state must have {n} entries (the plant order), got {x0.size}"
            )
        u = self.backlash.apply(vv, u0=u0, backend=backend)
        ad, bd = zoh_discretize(self.a, self.b, ts)
        if backend == "numpy":
            from ._numpy_control import zoh_recurrence

            x = zoh_recurrence(ad, bd, u, x0)
        else:
            from . import _core

            x = np.asarray(_core.zoh_recurrence(ad, bd, u, x0))
        y = x @ self.c + self.d * u
        return PlantResponse(t=tt, v=vv, u=u, y=y, x=x)
