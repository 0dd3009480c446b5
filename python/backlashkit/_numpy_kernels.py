"""Plain-NumPy reference of the compiled drive-chain kernel (``backlashkit._core``).

Same algorithm as ``crates/core/src/hybrid/`` and ``chain/``, written for reading
and for parity tests, not for speed (about 100 times slower). The matrix exponentials
come from :func:`scipy.linalg.expm` rather than the kernel's own Taylor scaling and
squaring, so parity also checks that part. Signature and outputs match
``_core.simulate_chain``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from .errors import InputError

TAYLOR_TERMS = 18
SCAN_POINTS = 8
MAX_RHO_H = 0.5
MAX_EVENTS_PER_STEP = 64
EVENT_RTOL = 1e-12
GRAZE_RTOL = 1e-6
MIN_TWIST_SCALE = 1e-6
STATIONARY_START = 1e-9


class _Chain:
    """Twin of ``chain::ChainModel``: switches are the shafts, then the inertias with a
    breakaway torque ``fs > 0`` (``sticky``); with ``tau_i > 0`` the motor torque is
    the last state."""

    def __init__(self, J, f, k, d, theta, law, fc=None, fs=None, tau_i=0.0, ts=1.0,
                 track_angle=False):
        self.J, self.f, self.k, self.d, self.theta = (
            np.asarray(a, float) for a in (J, f, k, d, theta)
        )
        self.n = self.J.size
        self.fc = np.zeros(self.n) if fc is None or len(fc) == 0 else np.asarray(fc, float)
        self.fs = self.fc.copy() if fs is None or len(fs) == 0 else np.asarray(fs, float)
        self.tau_i = float(tau_i)
        self.loop = self.tau_i > 0
        self.s = 2 * self.n - 1 + int(self.loop) + int(track_angle)
        self.angle = self.s - 1 if track_angle else None
        self.sticky = [i for i in range(self.n) if self.fs[i] > 0]
        self.law = law
        self.ts = ts

    def free_dynamics(self, contact, viscous=True):
        n, s = self.n, self.s
        a = np.zeros((s, s))
        b = np.zeros(s)
        c = np.zeros(s)
        if viscous:
            a[np.arange(n), np.arange(n)] = -self.f / self.J
        if self.loop:
            q = 2 * n - 1
            a[0, q] = 1.0 / self.J[0]
            a[q, q] = -1.0 / self.tau_i
            b[q] = 1.0 / self.tau_i
        else:
            b[0] = 1.0 / self.J[0]
        if self.angle is not None:
            a[self.angle, 0] = 1.0
        for j, m in enumerate(contact):
            q = n + j
            a[q, j], a[q, j + 1] = 1.0, -1.0
            if m == 0:
                continue
            side = float(np.sign(m))
            k, dd = (2.0 * self.k[j], 0.0) if abs(m) == 2 else (self.k[j], self.d[j])
            off = -side * k * self.theta[j]
            for i, sign in ((j, -1.0), (j + 1, 1.0)):
                sc = sign / self.J[i]
                a[i, q] += sc * k
                a[i, j] += sc * dd
                a[i, j + 1] -= sc * dd
                c[i] += sc * off
        return a, b, c

    def dynamics(self, modes):
        contact, friction = modes[: self.n - 1], modes[self.n - 1 :]
        a, b, c = self.free_dynamics(contact)
        for r, m in enumerate(friction):
            i = self.sticky[r]
            if m == 0:
                a[i], b[i], c[i] = 0.0, 0.0, 0.0
            else:
                c[i] -= m * self.fc[i] / self.J[i]
        return a, b, c

    def _scale(self, j):
        return max(self.theta[j], MIN_TWIST_SCALE)

    # Guard functions are (h, hu, d, scale): h @ x + hu * u + d.
    def _twist(self, j, side):
        h = np.zeros(self.s)
        h[self.n + j] = 1.0
        return h, 0.0, -side * self.theta[j], self._scale(j)

    def _torque(self, j, side):
        h = np.zeros(self.s)
        h[self.n + j] = self.k[j]
        h[j], h[j + 1] = self.d[j], -self.d[j]
        return h, 0.0, -side * self.k[j] * self.theta[j], self.k[j] * self._scale(j)

    def _excess(self, j, side):
        """Damper minus spring torque on flank ``side``."""
        h = np.zeros(self.s)
        h[self.n + j] = -self.k[j]
        h[j], h[j + 1] = self.d[j], -self.d[j]
        return h, 0.0, side * self.k[j] * self.theta[j], self.k[j] * self._scale(j)

    def _drive_torque(self, i, contact):
        a, b, c = self.free_dynamics(contact, viscous=False)
        return a[i] * self.J[i], b[i] * self.J[i], c[i] * self.J[i], self.fs[i]

    def _shaft_guards(self, j, m):
        neg = lambda g: (-g[0], -g[1], -g[2], g[3])  # noqa: E731
        if self.law == 0:
            if m == 0:
                return [([self._twist(j, 1.0)], j, 1), ([neg(self._twist(j, -1.0))], j, -1)]
            if m == 1:
                return [([neg(self._twist(j, 1.0))], j, 0)]
            return [([self._twist(j, -1.0)], j, 0)]
        if m == 0:
            return [
                ([self._twist(j, 1.0), self._torque(j, 1.0)], j, 1),
                ([neg(self._twist(j, -1.0)), neg(self._torque(j, -1.0))], j, -1),
            ]
        if self.law == 1:
            return [([neg(self._torque(j, 1.0))] if m == 1 else [self._torque(j, -1.0)], j, 0)]
        return {
            1: [([neg(self._torque(j, 1.0))], j, 0), ([self._excess(j, 1.0)], j, 2)],
            2: [([neg(self._excess(j, 1.0))], j, 1)],
            -1: [([self._torque(j, -1.0)], j, 0), ([neg(self._excess(j, -1.0))], j, -2)],
            -2: [([self._excess(j, -1.0)], j, -1)],
        }[m]

    def _friction_guards(self, r, m, contact):
        i, index = self.sticky[r], self.n - 1 + r
        if m == 0:
            h, hu, dd, sc = self._drive_torque(i, contact)
            fs = self.fs[i]
            return [([(h, hu, dd - fs, sc)], index, 1), ([(-h, -hu, -dd - fs, sc)], index, -1)]
        h = np.zeros(self.s)
        h[i] = -float(m)
        return [([(h, 0.0, 0.0, self.fs[i] * self.ts / self.J[i])], index, 0)]

    def guards(self, modes):
        """List of (funcs, switch, target); funcs are normalised (h, hu, d) triples."""
        contact, friction = modes[: self.n - 1], modes[self.n - 1 :]
        out = []
        for j, m in enumerate(contact):
            out += self._shaft_guards(j, m)
        for r, m in enumerate(friction):
            out += self._friction_guards(r, m, contact)
        return [
            ([(h / sc, hu / sc, dd / sc) for h, hu, dd, sc in funcs], j, t) for funcs, j, t in out
        ]

    def _sub_mode(self, j, side, x):
        if self.law != 2 or side == 0:
            return side
        h, _hu, dd, _sc = self._excess(j, float(side))
        v = h @ x + dd
        return 2 * side if (side > 0 and v > 0) or (side < 0 and v < 0) else side

    def _stick_or_slip(self, i, contact, x, u):
        h, hu, dd, _ = self._drive_torque(i, contact)
        torque = h @ x + hu * u + dd
        return 1 if torque > self.fs[i] else (-1 if torque < -self.fs[i] else 0)

    def classify(self, x, u):
        n = self.n
        modes = []
        for j in range(n - 1):
            phi, th = x[n + j], self.theta[j]

            def sd(side, j=j, phi=phi, th=th):
                return self.k[j] * (phi - side * th) + self.d[j] * (x[j] - x[j + 1])

            if phi > th and (self.law == 0 or sd(1.0) > 0):
                side = 1
            elif phi < -th and (self.law == 0 or sd(-1.0) < 0):
                side = -1
            else:
                side = 0
            modes.append(self._sub_mode(j, side, x))
        contact = list(modes)
        for i in self.sticky:
            modes.append(int(np.sign(x[i])) if x[i] != 0 else self._stick_or_slip(i, contact, x, u))
        return modes

    def resolve(self, index, src, target, modes, x, u):
        """Twin of ``ChainModel::resolve``; may set a stuck speed to 0 in ``x``."""
        if index < self.n - 1:
            return self._sub_mode(index, target, x) if src == 0 else target
        if target != 0:
            return target
        i = self.sticky[index - (self.n - 1)]
        x[i] = 0.0
        return self._stick_or_slip(i, modes[: self.n - 1], x, u)

    def extreme_modes(self):
        slip = [1] * len(self.sticky)
        out = [[0] * (self.n - 1) + slip, [1] * (self.n - 1) + slip]
        if self.law == 2:
            out.append([2] * (self.n - 1) + slip)
        return out


def _spectral_radius(a):
    return float(np.max(np.abs(np.linalg.eigvals(a)))) if a.size else 0.0


class _Mode:
    def __init__(self, chain, modes, h):
        self.a, self.b, self.c = chain.dynamics(modes)
        s = chain.s
        # F = int_0^h exp(A t) dt from the block exponential [[A, I], [0, 0]].
        big = np.zeros((2 * s, 2 * s))
        big[:s, :s] = self.a
        big[:s, s:] = np.eye(s)
        eb = expm(big * h)
        self.e = eb[:s, :s]
        f = eb[:s, s:]
        self.fb = f @ self.b
        self.fc = f @ self.c
        self.guards = chain.guards(modes)


def _taylor(md, x0, u, rem):
    v = np.zeros((TAYLOR_TERMS + 1, x0.size))
    v[0] = x0
    d = md.a @ x0 + md.b * u + md.c
    coef = rem
    for k in range(1, TAYLOR_TERMS + 1):
        if k > 1:
            d = md.a @ d
            coef *= rem / k
        v[k] = d * coef
    return v


def _poly(p, s):
    return np.polynomial.polynomial.polyval(s, p)


def _poly_deriv(p, s):
    return np.polynomial.polynomial.polyval(s, np.arange(1, p.size) * p[1:])


def _bisect(pred, lo, hi):
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if pred(mid):
            lo = mid
        else:
            hi = mid
    return hi


def _crossing_in(polys, lo, end):
    """Twin of ``hybrid::crossing_in``: the guard's crossing in ``[lo, end]``."""

    def value(s):
        return min(_poly(p, s) for p in polys)

    if value(lo) < 0:
        return _bisect(lambda s: value(s) <= 0, lo, end)
    p = min(polys, key=lambda q: _poly(q, lo))
    if _poly_deriv(p, lo) >= 0:
        return lo
    bottom = _bisect(lambda s: _poly_deriv(p, s) <= 0, lo, end) if _poly_deriv(p, end) > 0 else end
    if value(bottom) < 0:
        return _bisect(lambda s: value(s) <= 0, bottom, end)
    return lo


