"""References ``r(t)`` of the closed loop: a sum of sines (paper B's) or a table.

Each reference evaluates itself and its derivative, and packs itself into the arrays
the kernels read (:meth:`SumOfSines.kernel_arrays`), so the loop needs no dispatch on
its type.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import validate as v
from ..errors import InputError

__all__ = ["Reference", "SumOfSines", "TableReference"]

#: Relative slack on a table's last time against the run's duration: the rounding of
#: times written as text.
COVER_SLACK = 1e-9


@dataclass(frozen=True)
class SumOfSines:
    """Reference ``r(t) = sum_i amplitude_i sin(frequency_i t + phase_i)``.

    Parameters
    ----------
    amplitude : sequence of float
        Amplitudes (units of the plant output's reference).
    frequency : sequence of float
        Angular frequencies in rad/s.
    phase : sequence of float, optional
        Phases in rad (default zeros).
    """

    amplitude: Sequence[float]
    frequency: Sequence[float]
    phase: Sequence[float] | None = None

    def __post_init__(self) -> None:
        for name in ("amplitude", "frequency", "phase"):
            if name != "phase" or self.phase is not None:
                v.real_numbers(name, getattr(self, name))
        a = v.finite_array("amplitude", np.atleast_1d(np.asarray(self.amplitude, dtype=float)))
        w = v.finite_array("frequency", np.atleast_1d(np.asarray(self.frequency, dtype=float)))
        if a.size != w.size or a.size == 0:
            raise InputError(
                f"amplitude and frequency must be non-empty lists of equal length, got "
                f"{a.size} and {w.size}"
            )
        ph = (
            np.zeros_like(a)
            if self.phase is None
            else v.finite_array("phase", np.atleast_1d(np.asarray(self.phase, dtype=float)))
        )
        if ph.size != a.size:
            raise InputError(f"phase must have {a.size} values, got {ph.size}")
        object.__setattr__(self, "amplitude", a)
        object.__setattr__(self, "frequency", w)
        object.__setattr__(self, "phase", ph)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Evaluate ``r`` at times ``t`` (s).

        Parameters
        ----------
        t : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            ``r(t)``.
        """
        t = np.asarray(t, dtype=float)
        return np.sum(
            self.amplitude * np.sin(np.multiply.outer(t, self.frequency) + self.phase), axis=-1
        )

    def check_covers(self, duration: float) -> None:
        """Sines are defined at every time: nothing to refuse.

        Parameters
        ----------
        duration : float
            Length of the run in s.
        """

    def derivative(self, t: np.ndarray) -> np.ndarray:
        """Evaluate ``dr/dt`` at times ``t``.

        Parameters
        ----------
        t : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            ``dr/dt``.
        """
        t = np.asarray(t, dtype=float)
        return np.sum(
            self.amplitude
            * self.frequency
            * np.cos(np.multiply.outer(t, self.frequency) + self.phase),
            axis=-1,
        )

    def kernel_arrays(self) -> dict[str, np.ndarray]:
        """The reference as the kernels read it (the table's arrays empty).

        Returns
        -------
        dict
            ``amps``, ``freqs``, ``phases``, ``table_t``, ``table_r``.
        """
        return {
            "amps": np.asarray(self.amplitude),
            "freqs": np.asarray(self.frequency),
            "phases": np.asarray(self.phase),
            "table_t": np.zeros(0),
            "table_r": np.zeros(0),
        }


@dataclass(frozen=True)
class TableReference:
    """Reference given as a table, linearly interpolated (held at the ends).

    Parameters
    ----------
    t : sequence of float
        Strictly increasing times in s.
    r : sequence of float
        Reference values.
    """

    t: Sequence[float]
    r: Sequence[float]

    def __post_init__(self) -> None:
        v.real_numbers("reference t", self.t)
        v.real_numbers("reference r", self.r)
        tt = v.finite_array("reference t", self.t)
        rr = v.finite_array("reference r", self.r)
        if tt.size < 2 or tt.size != rr.size:
            raise InputError(
                "reference table needs >= 2 rows and equal-length t and r, "
                f"got {tt.size} and {rr.size}"
            )
        if not (np.diff(tt) > 0).all():
            raise InputError("reference t must be strictly increasing")
        object.__setattr__(self, "t", tt)
        object.__setattr__(self, "r", rr)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Evaluate ``r`` at times ``t`` (s).

        Parameters
        ----------
        t : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            Interpolated reference.
        """
        return np.interp(t, self.t, self.r)

    def check_covers(self, duration: float) -> None:
        """Refuse a run longer than the table: past its last row the reference would be
        held at its last value, and the tracking error measured against a constant.

        Parameters
        ----------
        duration : float
            Length of the run in s.

        Raises
        ------
        InputError
            If the table ends before ``duration``.
        """
        end = float(self.t[-1])
        if end < duration * (1.0 - COVER_SLACK):
            raise InputError(
                f"the reference table ends at t = {end:.6g} s, before the run's end at "
                f"duration = {duration:.6g} s (it would hold its last value there): extend "
                "the table or shorten the duration")

    def derivative(self, t: np.ndarray) -> np.ndarray:
        """Slope of the interpolant at times ``t`` (0 outside the table).

        Parameters
        ----------
        t : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            ``dr/dt``.
        """
        t = np.asarray(t, dtype=float)
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.t.size - 2)
        s = np.diff(self.r) / np.diff(self.t)
        out = s[i]
        return np.where((t < self.t[0]) | (t >= self.t[-1]), 0.0, out)

    def kernel_arrays(self) -> dict[str, np.ndarray]:
        """The reference as the kernels read it (the sines' arrays empty).

        Returns
        -------
        dict
            ``amps``, ``freqs``, ``phases``, ``table_t``, ``table_r``.
        """
        return {
            "amps": np.zeros(0),
            "freqs": np.zeros(0),
            "phases": np.zeros(0),
            "table_t": np.asarray(self.t),
            "table_r": np.asarray(self.r),
        }


Reference = SumOfSines | TableReference
