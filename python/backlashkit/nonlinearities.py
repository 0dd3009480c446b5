"""The backlash characteristic of Tao & Kokotović (1995) and its (adaptive) inverses.

Paper B, eq. (2.1): a backlash ``u = B(v)`` with slope ``m > 0`` and crossings
``c_l < c_r`` follows ``u = m (v - c_r)`` while ``v`` moves up, ``u = m (v - c_l)``
while ``v`` moves down, and holds ``u`` constant on the inner (horizontal) segments.
On sampled signals this is the *play operator*

    u_k = min(max(u_{k-1}, m (v_k - c_r)), m (v_k - c_l)),

which is exact at the samples whenever ``v`` is monotone between samples (in
particular for a zero-order-hold ``v``). The total gap of this backlash, measured on
``v``, is ``c_r - c_l`` (it is *not* a half-width).

The inverse-choice objects (:class:`ExactInverse`, :class:`SmoothFilterInverse`,
:class:`SmoothRampInverse`, :class:`NoInverse`, :class:`GainOnlyInverse`) configure
how the controller of :mod:`backlashkit.control` turns its desired control ``u_d`` into
the backlash input ``v``: (2.4)/(2.7), (2.6)/(2.8), (2.5)/(2.8), ``v = u_d`` and
``v = u_d / m_hat`` (the two comparisons of Section IV).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from . import validate as _v
from .errors import InputError

__all__ = [
    "Backlash",
    "ExactInverse",
    "GainOnlyInverse",
    "InverseKind",
    "InverseMemory",
    "NoInverse",
    "SmoothFilterInverse",
    "SmoothRampInverse",
    "backlash_inverse",
    "inverse_from_name",
    "inverse_kind_error",
]


def _play_numpy(v: np.ndarray, m: float, c_r: float, c_l: float, u0: float) -> np.ndarray:
    """Play operator on samples (plain NumPy/Python reference of the compiled kernel)."""
    out = np.empty_like(v)
    u = u0
    for k in range(v.size):
        lo = m * (v[k] - c_r)
        hi = m * (v[k] - c_l)
        u = min(max(u, lo), hi)
        out[k] = u
    return out


@dataclass(frozen=True)
class Backlash:
    """Backlash characteristic ``u = B(v)`` of paper B, eq. (2.1).

    Parameters
    ----------
    m : float
        Slope of the two parallel sides, ``m > 0`` (output units per input unit).
    c_r : float
        Crossing of the upward side with ``u = 0`` (input units): ``u = m (v - c_r)``
        while ``v`` increases.
    c_l : float
        Crossing of the downward side (input units), ``c_l < c_r``:
        ``u = m (v - c_l)`` while ``v`` decreases.

    Notes
    -----
    ``theta_b = (m c_r, m, m c_l)`` is the parameter vector the adaptive law of
    paper B estimates; :attr:`theta_b` returns it. The gap on the input axis is the
    total width ``c_r - c_l`` (paper A's ``theta`` is a half-width; here there is
    none).
    """

    m: float
    c_r: float
    c_l: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "m", _v.positive("m", self.m))
        object.__setattr__(self, "c_r", _v.finite_scalar("c_r", self.c_r))
        object.__setattr__(self, "c_l", _v.finite_scalar("c_l", self.c_l))
        if not self.c_l < self.c_r:
            raise InputError(f"c_l must be < c_r, got c_l={self.c_l!r}, c_r={self.c_r!r}")

    @property
    def theta_b(self) -> np.ndarray:
        """The parameter vector ``(m c_r, m, m c_l)`` of paper B, Section III-B."""
        return np.array([self.m * self.c_r, self.m, self.m * self.c_l])

    def initial_output(self, v0: float, u0: float | None = None) -> float:
        """Backlash output at the first sample.

        Parameters
        ----------
        v0 : float
            First input sample.
        u0 : float, optional
            Output *before* the first sample (the state of the play). ``None`` means
            0, i.e. the characteristic starts at rest on ``u = 0``.

        Returns
        -------
        float
            ``clip(u0, m (v0 - c_r), m (v0 - c_l))``.
        """
        u = 0.0 if u0 is None else _v.finite_scalar("u0", u0)
        return min(max(u, self.m * (v0 - self.c_r)), self.m * (v0 - self.c_l))

    def apply(
        self, v: np.ndarray, *, u0: float | None = None, backend: str = "rust"
    ) -> np.ndarray:
        """Apply the backlash to a sampled input (play operator).

        Parameters
        ----------
        v : array_like, shape (N,)
            Input samples.
        u0 : float, optional
            Output before the first sample (state of the play); ``None`` means 0.
            The first output sample is ``clip(u0, m (v[0] - c_r), m (v[0] - c_l))``.
        backend : {"rust", "numpy"}
            Compiled kernel (default) or the plain NumPy reference.

        Returns
        -------
        numpy.ndarray, shape (N,)
            Output samples ``u_k``.
        """
        arr = _v.finite_array("v", v)
        u_init = 0.0 if u0 is None else _v.finite_scalar("u0", u0)
        if backend == "numpy":
            return _play_numpy(arr, self.m, self.c_r, self.c_l, u_init)
        if backend != "rust":
            raise InputError(f"backend must be 'rust' or 'numpy', got {backend!r}")
        from . import _core

        return np.asarray(_core.play_operator(arr, self.m, self.c_r, self.c_l, u_init))

    def inverse(self, u_d: np.ndarray, *, v0_side: str = "up") -> np.ndarray:
        """Exact right inverse (2.2)/(2.4) applied to sampled ``u_d``.

        Parameters
        ----------
        u_d : array_like, shape (N,)
            Desired backlash output.
        v0_side : {"up", "down"}
            Side of the inverse used before ``u_d`` first moves.

        Returns
        -------
        numpy.ndarray, shape (N,)
            ``v`` with ``B(v) = u_d`` sample by sample (see :func:`backlash_inverse`).
        """
        return backlash_inverse(u_d, m=self.m, c_r=self.c_r, c_l=self.c_l, v0_side=v0_side)


def backlash_inverse(
    u_d: np.ndarray, *, m: float, c_r: float, c_l: float, v0_side: str = "up"
) -> np.ndarray:
    """Exact backlash inverse (2.3)-(2.4) of paper B on a sampled desired output.

    ``v = u_d / m + omega`` with ``omega = c_r`` while ``u_d`` increases, ``c_l`` while
    it decreases, held while it is constant; on samples the direction is that of
    ``u_d[k] - u_d[k-1]``.

    Parameters
    ----------
    u_d : array_like, shape (N,)
        Desired backlash output samples.
    m, c_r, c_l : float
        Backlash parameters (see :class:`Backlash`).
    v0_side : {"up", "down"}
        Side used at the first sample (and until ``u_d`` first moves).

    Returns
    -------
    numpy.ndarray, shape (N,)
        Backlash input ``v``. ``Backlash(m, c_r, c_l).apply(v, u0=u_d[0])`` returns
        ``u_d`` (Lemma 2.1).
    """
    b = Backlash(m, c_r, c_l)
    arr = _v.finite_array("u_d", u_d)
    if v0_side not in ("up", "down"):
        raise InputError(f"v0_side must be 'up' or 'down', got {v0_side!r}")
    omega = np.empty_like(arr)
    w = b.c_r if v0_side == "up" else b.c_l
    prev = arr[0] if arr.size else 0.0
    for k in range(arr.size):
        d = arr[k] - prev
        if d > 0:
            w = b.c_r
        elif d < 0:
            w = b.c_l
        omega[k] = w
        prev = arr[k]
    return arr / b.m + omega


@dataclass
class InverseMemory:
    """What an inverse keeps between a discrete controller's samples.

    Parameters
    ----------
    rising : bool
        Whether ``u_d`` last rose (the ``c_r`` side) rather than fell.
    locked_right : bool
        The smooth ramp's side: locked on ``c_r`` (else on ``c_l``).
    omega_bar : float or None
        The smooth filter's output (None before the first sample).
    """

    rising: bool
    locked_right: bool
    omega_bar: float | None = None

    def side(self, theta_b: np.ndarray) -> float:
        """The estimated side of the gap that ``u_d`` moves towards.

        Parameters
        ----------
        theta_b : numpy.ndarray
            The estimates ``(m c_r, m, m c_l)``.

        Returns
        -------
        float
            ``c_hat_r`` while ``u_d`` rises, ``c_hat_l`` while it falls.
        """
        return float(theta_b[0] / theta_b[1] if self.rising else theta_b[2] / theta_b[1])


class InverseKind:
    """Base class of the inverse choices of the adaptive controller.

    Subclasses are small frozen configuration objects; ``code`` is the integer the
    compiled kernel uses, ``name`` the CLI spelling.
    """

    code: ClassVar[int] = -1
    name: ClassVar[str] = ""
    adapts: ClassVar[bool] = True
    #: Which of the adaptive law's ``(c_r, m, c_l)`` adapt (1) or stay at 0 (0).
    adapted: ClassVar[tuple[float, float, float]] = (1.0, 1.0, 1.0)

    @property
    def rate(self) -> float:
        """The rate of the inverse's own dynamics in 1/s (0: it has none); the closed
        loop's integration step must resolve it."""
        return 0.0

    def sample(self, u_d: float, u_d_dot: float, theta_b: np.ndarray, memory: InverseMemory,
               ts: float) -> float:
        """The inverse's output for one sample of a discrete controller.

        Parameters
        ----------
        u_d : float
            The fixed controller's output at this sample.
        u_d_dot : float
            Its time derivative (units of ``u_d`` per s).
        theta_b : numpy.ndarray
            The estimates ``(m c_r, m, m c_l)``.
        memory : InverseMemory
            What the inverse keeps between samples (updated in place).
        ts : float
            Sample time in s.

        Returns
        -------
        float
            The backlash input ``v``.
        """
        return self._sample(u_d, u_d_dot, theta_b, memory, ts)

    def _sample(self, u_d: float, u_d_dot: float, theta_b: np.ndarray,
                memory: InverseMemory, ts: float) -> float:
        """The exact inverse (2.7): ``u_d / m_hat + c_hat_r`` while ``u_d`` rises,
        ``+ c_hat_l`` while it falls."""
        return u_d / theta_b[1] + memory.side(theta_b)

    def params(self) -> tuple[float, float]:
        """Two numeric parameters passed to the kernel (meaning depends on the kind).

        Returns
        -------
        tuple of float
            ``(alpha, 0)`` for the filter, ``(beta_r, beta_l)`` for the ramp, zeros
            otherwise.
        """
        return (0.0, 0.0)


