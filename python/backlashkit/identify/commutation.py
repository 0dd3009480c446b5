"""The commutation instants after a torque step-down and paper A's pre-estimate of the
backlash (Ravanbod-Shirazi & Besançon-Voda, IFAC 2002, eqs. 6 and 9).

After the step-down at ``t_s`` the shaft leaves its positive flank at ``t_c`` and meets
the negative flank at ``t_b``; :func:`commutation_instants` locates both by the
piecewise free-decay fits of eq. 9, and :func:`pre_estimate` integrates the filtered
speeds between them (eq. 6). The choices the paper leaves open are listed in
:mod:`backlashkit.identify.two_step`.

Every ``theta`` is the backlash **half-width** in rad. Units are SI: s, rad/s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import validate as v
from ..errors import InputError, Option
from .record import Record
from .step import find_step_down

__all__ = [
    "ONSETS",
    "Commutation",
    "commutation_instants",
    "fir_lowpass",
    "firwin_hamming",
    "pre_estimate",
]

ArrayLike = Sequence[float] | np.ndarray


def firwin_hamming(numtaps: int, cutoff: float) -> np.ndarray:
    """Hamming-windowed sinc low-pass taps, unit DC gain: ``scipy.signal.firwin(numtaps,
    cutoff)`` (``cutoff`` relative to Nyquist), checked against it by the tests.

    Written out because importing ``scipy.signal`` alone takes about 0.9 s, half of
    the time budget of one identification from the command line.

    Parameters
    ----------
    numtaps : int
        Filter length.
    cutoff : float
        Cut-off relative to the Nyquist frequency, in (0, 1).

    Returns
    -------
    numpy.ndarray
        The taps.
    """
    m = np.arange(numtaps) - 0.5 * (numtaps - 1)
    taps = cutoff * np.sinc(cutoff * m) * np.hamming(numtaps)
    return taps / np.sum(taps)


def fir_lowpass(
    x: ArrayLike, cutoff: float, ts: float, *, numtaps: int | None = None,
    span: tuple[int, int] | None = None,
) -> np.ndarray:
    """Zero-phase FIR low-pass filter (linear-phase taps applied centred).

    Parameters
    ----------
    x : array_like
        Signal, 1-D.
    cutoff : float
        Cut-off in **rad/s**, > 0 and below the Nyquist frequency ``pi / ts``.
    ts : float
        Sample time in s.
    numtaps : int, optional
        Odd filter length; default the odd integer nearest ``3.3 f_s / f_c``
        (Hamming window, transition band about as wide as the cut-off), at least 3.
    span : tuple of int, optional
        ``(start, stop)``, ``0 <= start < stop <= len(x)``: only ``y[start:stop]`` of
        the filtered signal ``y``, from the samples it needs (the same values, each
        output the same sum; eq. 6 integrates a fraction of a second of a record).

    Returns
    -------
    numpy.ndarray
        Filtered signal, same length (or ``span``'s); the ends are padded with the end
        values.
    """
    arr = v.finite_array("x", x)
    wc = v.positive("cutoff", cutoff)
    ts = v.positive("ts", ts)
    nyq = math.pi / ts
    if not wc < nyq:
        raise InputError(
            f"cutoff must be below the Nyquist frequency pi/ts = {nyq:.6g} rad/s, got {cutoff!r}"
        )
    if numtaps is None:
        fc_hz = wc / (2 * math.pi)
        numtaps = 2 * int(round(3.3 / (fc_hz * ts) / 2)) + 1
    elif isinstance(numtaps, bool) or not isinstance(numtaps, (int, np.integer)):
        raise InputError(f"numtaps must be an odd integer >= 3, got {numtaps!r}")
    numtaps = max(3, int(numtaps))
    if numtaps % 2 == 0:
        raise InputError(f"numtaps must be odd (a centred linear-phase filter), got {numtaps}")
    taps = firwin_hamming(numtaps, wc / nyq)
    half = numtaps // 2
    start, stop = (0, arr.size) if span is None else _span(span, arr.size)
    # the outputs start..stop-1 read the inputs half a filter either side; where that
    # passes an end of x, the edge padding of the whole signal is the segment's own
    lo, hi = max(0, start - half), min(arr.size, stop + half)
    padded = np.pad(arr[lo:hi], half, mode="edge")
    return np.convolve(padded, taps, mode="valid")[start - lo : stop - lo]


def _span(span: tuple[int, int], n: int) -> tuple[int, int]:
    """``span`` checked against a signal of ``n`` samples."""
    try:
        start, stop = span
    except (TypeError, ValueError):
        raise InputError(f"span must be two sample indices (start, stop), got {span!r}") from None
    start, stop = v.integer("span's start", start, 0), v.integer("span's stop", stop, 1)
    if not start < stop <= n:
        raise InputError(f"span must satisfy 0 <= start < stop <= len(x) = {n}, got {span!r}")
    return start, stop


@dataclass(frozen=True)

class Commutation:
    """Commutation instants found by eq. 9 and the windows used.

    Parameters
    ----------
    i_s, i_c, i_b : int
        Sample indices of ``t_s``, ``t_c`` and ``t_b``.
    t_s, t_c, t_b : float
        Step-down, contact-loss and impact instants in s.
    dt1, dt2, dt3 : float
        Windows of eq. 9 in s (after ``t_s``).
    """

    i_s: int
    i_c: int
    i_b: int
    t_s: float
    t_c: float
    t_b: float
    dt1: float
    dt2: float
    dt3: float


def _moving_average(x: np.ndarray, width: int) -> np.ndarray:
    if width <= 1:
        return x.copy()
    half = width // 2
    padded = np.pad(x, half, mode="edge")
    c = np.concatenate([[0.0], np.cumsum(padded)])
    return (c[2 * half + 1 :] - c[: -2 * half - 1]) / (2 * half + 1)


def _impact_time(record: Record, i_s: int, search: float) -> float:
    """Rough impact instant (s after t_s) from the fastest rise of the motor speed."""
    ts = record.ts
    n = min(int(round(search / ts)), record.t.size - 1 - i_s)
    h = max(1, int(round(0.020 / ts)))  # rise measured over 20 ms
    if n < 4 * h:
        raise InputError(
            f"{record.name}: too few samples after the step-down at t = {record.t[i_s]:.6g} s "
            f"({n}) to locate the commutations; record at least {search:g} s after it"
        )
    width = max(1, int(round(0.021 / ts)))
    w = _moving_average(record.w_motor[i_s : i_s + n + h + 1], width)
    rise = (w[h:] - w[:-h])[:n]
    top = float(np.max(rise))
    # noise level of the same statistic while the torque is held before t_s
    before = _moving_average(record.w_motor[max(0, i_s - n - h) : i_s], width)
    floor = 1e-9 * float(np.max(np.abs(record.w_motor[i_s : i_s + n])))
    if before.size > 2 * h + 2:
        pre = before[h:] - before[:-h]
        floor = max(floor, 3.0 * 1.4826 * float(np.median(np.abs(pre - np.median(pre)))))
    if not top > floor:
        raise InputError(
            f"{record.name}: no rise of the motor speed above its noise ({floor:.3g} rad/s) "
            f"within {search:g} s after the step-down at t = {record.t[i_s]:.6g} s: no impact "
            "on the negative flank found (are w_motor and w_load swapped? the motor's speed "
            "rises again when its side meets the other flank; else the step may be too "
            "small to cross the backlash)"
        )
    above = rise >= 0.5 * top
    k = int(np.argmax(above))
    while k + 1 < rise.size and rise[k + 1] >= rise[k]:  # climb to the local maximum
        k += 1
    j = k + h  # end of the fastest rise; walk back to the minimum that starts it
    while j > 0 and w[j - 1] <= w[j]:
        j -= 1
    return j * ts


#: Shapes of the load speed before the contact loss in ``F_1`` of eq. 9.
ONSETS = ("constant", "unloading")


def _w_c(y: np.ndarray, tt: np.ndarray, alpha: float, anchor: str,
         onset: str = "constant") -> np.ndarray:
    """W_c(t_c) for every candidate index 1 .. len - 2 (onset, then free decay).

    ``tt[0]`` is the step-down instant. With ``onset="unloading"`` the load speed
    before the candidate falls as ``w_0 - c (t - t_s)^3``: the shaft torque drops
    quadratically after a torque step (the motor decelerates at a constant rate), so
    the load's deceleration rises from 0 at ``t_s`` to the free decay's ``alpha w``
    at ``t_c``; ``c`` follows from that slope, so the onset adds no parameter.
    """
    m = y.size
    out = np.full(m, np.inf)
    idx = np.arange(m)
    tau = tt - tt[0]
    for c in range(1, m - 1):
        if onset == "unloading":
            d = tau[c]
            before = 1.0 + alpha * (d**3 - tau**3) / (3.0 * d**2)
        else:
            before = 1.0
        g = np.where(idx < c, before, np.exp(-alpha * (tt - tt[c])))
        a = y[c] if anchor == "sample" else float(y @ g) / float(g @ g)
        r = y - a * g
        out[c] = float(r @ r)
    return out


def _w_b(y: np.ndarray, tt: np.ndarray, alpha: float, anchor: str) -> np.ndarray:
    """W_b(t_b) for every candidate index 0 .. len - 2 (free decay, then constant)."""
    m = y.size
    out = np.full(m, np.inf)
    idx = np.arange(m)
    for c in range(0, m - 1):
        g = np.where(idx <= c, np.exp(-alpha * (tt - tt[c])), 1.0)
        a = y[c] if anchor == "sample" else float(y @ g) / float(g @ g)
        r = y - a * g
        out[c] = float(r @ r)
    return out


def commutation_instants(
    record: Record,
    alpha: float,
    *,
    dt1: float | None = None,
    dt2: float | None = None,
    dt3: float | None = None,
    anchor: str = "sample",
    onset: str = "constant",
    search: float = 0.5,
) -> Commutation:
    """Estimate ``t_c`` and ``t_b`` after the step-down by eq. 9 of paper A.

    Parameters
    ----------
    record : Record
        A step-down experiment.
    alpha : float
        Load decay rate ``f_L / J_L`` in 1/s (of the prior), >= 0.
    dt1, dt2, dt3 : float, optional
        Windows of eq. 9 in s after ``t_s``, ``0 < dt1``, ``0 < dt2 < dt3``; default
        from the data (module docstring).
    anchor : {"sample", "fit"}, optional
        Amplitude of the decay in ``F_1``, ``F_2``: the measured sample at the
        candidate instant (paper) or its least-squares value.
    onset : {"constant", "unloading"}, optional
        Load speed before ``t_c`` in ``F_1``: constant (paper; ``t_c`` comes out
        about 2.4 samples early on paper A's noise-free data, since the unloading
        shaft already slows the load) or falling as ``(t - t_s)^3`` into the free
        decay (the unloading after a torque step; within 0.4 samples there, within
        2 samples for shafts 0.3 to 3 times as stiff and motors 0.2 to 5 times as
        heavy). Same number of fitted values either way.
    search : float, optional
        Span in s after ``t_s`` searched for the impact when the windows are derived
        from the data (default 0.5 s).

    Returns
    -------
    Commutation
        The instants and the windows used.

    Raises
    ------
    InputError
        If the record has no step-down, no impact is found, or the windows do not fit
        in the record.
    """
    alpha = v.nonnegative("alpha", alpha)
    if anchor not in ("sample", "fit"):
        raise InputError(f"anchor must be 'sample' or 'fit', got {anchor!r}")
    if onset not in ONSETS:
        raise InputError(f"onset must be 'constant' or 'unloading', got {onset!r}")
    i_s, t_s, _, _ = find_step_down(record)
    ts = record.ts
    if dt1 is None or dt2 is None or dt3 is None:
        tau = _impact_time(record, i_s, v.positive("search", search))
        if tau < 4 * ts:
            raise InputError(
                f"{record.name}: the motor speed rises {tau:.3g} s after the step-down at "
                f"t = {t_s:.6g} s: too early for a passage through the backlash; no contact "
                "change found"
            )
        dt1 = 0.5 * tau if dt1 is None else dt1
        dt2 = 0.5 * tau if dt2 is None else dt2
        dt3 = 1.15 * tau if dt3 is None else dt3
    dt1, dt2, dt3 = (v.positive(n, x) for n, x in (("dt1", dt1), ("dt2", dt2), ("dt3", dt3)))
    if not dt2 < dt3:
        raise InputError(f"dt2 must be < dt3, got dt2 = {dt2!r}, dt3 = {dt3!r}")
    n1, n2, n3 = (int(round(x / ts)) for x in (dt1, dt2, dt3))
    if n1 < 2 or n3 - n2 < 2:
        raise InputError(
            f"{record.name}: the windows searched for the contact loss and the impact "
            f"after the step-down must each span at least 2 samples, got {dt1:.3g} s and "
            f"{dt3 - dt2:.3g} s at a sample time of {ts:.3g} s (lengthen ",
            Option("dt1", None), " and the span from ", Option("dt2", None), " to ",
            Option("dt3", None), ", or record at a higher sample rate)"
        )
    if i_s + n3 >= record.t.size:
        raise InputError(
            f"{record.name}: the record ends at t = {record.t[-1]:.6g} s, before the end "
            f"of the window searched for the impact, t = {t_s + dt3:.6g} s ({dt3:.3g} s "
            f"after the step-down at t = {t_s:.6g} s): record longer after the step-down"
        )
    t, y = record.t, record.w_load
    # eq. 9's argmins do not depend on the speed's scale, but 1e300 rad/s would overflow
    # its squares: scaled by a power of 2, exact, so every other record's sums are unchanged
    y = np.ldexp(y, -math.frexp(float(np.max(np.abs(y))))[1])
    wc = _w_c(y[i_s : i_s + n1 + 1], t[i_s : i_s + n1 + 1], alpha, anchor, onset)
    i_c = i_s + int(np.argmin(wc))
    lo = i_s + n2
    wb = _w_b(y[lo : i_s + n3 + 1], t[lo : i_s + n3 + 1], alpha, anchor)
    i_b = lo + int(np.argmin(wb))
    if not i_b > i_c:
        raise InputError(
            f"{record.name}: the impact on the other flank, located at t = {t[i_b]:.6g} s, "
            f"comes before the contact loss, located at t = {t[i_c]:.6g} s: the load speed "
            "shows no passage through the backlash after the step-down (record a step-down "
            "to 0 with less noise on the load speed, or give the windows searched as ",
            Option("dt1", None), ", ", Option("dt2", None), ", ", Option("dt3", None), ")"
        )
    return Commutation(i_s, i_c, i_b, t_s, float(t[i_c]), float(t[i_b]), dt1, dt2, dt3)


def pre_estimate(w_motor_f: ArrayLike, w_load_f: ArrayLike, ts: float, i_c: int, i_b: int) -> float:
    """Eq. 6: ``theta_ini = -0.5 * integral_{t_c}^{t_b} (w_Mf - w_Lf) dt``.

    Parameters
    ----------
    w_motor_f, w_load_f : array_like
        Filtered motor and load speeds in rad/s.
    ts : float
        Sample time in s.
    i_c, i_b : int
        Sample indices of ``t_c`` and ``t_b``, ``i_c < i_b``.

    Returns
    -------
    float
        The pre-estimate of the backlash half-width in rad (trapezoidal rule).
    """
    d = np.asarray(w_motor_f, float)[i_c : i_b + 1] - np.asarray(w_load_f, float)[i_c : i_b + 1]
    return float(-0.5 * ts * (d.sum() - 0.5 * (d[0] + d[-1])))