def _shallow_peak(polys, s):
    """Twin of ``hybrid::shallow_peak``."""
    best = None
    for p in polys:
        if _poly_deriv(p, s) > 0 and _poly_deriv(p, 1.0) < 0:
            at = _bisect(lambda x, p=p: _poly_deriv(p, x) > 0, s, 1.0)
            v = _poly(p, at)
            if best is None or v < best[1]:
                best = (at, v)
    return best if best is not None and best[1] < GRAZE_RTOL else None


def _find_crossing(md, v, u, t_start, rem, grazes):
    best = None
    close = []
    for gi, (funcs, shaft, _target) in enumerate(md.guards):
        polys = []
        for h, hu, dd in funcs:
            p = v @ h
            p[0] += dd + hu * u
            polys.append(p)

        def value(s, polys=polys):
            return min(_poly(p, s) for p in polys)

        limit = 1.0 if best is None else best[0]
        lo = 0.0
        for j in range(1, SCAN_POINTS + 1):
            hi = j / SCAN_POINTS
            if lo >= limit:
                break
            crossing_before = None
            for p in polys:
                if _poly_deriv(p, lo) > 0 and _poly_deriv(p, hi) < 0:
                    se = _bisect(lambda s, p=p: _poly_deriv(p, s) > 0, lo, hi)
                    ve = value(se)
                    if ve > EVENT_RTOL:
                        crossing_before = (
                            se if crossing_before is None else min(crossing_before, se)
                        )
                    stationary_start = p[0] == 0.0 and lo == 0.0 and se <= STATIONARY_START
                    if -GRAZE_RTOL < ve <= EVENT_RTOL and not stationary_start:  # a near miss
                        close.append((se, (t_start + se * rem, shaft, ve)))
            if crossing_before is not None:
                end = crossing_before
            elif value(hi) > EVENT_RTOL:
                end = hi
            else:
                end = None
            if end is not None:
                s = _crossing_in(polys, lo, end)
                peak = _shallow_peak(polys, s)
                if peak is not None:  # barely over the boundary: as sensitive as a near miss
                    close.append((s, (t_start + peak[0] * rem, shaft, peak[1])))
                if best is None or s < best[0]:
                    best = (s, gi)
                break
            lo = hi
    limit = math.inf if best is None else best[0]
    grazes.extend(g for s, g in close if s <= limit)
    return best


