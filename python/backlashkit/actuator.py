"""Actuators: how the motor torque follows its set-point.

A drive's torque is not applied exactly: it is the output of a current loop. Its
closed-loop response is close to first order, ``tau_i dT/dt = T_ref - T``, with a time
constant ``tau_i`` of about a millisecond. :class:`CurrentLoop` models it; the
simulator then carries the motor torque ``T`` as one more state, so the zero-order-hold
flow stays exact (``T`` follows ``T_ref (1 - exp(-t / tau_i))`` inside each sample).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import InputError

__all__ = ["CurrentLoop"]


@dataclass(frozen=True)
class CurrentLoop:
    """A first-order current loop between the torque set-point and the motor torque.

    Parameters
    ----------
    tau_i : float
        Time constant in s, finite and >= 0; 0 applies the set-point exactly (the same
        as no actuator).

    Notes
    -----
    A simulation starts the loop settled at the first set-point sample, as a drive that
    has held it: a step at ``t[0]`` shows no lag (give ``initial_state`` one more entry,
    the motor torque, to start it elsewhere, e.g. at 0).

    Examples
    --------
    >>> from backlashkit import CurrentLoop
    >>> CurrentLoop(tau_i=1e-3)
    CurrentLoop(tau_i=0.001)
    """

    tau_i: float = 0.0

    def __post_init__(self) -> None:
        value = self.tau_i
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not ok or not math.isfinite(value) or value < 0:
            raise InputError(
                "tau_i must be a finite time constant >= 0 s (0: the torque set-point is "
                f"applied exactly), got {value!r}"
            )
        object.__setattr__(self, "tau_i", float(value))

    @property
    def exact(self) -> bool:
        """Whether the set-point is applied exactly (``tau_i == 0``)."""
        return self.tau_i == 0.0