@dataclass(frozen=True)
class NoInverse(InverseKind):
    """Fixed controller alone, ``v = u_d`` (comparison of paper B, Section IV)."""

    code: ClassVar[int] = 0
    name: ClassVar[str] = "none"
    adapts: ClassVar[bool] = False

    def _sample(self, u_d: float, u_d_dot: float, theta_b: np.ndarray,
                memory: InverseMemory, ts: float) -> float:
        """``v = u_d``."""
        return u_d


@dataclass(frozen=True)
class ExactInverse(InverseKind):
    """Adaptive exact inverse (2.7): ``v = u_d / m_hat + c_hat_r or c_hat_l`` (jumps)."""

    code: ClassVar[int] = 1
    name: ClassVar[str] = "exact"


@dataclass(frozen=True)
class SmoothFilterInverse(InverseKind):
    """Continuous approximation (2.6)/(2.8): ``omega_bar`` filtered at ``alpha``.

    Parameters
    ----------
    alpha : float
        Filter bandwidth in rad/s (``d omega_bar/dt = alpha (omega - omega_bar)``),
        ``alpha > 0``; paper B's Fig. 6 uses 6.
    """

    alpha: float = 6.0
    code: ClassVar[int] = 2
    name: ClassVar[str] = "smooth-filter"

    def __post_init__(self) -> None:
        object.__setattr__(self, "alpha", _v.positive("alpha", self.alpha))

    @property
    def rate(self) -> float:
        """``alpha``, the filter's bandwidth in rad/s."""
        return self.alpha

    def _sample(self, u_d: float, u_d_dot: float, theta_b: np.ndarray,
                memory: InverseMemory, ts: float) -> float:
        """``v = u_d / m_hat + omega_bar``, ``omega_bar`` the side's estimate filtered
        at ``alpha`` over the sample."""
        target = memory.side(theta_b)
        if memory.omega_bar is None:
            memory.omega_bar = target
        out = u_d / theta_b[1] + memory.omega_bar
        decay = np.exp(-self.alpha * ts)
        memory.omega_bar = target + (memory.omega_bar - target) * decay
        return out

    def params(self) -> tuple[float, float]:
        """Kernel parameters of the filter.

        Returns
        -------
        tuple of float
            ``(alpha, 0.0)``.
        """
        return (self.alpha, 0.0)


