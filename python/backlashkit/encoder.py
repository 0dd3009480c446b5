"""Encoders: what a drive measures of its positions and speeds.

An incremental encoder of ``N`` counts per revolution reports the angle quantised to
``2 pi / N``: ``count = floor(phi N / (2 pi))``. A drive's speed is the difference of
two successive counts over the sample time, ``w_k = (count_k - count_{k-1}) (2 pi / N)
/ Ts``, often smoothed by the drive's speed observer, here a first-order filter of
time constant ``tau_w`` (discretised exactly for a signal held over each sample).

:class:`Encoder` measures one angle; :func:`measure_encoders` measures motor and load of
a :class:`~backlashkit.simulate.DriveResponse` (its exact absolute angles
``phi_motor``, ``phi_load``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import validate as v
from .errors import InputError

if TYPE_CHECKING:
    from .simulate import DriveResponse

__all__ = ["Encoder", "EncoderReading", "measure_encoders"]

#: Fewest counts per revolution of an encoder (below one count the angle is not
#: measured at all).
MIN_COUNTS = 1.0


@dataclass(frozen=True)
class EncoderReading:
    """What an encoder delivers on a time grid.

    Parameters
    ----------
    t : numpy.ndarray
        Time in s, shape ``(n,)``.
    counts : numpy.ndarray
        Encoder counts, ``int64``, shape ``(n,)``.
    angle : numpy.ndarray
        The counts as an angle in rad (``counts * 2 pi / N``).
    speed : numpy.ndarray
        Difference of successive counts over the sample time in rad/s, through the
        speed filter if any. The first sample has no predecessor: it repeats the
        second.
    """

    t: np.ndarray
    counts: np.ndarray
    angle: np.ndarray
    speed: np.ndarray


@dataclass(frozen=True)
class Encoder:
    """An incremental encoder with a difference speed estimate.

    Parameters
    ----------
    counts_per_rev : float
        Resolution ``N`` in counts per revolution, >= 1 (quadrature included: a
        2500-line encoder read in quadrature has ``N = 10000``).
    tau_w : float, optional
        Time constant in s of the first-order speed filter (the drive's speed
        observer), >= 0; default 0 (the raw difference of counts).

    Examples
    --------
    >>> import numpy as np
    >>> from backlashkit import Encoder
    >>> t = np.arange(4) * 1e-3
    >>> Encoder(1000).measure(t, 2 * np.pi * 3.3 * t).counts  # 3.3 rev/s
    array([0, 3, 6, 9])
    """

    counts_per_rev: float
    tau_w: float = 0.0

    def __post_init__(self) -> None:
        n = v.finite_scalar("counts_per_rev", self.counts_per_rev)
        if not n >= MIN_COUNTS:
            raise InputError(
                f"counts_per_rev must be >= {MIN_COUNTS:g} count per revolution (an encoder "
                f"resolves at least one count per turn), got {self.counts_per_rev!r}"
            )
        object.__setattr__(self, "counts_per_rev", n)
        object.__setattr__(self, "tau_w", v.nonnegative("tau_w", self.tau_w))

    @property
    def resolution(self) -> float:
        """Angle of one count in rad, ``2 pi / N``."""
        return 2.0 * math.pi / self.counts_per_rev

    def counts(self, angle: np.ndarray) -> np.ndarray:
        """Counts of angles in rad: ``floor(angle / resolution)``, ``int64``.

        Parameters
        ----------
        angle : array_like
            Absolute angles in rad.

        Returns
        -------
        numpy.ndarray
            The counts.
        """
        a = v.finite_array("angle", angle)
        return np.floor(a / self.resolution).astype(np.int64)

    def measure(self, t: np.ndarray, angle: np.ndarray) -> EncoderReading:
        """Counts and difference speed of an angle sampled on a uniform grid.

        Parameters
        ----------
        t : array_like
            Uniform time grid in s, at least 2 samples.
        angle : array_like
            Absolute angle in rad at ``t``.

        Returns
        -------
        EncoderReading
            Counts, quantised angle and speed.
        """
        t_arr, ts = v.time_grid(t)
        counts = self.counts(angle)
        if counts.shape != t_arr.shape:
            raise InputError(f"angle must have one sample per time step ({t_arr.size}), "
                             f"got {counts.size}")
        raw = np.empty(t_arr.size)
        raw[1:] = np.diff(counts) * (self.resolution / ts)
        raw[0] = raw[1]
        return EncoderReading(t_arr, counts, counts * self.resolution,
                              self._filter(raw, ts))

    def _filter(self, speed: np.ndarray, ts: float) -> np.ndarray:
        """First-order filter ``tau_w dy/dt = x - y``, exact for ``x`` held over each
        sample: ``y_k = a y_{k-1} + (1 - a) x_k``, ``a = exp(-ts / tau_w)``."""
        if self.tau_w == 0.0:
            return speed
        from scipy.signal import lfilter

        a = math.exp(-ts / self.tau_w)
        y, _ = lfilter([1.0 - a], [1.0, -a], speed, zi=[a * speed[0]])
        return y


def measure_encoders(
    response: DriveResponse, motor: Encoder, load: Encoder | None = None
) -> dict[str, np.ndarray]:
    """Encoder readings of a simulated drive's motor and load.

    Parameters
    ----------
    response : DriveResponse
        A simulation; its exact absolute angles ``phi_motor`` and ``phi_load`` are
        measured.
    motor : Encoder
        The motor's encoder.
    load : Encoder, optional
        The load's encoder; default the same as the motor's.

    Returns
    -------
    dict of str to numpy.ndarray
        Columns ``t``, ``torque``, ``w_motor``, ``w_load`` (encoder speeds, the format
        identification reads) and ``count_motor``, ``count_load``.
    """
    load = motor if load is None else load
    m = motor.measure(response.t, response.phi_motor)
    ld = load.measure(response.t, response.phi_load)
    return {
        "t": response.t,
        "torque": response.torque,
        "w_motor": m.speed,
        "w_load": ld.speed,
        "count_motor": m.counts,
        "count_load": ld.counts,
    }