def _step_is_clear(md, x, xn, ui, h):
    """The per-step check of the fast path: no guard positive at the step's end and
    no extremum towards a boundary inside the step."""
    for funcs, _switch, _target in md.guards:
        val = math.inf
        for hv, hu, dd in funcs:
            g0, g1 = hv @ x + hu * ui + dd, hv @ xn + hu * ui + dd
            val = min(val, g1)
            ha, hb, hc = hv @ md.a, hv @ md.b, hv @ md.c
            s0, s1 = ha @ x + hb * ui + hc, ha @ xn + hb * ui + hc
            if s0 > 0 and s1 < 0 and max(g0 + s0 * h, g1 - s1 * h) > -GRAZE_RTOL:
                return False
        if val > 0:
            return False
    return True


def _slow_step(chain, mode, modes, x, ui, start, h, events, grazes):
    """Twin of ``Engine::slow_step``: one internal step with every crossing located."""
    done = 0.0
    for _ in range(MAX_EVENTS_PER_STEP):
        rem = h - done
        md = mode(modes)
        v = _taylor(md, x, ui, rem)
        hit = _find_crossing(md, v, ui, start + done, rem, grazes)
        if hit is None:
            return np.polynomial.polynomial.polyval(1.0, v), modes
        s, gi = hit
        x = np.array([_poly(v[:, q], s) for q in range(chain.s)])
        _funcs, switch, target = md.guards[gi]
        modes = list(modes)
        src = modes[switch]
        modes[switch] = target
        modes[switch] = chain.resolve(switch, src, target, modes, x, ui)
        events.append((start + done + s * rem, switch, src, modes[switch]))
        done += s * rem
    raise InputError(f"contact chatter at t = {start + done} s")