@dataclass(frozen=True)
class SmoothRampInverse(InverseKind):
    """Continuous approximation (2.5)/(2.8): linear ramps between the two sides.

    Parameters
    ----------
    beta_r : float
        Width of the upward ramp on ``du_d/dt`` (units of ``u_d`` per s), ``> 0``:
        after a reversal to increasing ``u_d``, ``omega_bar = c_l + (c_r - c_l)
        du_d/dt / beta_r`` until ``du_d/dt`` reaches ``beta_r`` (then ``c_r``, locked).
    beta_l : float
        Width of the downward ramp, ``> 0``, symmetrically.

    Notes
    -----
    (2.5) conditions the ramps on ``omega_bar(t-) < c_r`` (resp. ``> c_l``); this is
    read as "not yet locked on the other side", which keeps ``omega_bar``
    continuous when ``du_d/dt`` turns back before reaching the end of a ramp.
    """

    beta_r: float = 1.0
    beta_l: float = 1.0
    code: ClassVar[int] = 3
    name: ClassVar[str] = "smooth-ramp"

    def __post_init__(self) -> None:
        object.__setattr__(self, "beta_r", _v.positive("beta_r", self.beta_r))
        object.__setattr__(self, "beta_l", _v.positive("beta_l", self.beta_l))

    def _sample(self, u_d: float, u_d_dot: float, theta_b: np.ndarray,
                memory: InverseMemory, ts: float) -> float:
        """``v = u_d / m_hat + omega_bar``, ``omega_bar`` on the ramp of ``du_d/dt``
        from the locked side."""
        cr, cl = theta_b[0] / theta_b[1], theta_b[2] / theta_b[1]
        if memory.locked_right:
            w = cr if u_d_dot >= 0 else cr + (cr - cl) * max(u_d_dot / self.beta_l, -1.0)
        else:
            w = cl if u_d_dot <= 0 else cl + (cr - cl) * min(u_d_dot / self.beta_r, 1.0)
        if u_d_dot >= self.beta_r:
            memory.locked_right = True
        elif u_d_dot <= -self.beta_l:
            memory.locked_right = False
        return u_d / theta_b[1] + w

    def params(self) -> tuple[float, float]:
        """Kernel parameters of the ramps.

        Returns
        -------
        tuple of float
            ``(beta_r, beta_l)``.
        """
        return (self.beta_r, self.beta_l)


