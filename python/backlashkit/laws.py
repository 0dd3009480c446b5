"""Shaft laws: how the shaft torque behaves once the backlash gap is closed."""

from __future__ import annotations

import enum

import numpy as np

from .errors import InputError

__all__ = ["ShaftLaw"]


class ShaftLaw(str, enum.Enum):
    """Contact law of an elastic shaft with backlash.

    With ``tau_c = k (phi - theta)`` the spring torque and ``tau_d = d dphi/dt`` the
    damper torque on the positive flank (``phi >= theta``; mirrored on the negative
    flank, with ``tau_c = k (phi + theta)``):

    ``PAPER`` (``"paper"``)
        Paper A, eq. 2, as written: in contact the torque is ``tau_c + tau_d`` whatever
        its sign, so the damper can *pull* (negative torque while ``phi > theta``) just
        before contact is lost. Contact is lost when the twist ``phi`` re-enters the gap
        ``(-theta, theta)``.
    ``NO_PULL`` (``"no-pull"``)
        ``max(tau_c + tau_d, 0)``: the flanks separate as soon as the damper would pull,
        and re-engage when the spring-damper torque becomes positive again. This is
        Modelica's event-based ``ElastoBacklash2`` (and the clamp of Nordin, Galic &
        Gutman); it is *not* Modelica's ``ElastoBacklash``.
    ``MODELICA`` (``"modelica"``)
        Modelica's ``ElastoBacklash``: ``tau_c + min(tau_c, tau_d)``, and 0 where
        ``tau_c + tau_d <= 0``. The damper acts only while its torque is below the
        spring's; above it the spring torque is doubled instead (so the torque rises
        from 0 at impact, without a jump).

    The three laws are identical when the shaft damping ``d`` (``f_sh``) is zero.

    Parameters
    ----------
    value : {"paper", "no-pull", "modelica"}
        The law's name (``ShaftLaw("no-pull")``); :meth:`parse` also accepts members.
    """

    PAPER = "paper"
    NO_PULL = "no-pull"
    MODELICA = "modelica"

    @classmethod
    def parse(cls, law: ShaftLaw | str) -> ShaftLaw:
        """The :class:`ShaftLaw` named by ``law``.

        Parameters
        ----------
        law : ShaftLaw or str
            A member, or its value (``"paper"``, ``"no-pull"``, ``"modelica"``).

        Returns
        -------
        ShaftLaw
            The member.
        """
        if isinstance(law, cls):
            return law
        try:
            return cls(str(law))
        except ValueError:
            choices = ", ".join(repr(m.value) for m in cls)
            raise InputError(f"law must be one of {choices}, got {law!r}") from None

    @property
    def code(self) -> int:
        """Integer code understood by the compiled kernels."""
        return {ShaftLaw.PAPER: 0, ShaftLaw.NO_PULL: 1, ShaftLaw.MODELICA: 2}[self]

    def contact_torque(
        self, spring: np.ndarray, damper: np.ndarray, side: np.ndarray
    ) -> np.ndarray:
        """The shaft torque on a closed flank, elementwise.

        Parameters
        ----------
        spring : numpy.ndarray
            Spring torque ``tau_c = k (phi - side theta)`` in N m.
        damper : numpy.ndarray
            Damper torque ``tau_d = d dphi/dt`` in N m.
        side : numpy.ndarray
            The flank: +1 positive, -1 negative (0 gives 0: the gap).

        Returns
        -------
        numpy.ndarray
            The law's torque in N m (0 in the gap).
        """
        spring, damper, side = np.broadcast_arrays(
            np.asarray(spring, float), np.asarray(damper, float), np.asarray(side)
        )
        # On the negative flank every law is the mirror image: flip, apply, flip back.
        c, dd = side * spring, side * damper
        if self is ShaftLaw.PAPER:
            torque = c + dd
        elif self is ShaftLaw.NO_PULL:
            torque = np.maximum(c + dd, 0.0)
        else:
            torque = np.where(c + dd <= 0.0, 0.0, c + np.minimum(c, dd))
        return np.where(side != 0, side * torque, 0.0) + 0.0  # no -0.0
