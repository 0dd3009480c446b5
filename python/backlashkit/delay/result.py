"""The answer of :func:`~backlashkit.delay.delay_margin`: the maximal delay interval."""

from __future__ import annotations

import math
from typing import Any

from .. import validate as v
from ..errors import InputError
from .crossings import Crossing, unstable_count_changes
from .system import DelaySystem

__all__ = ["DelayMarginResult"]

#: Default delay range of :meth:`DelayMarginResult.stability_windows`: this many times
#: ``h_max``, or :data:`DEFAULT_RANGE_NO_MARGIN` s when ``h_max`` is 0 or infinite.
DEFAULT_RANGE_FACTOR = 10.0
DEFAULT_RANGE_NO_MARGIN = 100.0
#: Most crossing delays a range may hold: each costs a root-direction computation, and
#: a range past this many periods of the crossing frequencies only repeats them.
MAX_CROSSING_DELAYS = 100_000


class DelayMarginResult:
    """The maximal delay interval ``[0, h_max)`` of a linear delay system, and its proof.

    Parameters
    ----------
    system : DelaySystem
        The system analysed.
    crossings : list of Crossing
        Every imaginary-axis crossing found (each stands for the delays
        ``h0 + 2 pi k / omega``).
    unstable_at_zero : int
        Roots of the delay-free system not in the open left half-plane.
    difference_radius : float
        Spectral radius of the companion of ``B1 .. Bq`` (0 for a retarded system).
    method : str
        ``"sweep"`` or ``"kronecker"``.
    sweep : SweepData or None
        The frequency grid and moduli of the sweep (plots).

    Attributes
    ----------
    h_max : float
        Largest delay (s) such that the system is asymptotically stable on
        ``[0, h_max)``: ``math.inf`` when stable for every delay, ``0.0`` when unstable
        at ``h = 0`` or when the neutral difference operator is unstable.
    omega : float
        Frequency (rad/s) of the root on the imaginary axis at ``h_max`` (``nan`` if
        none).
    vector : numpy.ndarray or None
        Unit right null vector of ``T(j omega, h_max)``: the crossing eigenvector.
    stable_at_zero : bool
        Whether the delay-free system is asymptotically stable.
    delay_independent : bool
        Whether the system is asymptotically stable for every ``h >= 0``.
    verification : dict
        Filled by :func:`~backlashkit.delay.delay_margin` with ``verify=True``:
        ``residual`` (relative ``sigma_min(T)`` at the polished crossing),
        ``rightmost_below`` and ``rightmost_above`` (real parts of the rightmost root,
        1/s, by :mod:`~backlashkit.delay.spectral` at ``h_max (1 -+ step)``),
        ``step``, ``touch`` (the first crossing is tangential: the root returns to
        the left) and ``passed``.
    """

    def __init__(self, system: DelaySystem, crossings: list[Crossing], *,
                 unstable_at_zero: int, difference_radius: float, method: str,
                 sweep: Any = None) -> None:
        self.system = system
        self.crossings = list(crossings)
        self.unstable_at_zero = int(unstable_at_zero)
        self.difference_radius = float(difference_radius)
        self.method = method
        self.sweep = sweep
        self.verification: dict[str, Any] = {}
        self.stable_at_zero = self.unstable_at_zero == 0
        first = min(self.crossings, key=lambda c: c.h0, default=None)
        if self.difference_radius > 1.0 or not self.stable_at_zero:
            self.h_max, first = 0.0, None
        else:
            self.h_max = first.h0 if first is not None else math.inf
        self.delay_independent = math.isinf(self.h_max)
        self.omega = first.omega if first is not None else math.nan
        self.vector = first.vector if first is not None else None

    def __repr__(self) -> str:
        return (f"DelayMarginResult(h_max={self.h_max:.10g}, omega={self.omega:.10g}, "
                f"stable_at_zero={self.stable_at_zero}, method={self.method!r})")

    def default_range(self) -> tuple[float, float]:
        """``(0, 10 h_max)``, or ``(0, 100)`` s when ``h_max`` is 0 or infinite.

        Returns
        -------
        tuple of float
            ``(lo, hi)`` in s.
        """
        if 0.0 < self.h_max < math.inf:
            return 0.0, DEFAULT_RANGE_FACTOR * self.h_max
        return 0.0, DEFAULT_RANGE_NO_MARGIN

    def stability_windows(self, h_range: tuple[float, float] | None = None
                          ) -> list[tuple[float, float]]:
        """Every interval of delays in ``h_range`` on which the system is stable.

        Counts the roots in the open right half-plane along ``h``: the count at
        ``h = 0+`` is that of the delay-free system, and each crossing changes it by 2
        in the direction of ``Re ds/dh``. Stability can come back at larger delays.
        A tangential touch splits a window (the system is only marginally stable
        there).

        Parameters
        ----------
        h_range : (float, float), optional
            ``(lo, hi)`` in s, finite, ``0 <= lo < hi`` (default :meth:`default_range`).

        Returns
        -------
        list of (float, float)
            Open intervals ``(a, b)`` (``a = lo`` may be included), sorted.
        """
        lo, hi = self.default_range() if h_range is None else self.checked_range(h_range)
        if self.difference_radius > 1.0:
            return []
        count, start, out = self.unstable_at_zero, 0.0, []
        for h, change in unstable_count_changes(self.system, self.crossings, hi):
            if count == 0 and change >= 0:  # a stable window ends (or is split by a touch)
                out.append((start, h))
            new = max(count + change, 0)
            if new == 0 and (count != 0 or change == 0):
                start = h
            count = new
        if count == 0:
            out.append((start, hi))
        clipped = [(max(a, lo), min(b, hi)) for a, b in out]
        return [(a, b) for a, b in clipped if b > a]

    def as_dict(self, h_range: tuple[float, float] | None = None) -> dict[str, Any]:
        """JSON-ready summary: ``h_max`` (``None`` when infinite), ``omega``,
        ``stable_at_zero``, ``delay_independent``, ``windows`` over ``h_range``, and
        ``difference_radius`` (the neutral difference operator's spectral radius: 0
        for a retarded system; above 1 the system is unstable for every ``h > 0``,
        which is why ``h_max`` is then 0).

        Parameters
        ----------
        h_range : (float, float), optional
            Range of the windows (default :meth:`default_range`).

        Returns
        -------
        dict
            Plain floats, bools, lists and ``None``.
        """
        return {
            "h_max": None if math.isinf(self.h_max) else float(self.h_max),
            "omega": None if math.isnan(self.omega) else float(self.omega),
            "stable_at_zero": bool(self.stable_at_zero),
            "delay_independent": bool(self.delay_independent),
            "windows": [[float(a), float(b)] for a, b in self.stability_windows(h_range)],
            "difference_radius": float(self.difference_radius),
        }

    def checked_range(self, h_range: Any) -> tuple[float, float]:
        """``h_range`` as ``(lo, hi)`` in s, checked.

        Parameters
        ----------
        h_range : (float, float)
            Delays in s, ``0 <= lo < hi``.

        Returns
        -------
        tuple of float
            ``(lo, hi)``.

        Raises
        ------
        InputError
            If ``h_range`` is not two finite numbers with ``0 <= lo < hi``, or holds
            more than :data:`MAX_CROSSING_DELAYS` delays at which a root crosses the
            imaginary axis (each one's direction is computed).
        """
        try:
            lo, hi = (v.finite_scalar("h_range", x) for x in h_range)
        except (TypeError, ValueError):
            raise InputError(f"h_range must be two delays (lo, hi) in s, got {h_range!r}"
                             ) from None
        if not 0.0 <= lo < hi:
            raise InputError(f"h_range must be finite with 0 <= lo < hi; got ({lo:g}, {hi:g})")
        count = sum(max(0.0, (hi * c.omega - c.phase) / (2 * math.pi) + 1)
                    for c in self.crossings)
        if count > MAX_CROSSING_DELAYS:
            raise InputError(
                f"h_range up to {hi:g} s holds about {count:.3g} delays at which roots "
                f"cross the imaginary axis, more than {MAX_CROSSING_DELAYS:,}: give a "
                "shorter range")
        return lo, hi

    def plot(self, *, ax=None, h_range: tuple[float, float] | None = None, n_h: int = 60):
        """Moduli of the generalized eigenvalues against frequency, and the rightmost
        root against the delay.

        Parameters
        ----------
        ax : sequence of two matplotlib Axes, optional
            Where to draw (default: a new figure with two panels).
        h_range : (float, float), optional
            Delays of the second panel (default :meth:`default_range`).
        n_h : int
            Delays evaluated in the second panel (spectral method at each).

        Returns
        -------
        matplotlib.figure.Figure
            The figure of the axes drawn on.
        """
        from .plotting import plot_margin

        span = self.default_range() if h_range is None else self.checked_range(h_range)
        return plot_margin(self, ax=ax, h_range=span, n_h=v.integer("n_h", n_h, 2))