@dataclass(frozen=True)
class GainOnlyInverse(InverseKind):
    """Degenerate adaptive inverse ``c_hat_r = c_hat_l = 0`` (only ``m_hat`` adapts).

    The second comparison of paper B, Section IV: ``v = u_d / m_hat``.
    """

    code: ClassVar[int] = 4
    name: ClassVar[str] = "gain-only"
    adapted: ClassVar[tuple[float, float, float]] = (0.0, 1.0, 0.0)

    def _sample(self, u_d: float, u_d_dot: float, theta_b: np.ndarray,
                memory: InverseMemory, ts: float) -> float:
        """``v = u_d / m_hat``."""
        return u_d / theta_b[1]


_BY_NAME: dict[str, type[InverseKind]] = {
    "none": NoInverse,
    "exact": ExactInverse,
    "smooth-filter": SmoothFilterInverse,
    "smooth-ramp": SmoothRampInverse,
    "gain-only": GainOnlyInverse,
}


def inverse_kind_error(value: object) -> InputError:
    """The refusal of ``inverse=value`` that is no :class:`InverseKind`, naming the
    classes and, for a name, :func:`inverse_from_name`.

    Parameters
    ----------
    value : object
        What was given.

    Returns
    -------
    InputError
        The error to raise.
    """
    named = (f"; for a name, inverse_from_name({value!r})" if isinstance(value, str) else "")
    return InputError(
        "inverse must be an InverseKind (ExactInverse(), SmoothFilterInverse(alpha), "
        "SmoothRampInverse(beta_r, beta_l), NoInverse() or GainOnlyInverse()), got "
        f"{type(value).__name__} {value!r}{named}")


def inverse_from_name(name: str, **params: float) -> InverseKind:
    """Map a CLI spelling onto an inverse configuration object.

    Parameters
    ----------
    name : {"exact", "smooth-filter", "smooth-ramp", "none", "gain-only"}
        The inverse.
    **params : float
        Its parameters (``alpha`` or ``beta_r``, ``beta_l``).

    Returns
    -------
    InverseKind
        The configuration object.
    """
    try:
        cls = _BY_NAME[name]
    except KeyError:
        close = difflib.get_close_matches(str(name), list(_BY_NAME), n=1)
        meant = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(f"inverse must be one of {sorted(_BY_NAME)}, got {name!r}{meant}"
                         ) from None
    return cls(**params)