def _reported(chain, modes_out, events):
    """Twin of ``chain::report_events``: Modelica's sub-modes as their flank, friction
    switches indexed ``N - 1 + inertia``."""
    ns = chain.n - 1
    if chain.law == 2:
        modes_out[:, :ns] = np.sign(modes_out[:, :ns])
    out = []
    for time, switch, src, dst in events:
        if switch < ns:
            src, dst = int(np.sign(src)), int(np.sign(dst))
            if src != dst:
                out.append((time, switch, src, dst))
        else:
            out.append((time, ns + chain.sticky[switch - ns], src, dst))
    return np.array(out, dtype=float).reshape(-1, 4)


def simulate_chain(J, f, k, d, theta, law, t0, ts, u, x0, fc=None, fs=None, tau_i=0.0,
                   track_angle=False):
    """NumPy twin of ``_core.simulate_chain``; same arguments and outputs."""
    chain = _Chain(J, f, k, d, theta, law, fc, fs, tau_i, ts, track_angle)
    rho = max(_spectral_radius(chain.dynamics(m)[0]) for m in chain.extreme_modes())
    substeps = max(1, math.ceil(rho * ts / MAX_RHO_H))
    h = ts / substeps
    cache: dict[tuple, _Mode] = {}

    def mode(modes):
        key = tuple(modes)
        if key not in cache:
            cache[key] = _Mode(chain, modes, h)
        return cache[key]

    n = len(u)
    x = np.array(x0, dtype=float)
    modes = chain.classify(x, u[0])
    states = np.empty((n, chain.s))
    modes_out = np.empty((n, len(modes)), dtype=np.int8)
    events: list[tuple] = []
    grazes: list[tuple] = []
    states[0], modes_out[0] = x, modes
    for i in range(n - 1):
        ui = u[i]
        for sub in range(substeps):
            md = mode(modes)
            xn = md.e @ x + md.fb * ui + md.fc
            if _step_is_clear(md, x, xn, ui, h):
                x = xn
                continue
            start = t0 + i * ts + sub * h
            x, modes = _slow_step(chain, mode, modes, x, ui, start, h, events, grazes)
        states[i + 1], modes_out[i + 1] = x, modes
    ns = chain.n - 1
    grazes = [(t, s if s < ns else ns + chain.sticky[s - ns], m) for t, s, m in grazes]
    return (
        states,
        modes_out,
        _reported(chain, modes_out, events),
        np.array(grazes, dtype=float).reshape(-1, 3),
    )
