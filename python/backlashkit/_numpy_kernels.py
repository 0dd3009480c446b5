"""Plain-NumPy reference of the compiled drive-chain kernel (``backlashkit._core``).

Same algorithm as ``crates/core/src/hybrid.rs`` and ``chain.rs``, written for reading
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


class _Chain:
    def __init__(self, J, f, k, d, theta, law):
        self.J, self.f, self.k, self.d, self.theta = (
            np.asarray(a, float) for a in (J, f, k, d, theta)
        )
        self.n = self.J.size
        self.s = 2 * self.n - 1
        self.law = law

    def dynamics(self, modes):
        n, s = self.n, self.s
        a = np.zeros((s, s))
        b = np.zeros(s)
        c = np.zeros(s)
        a[np.arange(n), np.arange(n)] = -self.f / self.J
        b[0] = 1.0 / self.J[0]
        for j, m in enumerate(modes):
            q = n + j
            a[q, j], a[q, j + 1] = 1.0, -1.0
            if m == 0:
                continue
            k, dd, off = self.k[j], self.d[j], -m * self.k[j] * self.theta[j]
            for i, sign in ((j, -1.0), (j + 1, 1.0)):
                sc = sign / self.J[i]
                a[i, q] += sc * k
                a[i, j] += sc * dd
                a[i, j + 1] -= sc * dd
                c[i] += sc * off
        return a, b, c

    def _scale(self, j):
        return max(self.theta[j], MIN_TWIST_SCALE)

    def _twist(self, j, side):
        h = np.zeros(self.s)
        h[self.n + j] = 1.0
        return h, -side * self.theta[j], self._scale(j)

    def _torque(self, j, side):
        h = np.zeros(self.s)
        h[self.n + j] = self.k[j]
        h[j], h[j + 1] = self.d[j], -self.d[j]
        return h, -side * self.k[j] * self.theta[j], self.k[j] * self._scale(j)

    def guards(self, modes):
        """List of (funcs, shaft, target); funcs are normalised (h, d) pairs."""
        neg = lambda g: (-g[0], -g[1], g[2])  # noqa: E731
        out = []
        for j, m in enumerate(modes):
            if self.law == 0:
                if m == 0:
                    out += [([self._twist(j, 1.0)], j, 1), ([neg(self._twist(j, -1.0))], j, -1)]
                elif m == 1:
                    out.append(([neg(self._twist(j, 1.0))], j, 0))
                else:
                    out.append(([self._twist(j, -1.0)], j, 0))
            else:
                if m == 0:
                    out.append(([self._twist(j, 1.0), self._torque(j, 1.0)], j, 1))
                    out.append(([neg(self._twist(j, -1.0)), neg(self._torque(j, -1.0))], j, -1))
                elif m == 1:
                    out.append(([neg(self._torque(j, 1.0))], j, 0))
                else:
                    out.append(([self._torque(j, -1.0)], j, 0))
        return [([(h / sc, dd / sc) for h, dd, sc in funcs], j, t) for funcs, j, t in out]

    def classify(self, x):
        n = self.n
        modes = []
        for j in range(n - 1):
            phi, th = x[n + j], self.theta[j]

            def sd(side, j=j, phi=phi, th=th):
                return self.k[j] * (phi - side * th) + self.d[j] * (x[j] - x[j + 1])

            if phi > th and (self.law == 0 or sd(1.0) > 0):
                modes.append(1)
            elif phi < -th and (self.law == 0 or sd(-1.0) < 0):
                modes.append(-1)
            else:
                modes.append(0)
        return modes


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


def _find_crossing(md, v, t_start, rem, grazes):
    best = None
    close = []
    for gi, (funcs, shaft, _target) in enumerate(md.guards):
        polys = []
        for h, dd in funcs:
            p = v @ h
            p[0] += dd
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
                    if -GRAZE_RTOL < ve <= EVENT_RTOL:  # a near miss
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


def simulate_chain(J, f, k, d, theta, law, t0, ts, u, x0):
    """NumPy twin of ``_core.simulate_chain``; same arguments and outputs."""
    chain = _Chain(J, f, k, d, theta, law)
    rho = max(
        _spectral_radius(chain.dynamics(m)[0]) for m in ([0] * (chain.n - 1), [1] * (chain.n - 1))
    )
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
    modes = chain.classify(x)
    states = np.empty((n, chain.s))
    modes_out = np.empty((n, chain.n - 1), dtype=np.int8)
    events: list[tuple] = []
    grazes: list[tuple] = []
    states[0], modes_out[0] = x, modes
    for i in range(n - 1):
        ui = u[i]
        for sub in range(substeps):
            md = mode(modes)
            xn = md.e @ x + md.fb * ui + md.fc
            fast = True
            for funcs, _shaft, _target in md.guards:
                val = math.inf
                for hv, dd in funcs:
                    g0, g1 = hv @ x + dd, hv @ xn + dd
                    val = min(val, g1)
                    ha, hb, hc = hv @ md.a, hv @ md.b, hv @ md.c
                    s0, s1 = ha @ x + hb * ui + hc, ha @ xn + hb * ui + hc
                    if s0 > 0 and s1 < 0 and max(g0 + s0 * h, g1 - s1 * h) > -GRAZE_RTOL:
                        fast = False
                if val > 0:
                    fast = False
            if fast:
                x = xn
                continue
            start = t0 + i * ts + sub * h
            done = 0.0
            for _ in range(MAX_EVENTS_PER_STEP):
                rem = h - done
                md = mode(modes)
                v = _taylor(md, x, ui, rem)
                hit = _find_crossing(md, v, start + done, rem, grazes)
                if hit is None:
                    x = np.polynomial.polynomial.polyval(1.0, v)
                    break
                s, gi = hit
                x = np.array([_poly(v[:, q], s) for q in range(chain.s)])
                _funcs, shaft, target = md.guards[gi]
                events.append((start + done + s * rem, shaft, modes[shaft], target))
                modes = list(modes)
                modes[shaft] = target
                done += s * rem
            else:
                raise InputError(f"contact chatter at t = {start + done} s")
        states[i + 1], modes_out[i + 1] = x, modes
    return (
        states,
        modes_out,
        np.array(events, dtype=float).reshape(-1, 4),
        np.array(grazes, dtype=float).reshape(-1, 3),
    )
