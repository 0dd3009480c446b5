"""The model of :mod:`backlashkit.verify`'s reference, written from the physics.

Kept apart from the compiled kernel's model (``crates/core/src/chain``): the right-hand
side is the force balance of each inertia, the contact torque is the shaft law's
formula, and every matrix the reference needs is obtained by probing those formulas
(they are affine in the state for fixed modes).

Switches: one per shaft (0 gap, +-1 on a flank; Modelica's law also +-2, the flank's
doubled-spring branch), then one per inertia with a breakaway torque ``fs > 0`` (+1 /
-1 slipping forwards / backwards, 0 stuck). With a current loop the motor torque is
the last state.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .laws import ShaftLaw
from .response import FrictionEvent

_FLANK = {1: "positive", -1: "negative"}
_DIRECTION = {1: "positive", -1: "negative", 0: "none"}


@dataclass
class ReferenceModel:
    """Parameters, physics and switching functions of the reference's chain."""

    J: np.ndarray
    f: np.ndarray
    k: np.ndarray
    d: np.ndarray
    theta: np.ndarray
    law: ShaftLaw
    twist_scale: np.ndarray
    fc: np.ndarray
    fs: np.ndarray
    tau_i: float = 0.0
    speed_scale: float = 1.0
    _fields: dict = field(default_factory=dict)
    _guards: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.J.size

    @property
    def s(self) -> int:
        return 2 * self.J.size - 1 + int(self.tau_i > 0)

    @property
    def sticky(self) -> list[int]:
        return [i for i in range(self.n) if self.fs[i] > 0]

    def scale(self, index: int) -> float:
        """Scale of a switch's functions: rad for shafts; friction functions are
        normalised (by the speed scale, or the breakaway torque)."""
        if index < self.n - 1:
            return float(self.twist_scale[index])
        return 1.0

    # ----------------------------------------------------------------- physics

    def shaft_torques(self, modes, x) -> np.ndarray:
        """Torque of every shaft: 0 in the gap, the law's branch on a flank."""
        n = self.n
        w, phi = x[:n], x[n : 2 * n - 1]
        contact = np.asarray(modes[: n - 1], dtype=float)
        side = np.sign(contact)
        spring = self.k * (phi - side * self.theta)
        damper = self.d * (w[:-1] - w[1:])
        doubled = np.abs(contact) == 2  # Modelica: the spring's torque, twice
        return np.where(side == 0, 0.0, np.where(doubled, 2.0 * spring, spring + damper))

    def drive_torques(self, modes, u: float, x) -> np.ndarray:
        """Torque on every inertia from the motor and the shafts (no friction)."""
        n = self.n
        shaft = self.shaft_torques(modes, x)
        load = np.zeros(n)
        load[0] += x[2 * n - 1] if self.tau_i > 0 else u
        load[:-1] -= shaft
        load[1:] += shaft
        return load

    def rhs_direct(self, modes, u: float, x: np.ndarray) -> np.ndarray:
        """Time derivative of the state from the force balance of each inertia."""
        n = self.n
        w = x[:n]
        load = self.drive_torques(modes, u, x) - self.f * w
        wdot = load / self.J
        for r, i in enumerate(self.sticky):
            m = modes[n - 1 + r]
            wdot[i] = 0.0 if m == 0 else wdot[i] - m * self.fc[i] / self.J[i]
        out = [wdot, w[:-1] - w[1:]]
        if self.tau_i > 0:
            out.append([(u - x[2 * n - 1]) / self.tau_i])
        return np.concatenate(out)

    @staticmethod
    def _probe(fun, size: int) -> tuple[np.ndarray, np.ndarray]:
        """``(A, c)`` of an affine ``fun(x) = A x + c``, probed at 0 and unit vectors."""
        c = np.asarray(fun(np.zeros(size)), dtype=float)
        a = np.empty((c.size, size))
        for i in range(size):
            e = np.zeros(size)
            e[i] = 1.0
            a[:, i] = np.asarray(fun(e), dtype=float) - c
        return a, c

    def field(self, modes: tuple[int, ...], u: float) -> tuple[np.ndarray, np.ndarray]:
        """``(A, c)`` with ``dx/dt = A x + c`` in ``modes`` under input ``u``."""
        key = (modes, u)
        if key not in self._fields:
            self._fields[key] = self._probe(lambda x: self.rhs_direct(modes, u, x), self.s)
        return self._fields[key]

    # ----------------------------------------------------------------- switching

    def _shaft_guards(self, j: int, m: int) -> list:
        """Guards of shaft ``j`` in rad (torques divided by the stiffness)."""
        n, s = self.n, self.s
        ph = np.zeros(s)
        ph[n + j] = 1.0
        rate = np.zeros(s)  # d/k * dphi_j/dt
        rate[j], rate[j + 1] = self.d[j] / self.k[j], -self.d[j] / self.k[j]
        th = self.theta[j]
        one = lambda h, h0: (h[None, :], np.array([h0]))  # noqa: E731
        if self.law is ShaftLaw.PAPER:
            if m == 0:
                return [(1, *one(ph, -th)), (-1, *one(-ph, -th))]
            return [(0, *one(-ph, th))] if m == 1 else [(0, *one(ph, th))]
        if m == 0:
            # enter a flank when phi passes theta AND the spring-damper torque pushes
            return [
                (1, np.stack([ph, ph + rate]), np.array([-th, -th])),
                (-1, np.stack([-ph, -ph - rate]), np.array([-th, -th])),
            ]
        if self.law is ShaftLaw.NO_PULL:
            return [(0, *one(-(ph + rate), th))] if m == 1 else [(0, *one(ph + rate, th))]
        # Modelica: tau_c + min(tau_c, tau_d); the branch changes where tau_d = tau_c
        return {
            1: [(0, *one(-(ph + rate), th)), (2, *one(rate - ph, th))],
            2: [(1, *one(ph - rate, -th))],
            -1: [(0, *one(ph + rate, th)), (-2, *one(ph - rate, th))],
            -2: [(-1, *one(rate - ph, -th))],
        }[m]

    def _friction_guards(self, r: int, m: int, modes, u: float) -> list:
        i = self.sticky[r]
        if m != 0:  # slipping: the speed crosses zero (relative to the speed scale)
            h = np.zeros(self.s)
            h[i] = -m / self.speed_scale
            return [(0, h[None, :], np.array([0.0]))]
        # stuck: the torque on it exceeds the breakaway torque (relative to it)
        a, c = self._probe(lambda x: self.drive_torques(modes, u, x)[i : i + 1], self.s)
        fs = self.fs[i]
        return [(1, a / fs, (c - fs) / fs), (-1, -a / fs, (-c - fs) / fs)]

    def guards(self, modes: tuple[int, ...], u: float) -> list:
        """Switching functions of ``modes`` under input ``u``: ``(index, target, H,
        h0)``, switch ``index`` goes to ``target`` when ``min_r (H[r] @ x + h0[r])``
        crosses from ``<= 0`` to ``> 0``."""
        key = (modes, u)
        if key in self._guards:
            return self._guards[key]
        out = []
        for j in range(self.n - 1):
            out += [(j, *g) for g in self._shaft_guards(j, modes[j])]
        for r in range(len(self.sticky)):
            out += [(self.n - 1 + r, *g) for g in
                    self._friction_guards(r, modes[self.n - 1 + r], modes, u)]
        self._guards[key] = out
        return out

    def _branch(self, j: int, side: int, x) -> int:
        """Modelica's branch on flank ``side``: 2 side where the damper's torque exceeds
        the spring's (outwards), else ``side``."""
        if self.law is not ShaftLaw.MODELICA or side == 0:
            return side
        n = self.n
        spring = self.k[j] * (x[n + j] - side * self.theta[j])
        damper = self.d[j] * (x[j] - x[j + 1])
        return 2 * side if side * (damper - spring) > 0 else side

    def _stick_or_slip(self, i: int, modes, u: float, x) -> int:
        torque = self.drive_torques(modes, u, x)[i]
        return 1 if torque > self.fs[i] else (-1 if torque < -self.fs[i] else 0)

    def classify(self, x: np.ndarray, u: float) -> tuple[int, ...]:
        """Modes of a state, strictly (a state exactly on a flank is in the gap; the
        reference's settling then decides from the direction of motion)."""
        n = self.n
        out = []
        for j in range(n - 1):
            phi, th = x[n + j], self.theta[j]
            sd = self.k[j] * phi + self.d[j] * (x[j] - x[j + 1])
            if phi > th and (self.law is ShaftLaw.PAPER or sd - self.k[j] * th > 0):
                out.append(self._branch(j, 1, x))
            elif phi < -th and (self.law is ShaftLaw.PAPER or sd + self.k[j] * th < 0):
                out.append(self._branch(j, -1, x))
            else:
                out.append(0)
        for i in self.sticky:
            w = x[i]
            out.append((1 if w > 0 else -1) if w != 0 else self._stick_or_slip(i, out, u, x))
        return tuple(out)

    def switch(self, modes, index: int, target: int, t: float, x: np.ndarray, u: float):
        """Apply a switch at ``t``: the modes after it, its events (contact changes
        as ``(time, shaft, kind, flank)``, friction changes as :class:`FrictionEvent`),
        and the state (a stuck speed is set to exactly 0 in ``x``)."""
        src = modes[index]
        out = list(modes)
        events = []
        if index < self.n - 1:
            if src == 0:
                target = self._branch(index, target, x)
            out[index] = target
            if np.sign(src) != np.sign(target):  # branch changes are no contact change
                if src != 0:
                    events.append((t, index, "contact_lost", _FLANK[int(np.sign(src))]))
                if target != 0:
                    events.append((t, index, "contact_made", _FLANK[int(np.sign(target))]))
            return tuple(out), events
        i = self.sticky[index - (self.n - 1)]
        if target == 0:  # the speed crossed zero: stick, or slip the other way
            x[i] = 0.0
            target = self._stick_or_slip(i, out, u, x)
        out[index] = target
        kind = "stuck" if target == 0 else ("breakaway" if src == 0 else "reversal")
        return tuple(out), [FrictionEvent(float(t), i, kind, _DIRECTION[target])]
