"""Shaft laws: how the shaft torque behaves once the backlash gap is closed."""

from __future__ import annotations

import enum

from .errors import InputError

__all__ = ["ShaftLaw"]


class ShaftLaw(str, enum.Enum):
    """Contact law of an elastic shaft with backlash.

    ``PAPER`` (``"paper"``)
        Paper A, eq. 2, as written: in contact the torque is
        ``k (phi - theta) + d dphi/dt`` whatever its sign, so the damper can *pull*
        (negative torque while ``phi > theta``) just before contact is lost. Contact is
        lost when the twist ``phi`` re-enters the gap ``(-theta, theta)``.
    ``NO_PULL`` (``"no-pull"``)
        The clamp of Modelica's ``ElastoBacklash`` and of Nordin, Galic & Gutman:
        in contact the torque is ``max(k (phi - theta) + d dphi/dt, 0)`` (mirrored on
        the other flank), so the flanks separate as soon as the damper would pull, and
        re-engage when the spring-damper torque becomes positive again.

    The two laws are identical when the shaft damping ``d`` (``f_sh``) is zero.

    Parameters
    ----------
    value : {"paper", "no-pull"}
        The law's name (``ShaftLaw("no-pull")``); :meth:`parse` also accepts members.
    """

    PAPER = "paper"
    NO_PULL = "no-pull"

    @classmethod
    def parse(cls, law: ShaftLaw | str) -> ShaftLaw:
        """The :class:`ShaftLaw` named by ``law``.

        Parameters
        ----------
        law : ShaftLaw or str
            A member, or its value (``"paper"``, ``"no-pull"``).

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
        return 0 if self is ShaftLaw.PAPER else 1
