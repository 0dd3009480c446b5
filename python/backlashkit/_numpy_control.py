"""Plain NumPy references of the compiled control kernels (``crates/core/src/play.rs``
and ``crates/core/src/control.rs``).

They implement the same algorithms step for step and are used by the parity tests and
as a fallback (``backend="numpy"``). They are slow (Python loops).

Closed-loop integration (both backends)
---------------------------------------
Classical fixed-step RK4 on the continuous states (plant, controller filters,
reference model, the four ``H(s)`` filters of the adaptive law, ``theta_b`` and the
smoothing filter), with the two discontinuities treated explicitly:

* the side of the inverse (``chi_r``) is a discrete mode switched where the
  switching function ``du_d/dt`` (a continuous function of the state and of ``t``)
  crosses zero; a crossing inside a step is located by Illinois regula falsi on
  RK4 sub-steps (to ``1e-12`` of the step), the step is split there, and ``v`` jumps
  at the located instant, not on the grid;
* the backlash output is the play operator evaluated against its value at the start
  of the step (exact while ``v`` is monotone over the step) and updated at every
  accepted step end and at both sides of every located jump.

The kinks where the backlash switches between an inner segment and a side are not
located (they make the right-hand side continuous but not smooth), so the global
error is first order in the step there; the tests show the traces do not change
(to the accuracy of the bars) when the step is halved.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["play_operator", "simulate_adaptive", "zoh_recurrence"]


def play_operator(v: np.ndarray, m: float, c_r: float, c_l: float, u0: float) -> np.ndarray:
    """Play operator ``u_k = min(max(u_{k-1}, m (v_k - c_r)), m (v_k - c_l))``.

    Parameters
    ----------
    v : numpy.ndarray
        Input samples.
    m, c_r, c_l : float
        Backlash parameters of paper B (2.1).
    u0 : float
        Output before the first sample.

    Returns
    -------
    numpy.ndarray
        Output samples.
    """
    out = np.empty(len(v))
    u = u0
    for k, vk in enumerate(v):
        u = min(max(u, m * (vk - c_r)), m * (vk - c_l))
        out[k] = u
    return out


def zoh_recurrence(ad: np.ndarray, bd: np.ndarray, u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """State samples of ``x_{k+1} = A_d x_k + b_d u_k``.

    Parameters
    ----------
    ad : numpy.ndarray, shape (n, n)
    bd : numpy.ndarray, shape (n,)
    u : numpy.ndarray, shape (N,)
    x0 : numpy.ndarray, shape (n,)

    Returns
    -------
    numpy.ndarray, shape (N, n)
        ``x_0 .. x_{N-1}``.
    """
    n = ad.shape[0]
    x = np.empty((len(u), n))
    xk = np.array(x0, dtype=float)
    for k in range(len(u)):
        x[k] = xk
        xk = ad @ xk + bd * u[k]
    return x


class _Loop:
    """Closed loop of paper B: plant + backlash + controller (3.2) + inverse + (3.11)."""

    def __init__(self, p: dict[str, Any]) -> None:
        self.p = p
        self.np_ = p["ap"].shape[0]
        self.n = p["al"].shape[0]
        self.q = p["am"].shape[0]
        self.nh = p["ah"].shape[0]
        o = 0
        self.sp = slice(o, o + self.np_)
        o += self.np_
        self.s1 = slice(o, o + self.n)
        o += self.n
        self.s2 = slice(o, o + self.n)
        o += self.n
        self.sm = slice(o, o + self.q)
        o += self.q
        self.sz = [slice(o + j * self.nh, o + (j + 1) * self.nh) for j in range(4)]
        o += 4 * self.nh
        self.st = slice(o, o + 3)
        o += 3
        self.iw = o
        self.size = o + 1

    def reference(self, t: float) -> tuple[float, float]:
        p = self.p
        if p["table_t"].size:
            tt, rr = p["table_t"], p["table_r"]
            if t <= tt[0]:
                return float(rr[0]), 0.0
            if t >= tt[-1]:
                return float(rr[-1]), 0.0
            i = int(np.searchsorted(tt, t, side="right")) - 1
            s = (rr[i + 1] - rr[i]) / (tt[i + 1] - tt[i])
            return float(rr[i] + s * (t - tt[i])), float(s)
        r = rd = 0.0
        for a, w, ph in zip(p["amps"], p["freqs"], p["phases"], strict=True):
            r += a * math.sin(w * t + ph)
            rd += a * w * math.cos(w * t + ph)
        return r, rd

    def ud_and_rate(
        self, t: float, x: np.ndarray, noise: float
    ) -> tuple[float, float, float, float]:
        p = self.p
        r, rd = self.reference(t)
        y = float(p["cp"] @ x[self.sp]) + noise
        x1, x2 = x[self.s1], x[self.s2]
        ud = float(p["th1"] @ x1 + p["th2"] @ x2 + p["th3"] * r)
        udd = float(
            p["th1"] @ (p["al"] @ x1 + p["bl"] * ud)
            + p["th2"] @ (p["al"] @ x2 + p["bl"] * y)
            + p["th3"] * rd
        )
        return r, y, ud, udd

    def inverse(self, x: np.ndarray, ud: float, udd: float, mode: int, lock: int) -> float:
        p = self.p
        kind = p["kind"]
        th = x[self.st]
        if kind == 0:
            return ud
        if kind == 4:
            return ud / th[1]
        cr, cl = th[0] / th[1], th[2] / th[1]
        if kind == 1:
            return ud / th[1] + (cr if mode else cl)
        if kind == 2:
            return ud / th[1] + x[self.iw]
        # kind 3: ramps (2.5)
        br, bl = p["p1"], p["p2"]
        if lock:
            w = cr if udd >= 0 else cr + (cr - cl) * max(udd / bl, -1.0)
        else:
            w = cl if udd <= 0 else cl + (cr - cl) * min(udd / br, 1.0)
        return ud / th[1] + w

    def play(self, u_prev: float, v: float) -> float:
        p = self.p
        return min(max(u_prev, p["m"] * (v - p["c_r"])), p["m"] * (v - p["c_l"]))

    def deriv(self, t, x, mode, lock, u_prev, noise, dist):
        p = self.p
        r, y, ud, udd = self.ud_and_rate(t, x, noise)
        v = self.inverse(x, ud, udd, mode, lock)
        u = self.play(u_prev, v) + dist
        th = x[self.st]
        dx = np.empty(self.size)
        dx[self.sp] = p["ap"] @ x[self.sp] + p["bp"] * u
        dx[self.s1] = p["al"] @ x[self.s1] + p["bl"] * ud
        dx[self.s2] = p["al"] @ x[self.s2] + p["bl"] * y
        dx[self.sm] = p["am"] @ x[self.sm] + p["bm"] * r
        chi = 1.0 if mode else 0.0
        wb = (chi, -v, 1.0 - chi)
        tw = th[0] * wb[0] + th[1] * wb[1] + th[2] * wb[2]
        ah, bh, ch = p["ah"], p["bh"], p["ch"]
        zeta = np.empty(3)
        for j in range(3):
            z = x[self.sz[j]]
            dx[self.sz[j]] = ah @ z + bh * wb[j]
            zeta[j] = ch @ z
        zp = x[self.sz[3]]
        dx[self.sz[3]] = ah @ zp + bh * tw
        if p["kind"] == 0:
            dx[self.st] = 0.0
        else:
            e = y - float(p["cm"] @ x[self.sm])
            xi = float(th @ zeta) - float(ch @ zp)
            eps = e + xi
            nz = 1.0 + float(zeta @ zeta) + xi * xi
            g = p["gamma"]
            dth = -g * zeta * eps / nz
            sig = p["sigma"]
            if sig > 0:
                nrm = float(np.sqrt(th @ th))
                m0b = p["sigma_bound"]
                ss = 0.0 if nrm <= m0b else (sig * (nrm / m0b - 1.0) if nrm <= 2 * m0b else sig)
                dth = dth - ss * g * th
            if th[1] <= p["m0"] and dth[1] < 0:
                dth[1] = 0.0
            if th[0] <= 0 and dth[0] < 0:
                dth[0] = 0.0
            if th[2] >= 0 and dth[2] > 0:
                dth[2] = 0.0
            dx[self.st] = dth
        if p["kind"] == 2:
            target = th[0] / th[1] if mode else th[2] / th[1]
            dx[self.iw] = p["p1"] * (target - x[self.iw])
        else:
            dx[self.iw] = 0.0
        return dx

    def rk4(self, t, x, h, mode, lock, u_prev, noise, dist):
        f = self.deriv
        k1 = f(t, x, mode, lock, u_prev, noise, dist)
        k2 = f(t + h / 2, x + h / 2 * k1, mode, lock, u_prev, noise, dist)
        k3 = f(t + h / 2, x + h / 2 * k2, mode, lock, u_prev, noise, dist)
        k4 = f(t + h, x + h * k3, mode, lock, u_prev, noise, dist)
        xn = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self.project(xn)
        return xn

    def project(self, x):
        if self.p["kind"] == 0:
            return
        th = x[self.st]
        th[1] = max(th[1], self.p["m0"])
        th[0] = max(th[0], 0.0)
        th[2] = min(th[2], 0.0)


def _wrong_side(mode: int, g: float) -> bool:
    return (mode == 1 and g < 0) or (mode == 0 and g > 0)


def simulate_adaptive(p: dict[str, Any]) -> dict[str, np.ndarray]:
    """Closed-loop simulation of paper B's adaptive backlash-inverse controller.

    Parameters
    ----------
    p : dict
        The packed problem built by :func:`backlashkit.control.problem.build_problem`
        (matrices of the plant, filters, ``H(s)``, gains, reference, step ``h``,
        ``n_steps``, output decimation ``n_sub``, optional per-step ``noise``/``dist``).

    Returns
    -------
    dict
        Arrays ``t, r, y, ym, ud, v, u`` and ``thb`` (shape (N, 3)) at the output
        samples, and ``n_switches``.
    """
    lp = _Loop(p)
    h, n_steps, n_sub = float(p["h"]), int(p["n_steps"]), int(p["n_sub"])
    noise_arr, dist_arr = p["noise"], p["dist"]
    x = np.zeros(lp.size)
    x[lp.sp] = p["xp0"]
    x[lp.st] = p["thb0"]
    t = 0.0
    n_out = n_steps // n_sub + 1
    out = {k: np.empty(n_out) for k in ("t", "r", "y", "ym", "ud", "v", "u")}
    out["thb"] = np.empty((n_out, 3))
    out["xp"] = np.empty((n_out, lp.np_))
    _, _, ud, udd = lp.ud_and_rate(0.0, x, float(noise_arr[0]) if noise_arr.size else 0.0)
    mode = 1 if udd >= 0 else 0
    lock = mode
    th = x[lp.st]
    if p["kind"] == 2:
        x[lp.iw] = th[0] / th[1] if mode else th[2] / th[1]
    u_prev = float(p["u0"])
    n_sw = 0
    j = 0
    for k in range(n_steps + 1):
        noise = float(noise_arr[k]) if k < noise_arr.size else 0.0
        dist = float(dist_arr[k]) if k < dist_arr.size else 0.0
        r, y, ud, udd = lp.ud_and_rate(t, x, noise)
        if _wrong_side(mode, udd):
            u_prev = lp.play(u_prev, lp.inverse(x, ud, udd, mode, lock))
            mode = 1 - mode
            n_sw += 1
        v = lp.inverse(x, ud, udd, mode, lock)
        u_prev = lp.play(u_prev, v)
        if p["kind"] == 3:
            if udd >= p["p1"]:
                lock = 1
            elif udd <= -p["p2"]:
                lock = 0
        if k % n_sub == 0:
            out["t"][j] = t
            out["r"][j] = r
            out["y"][j] = float(p["cp"] @ x[lp.sp])
            out["ym"][j] = float(p["cm"] @ x[lp.sm])
            out["ud"][j] = ud
            out["v"][j] = v
            out["u"][j] = u_prev + dist
            out["thb"][j] = x[lp.st]
            out["xp"][j] = x[lp.sp]
            j += 1
        if k == n_steps:
            break
        t_end = (k + 1) * h
        remaining = h
        for _ in range(8):
            xn = lp.rk4(t, x, remaining, mode, lock, u_prev, noise, dist)
            _, _, udn, uddn = lp.ud_and_rate(t + remaining, xn, noise)
            if not _wrong_side(mode, uddn):
                x, t = xn, t_end
                break
            # locate the zero of du_d/dt inside (0, remaining): Illinois regula falsi
            _, _, _, g0 = lp.ud_and_rate(t, x, noise)
            a, fa, b, fb = 0.0, g0, remaining, uddn
            s, xs, side = b, xn, 0
            for _ in range(60):
                s = (a * fb - b * fa) / (fb - fa) if fb != fa else 0.5 * (a + b)
                if not (a < s < b):
                    s = 0.5 * (a + b)
                xs = lp.rk4(t, x, s, mode, lock, u_prev, noise, dist)
                _, _, _, fs = lp.ud_and_rate(t + s, xs, noise)
                if _wrong_side(mode, fs):
                    b, fb = s, fs
                    if side == -1:
                        fa *= 0.5
                    side = -1
                else:
                    a, fa = s, fs
                    if side == 1:
                        fb *= 0.5
                    side = 1
                if b - a <= 1e-12 * h:
                    break
            s = b
            xs = lp.rk4(t, x, s, mode, lock, u_prev, noise, dist)
            t = t + s
            x = xs
            _, _, uds, udds = lp.ud_and_rate(t, x, noise)
            u_prev = lp.play(u_prev, lp.inverse(x, uds, udds, mode, lock))
            mode = 1 - mode
            n_sw += 1
            u_prev = lp.play(u_prev, lp.inverse(x, uds, udds, mode, lock))
            remaining = t_end - t
            if remaining <= 1e-12 * h:
                t = t_end
                break
        else:  # pragma: no cover - more than 8 switches in one step
            t = t_end
        # play update at the accepted step end (before a possible switch, handled next)
        _, _, ude, udde = lp.ud_and_rate(t, x, noise)
        u_prev = lp.play(u_prev, lp.inverse(x, ude, udde, mode, lock))
    out["n_switches"] = np.array(n_sw)
    return out
