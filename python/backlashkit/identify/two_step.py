"""Backlash identification from a torque step-down (paper A, Ravanbod-Shirazi &
Besançon-Voda, "Backlash identification: a two step approach", IFAC 2002).

Two estimators, in the scikit-learn style (``fit`` returns ``self``; what is learned
ends in ``_``):

* :class:`TwoStepIdentifier` -- paper A's algorithm, Section 4.3 steps 4-8: the
  commutation instants ``t_c`` (shaft leaves the positive flank) and ``t_b`` (it
  meets the negative flank) after the step-down at ``t_s`` are located by the
  piecewise free-decay fits of eq. 9; both speeds are low-pass filtered by FIR
  filters; the backlash is pre-estimated by eq. 6,
  ``theta_ini = -0.5 * integral_{t_c}^{t_b} (w_Mf - w_Lf) dt``; and the final value
  minimises the least-squares criterion ``W_1`` on the motor speed over
  ``[t_s, t_s + dt_4]`` with ``theta`` restricted to ``theta_ini (1 +- n_theta)``.
* :class:`RegressionIdentifier` -- the baseline of paper A's Table 2: the same
  criterion with ``theta`` searched over ``[0, theta_max]`` (15 deg) without the
  pre-estimate.

Every ``theta`` is the backlash **half-width** in rad (dead zone ``[-theta, theta]``,
total gap ``2 theta``). Units are SI: s, N m, rad, rad/s.

Choices the paper leaves open (documented here, configurable where it matters)
-----------------------------------------------------------------------------------
* **Step-down instant.** ``t_s`` is the first sample of the lower torque level: the
  torque record must hold a positive level and then drop (the largest negative jump
  of the torque column), as in paper A's ``C_M = a 1(t) - a 1(t - t_s)``.
* **Windows dt_1 .. dt_3 of eq. 9** (``t_s < t_c < t_s + dt_1 < t_b``,
  ``t_s + dt_2 < t_b < t_s + dt_3 < t_a``) are taken from the data unless given: the
  impact on the negative flank makes the motor speed jump up, so ``t_b`` is located
  roughly at ``t_s + tau``, the minimum of the motor speed (moving average over
  21 ms) that starts its fastest rise over 20 ms (the first rise reaching half the
  largest one within ``search`` seconds after ``t_s``);
  then ``dt_1 = dt_2 = tau / 2`` and ``dt_3 = 1.15 tau`` (the next contact loss comes
  about a quarter of a shaft period after the impact: 1.27 ``t_b`` after ``t_s`` for
  paper A's drive at ``a_1``, 1.74 ``t_b`` at ``a_2``).
* **Eq. 9.** ``W_c`` and ``W_b`` are evaluated on the raw (noisy) load speed, as the
  paper says, with ``alpha = f_L / J_L`` of the prior. The amplitude of the decay
  (``w_L(t_c)`` in ``F_1``, ``w_L(t_b)`` in ``F_2``) is the measured sample at the
  candidate instant (``anchor="sample"``, the paper's text) or its least-squares value
  over the window (``anchor="fit"``, closed form since ``F`` is linear in it).
* **Filters.** Linear-phase FIR low-pass filters (the taps of :func:`scipy.signal.firwin`,
  Hamming window) applied centred, i.e. with their delay of ``(N - 1) / 2`` samples
  removed (zero phase, single pass, so the magnitude response is the designed one).
  A causal filter would shift the speeds against ``t_c`` and ``t_b`` found on the raw
  signal and bias eq. 6; the paper filters recorded data offline. The record is
  padded with its end values. ``N`` is the odd number nearest ``3.3 f_s / f_c``
  (transition band about as wide as the cut-off) unless ``numtaps`` is given.
  Cut-offs are in **rad/s** (paper: 50 rad/s for ``w_M``, 20 rad/s for ``w_L``).
* **Integral of eq. 6.** Trapezoidal rule on the filtered speeds, with the ends at
  ``t_c`` and ``t_b`` (grid instants, as eq. 9 returns them).
* **Model start in W_1.** The model (prior linear parameters, candidate ``theta``) is
  simulated from ``t_s`` on, started at the steady state under the torque held before
  ``t_s``, with the speed level **measured** (mean motor speed over ``level_window``
  seconds before ``t_s``; the paper's step 1 measures the gain ``g_s``): state
  ``[w_0, w_0, theta + f_L w_0 / k_sh]`` with the prior's ``f_L`` and ``k_sh``. The
  prior's own steady state ``a / (f_M + f_L)`` would carry the parameter error into
  every sample of ``W_1``.
* **dt_4** = 1 s (paper A Section 5: "delta t = 1 s").
* **Search.** A grid over the interval (``n_grid`` points, simulated in parallel with
  :func:`backlashkit.simulate_batch`), then grids of 21 points, each ten times finer,
  around the best point until the spacing is below ``1e-6`` of the interval's end (no
  serial scalar minimiser: importing ``scipy.optimize`` alone would take longer than
  the whole search). The regression baseline keeps this search: its wrong local minima come from
  the criterion with an erroneous prior, not from the search.
* **Several records.** The pre-estimate is the mean of the per-record values of
  eq. 6; ``W_1`` is the sum of the per-record criteria. Paper A runs step 1 (small
  step ``a_1``, noisy) for the pre-estimate and step 2 (``a_2 = 0.6 a_max``) for
  ``W_1``: pass the step-2 records as ``final_records``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import validate as v
from ..errors import InputError
from ..plants import TwoMassDrive
from .record import Record, as_records, check_prior
from .step import find_step_down, warn_held_speeds

__all__ = [
    "Commutation",
    "RegressionIdentifier",
    "TwoStepIdentifier",
    "commutation_instants",
    "fir_lowpass",
    "pre_estimate",
]

ArrayLike = Sequence[float] | np.ndarray

#: Paper A's identification time dt_4 in s.
DEFAULT_DT4 = 1.0

def _firwin_hamming(numtaps: int, cutoff: float) -> np.ndarray:
    """Hamming-windowed sinc low-pass taps, unit DC gain: ``scipy.signal.firwin(numtaps,
    cutoff)`` (``cutoff`` relative to Nyquist), checked against it by the tests.

    Written out because importing ``scipy.signal`` alone takes about 0.9 s, half of
    the time budget of one identification from the command line.
    """
    m = np.arange(numtaps) - 0.5 * (numtaps - 1)
    taps = cutoff * np.sinc(cutoff * m) * np.hamming(numtaps)
    return taps / np.sum(taps)

def fir_lowpass(
    x: ArrayLike, cutoff: float, ts: float, *, numtaps: int | None = None
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

    Returns
    -------
    numpy.ndarray
        Filtered signal, same length; the ends are padded with the end values.
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
    taps = _firwin_hamming(numtaps, wc / nyq)
    half = numtaps // 2
    padded = np.pad(arr, half, mode="edge")
    return np.convolve(padded, taps, mode="valid")

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
            "on the negative flank found"
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
            f"{record.name}: the windows of eq. 9 span too few samples (dt1 = {dt1:.3g} s, "
            f"dt3 - dt2 = {dt3 - dt2:.3g} s at Ts = {ts:.3g} s)"
        )
    if i_s + n3 >= record.t.size:
        raise InputError(
            f"{record.name}: the record ends before t_s + dt3 = {t_s + dt3:.6g} s"
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
            f"{record.name}: eq. 9 put the impact (t_b = {t[i_b]:.6g} s) before the contact "
            f"loss (t_c = {t[i_c]:.6g} s); no contact change found"
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

@dataclass
class _Segment:
    """The part of a record used by W_1: from t_s over dt_4, and the model start."""

    t: np.ndarray
    torque: np.ndarray
    w_motor: np.ndarray
    w0: float
    name: str = "record"

def _segment(record: Record, dt4: float, level_window: float) -> _Segment:
    i_s, t_s, _, _ = find_step_down(record)
    ts = record.ts
    n4 = int(round(dt4 / ts))
    if i_s + n4 >= record.t.size:
        raise InputError(
            f"{record.name}: the record ends before t_s + dt4 = {t_s + dt4:.6g} s "
            f"(t_s = {t_s:.6g} s); record longer or lower dt4"
        )
    nl = max(1, min(i_s, int(round(level_window / ts))))
    w0 = float(np.mean(record.w_motor[i_s - nl : i_s]))
    sl = slice(i_s, i_s + n4 + 1)
    return _Segment(record.t[sl], record.torque[sl], record.w_motor[sl], w0, record.name)

def _cost(prior: TwoMassDrive, segments: list[_Segment], thetas: np.ndarray, workers) -> np.ndarray:
    """Sum over segments of W_1(theta) for every theta (simulated in parallel)."""
    from ..simulate import simulate_batch

    total = np.zeros(thetas.size)
    for seg in segments:
        drives = [prior.with_theta(float(th)) for th in thetas]
        x0 = np.array([[seg.w0, seg.w0, th + prior.f_L * seg.w0 / prior.k_sh] for th in thetas])
        try:
            responses = simulate_batch(drives, seg.t, seg.torque, initial_state=x0,
                                       workers=workers)
        except InputError:
            raise
        except ValueError as exc:  # what the compiled core refuses, with the record named
            text = " ".join(str(exc).split())
            raise InputError(f"{seg.name}: cannot simulate the prior on this record: "
                             f"{text}") from exc
        for j, r in enumerate(responses):
            e = seg.w_motor - r.w_motor
            total[j] += float(e @ e)
    return total

def _search(prior, segments, lo: float, hi: float, n_grid: int, workers) -> tuple[float, float]:
    """Grid search of ``W_1`` over ``[lo, hi]``, then zoomed grids around the best point.

    Each zoom simulates :data:`ZOOM_POINTS` candidates in one batch over the two grid
    cells around the current best (a factor 10 narrower each time) until the cell is
    below ``1e-6 max(hi, 1e-3)`` rad: no serial scalar minimiser, whose import
    (``scipy.optimize``, about 0.6 s) would cost more than the whole search.
    """
    grid = np.linspace(lo, hi, n_grid)
    costs = _cost(prior, segments, grid, workers)
    j = int(np.argmin(costs))
    best_theta, best_cost = float(grid[j]), float(costs[j])
    step = float(grid[1] - grid[0]) if n_grid > 1 else 0.0
    tol = 1e-6 * max(hi, 1e-3)
    while step > tol:
        a, b = max(lo, best_theta - step), min(hi, best_theta + step)
        zoom = np.linspace(a, b, ZOOM_POINTS)
        z_costs = _cost(prior, segments, zoom, workers)
        k = int(np.argmin(z_costs))
        if z_costs[k] < best_cost:
            best_theta, best_cost = float(zoom[k]), float(z_costs[k])
        step = float(zoom[1] - zoom[0])
    return best_theta, best_cost

#: Candidates per zoomed grid of :func:`_search` (21: each zoom narrows the cell tenfold).
ZOOM_POINTS = 21

class TwoStepIdentifier:
    """Paper A's two-step backlash identification (Section 4.3, steps 4-8).

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters ``P_hat`` (its ``theta`` is ignored).
    n_theta : float, optional
        Relative half-width of the final search interval around the pre-estimate,
        ``0 < n_theta < 1`` (default 0.1).
    cutoff_motor, cutoff_load : float, optional
        FIR cut-offs in rad/s for the motor and load speeds (default 50 and 20).
    numtaps : int, optional
        FIR length (odd); default per cut-off (see :func:`fir_lowpass`).
    dt1, dt2, dt3 : float, optional
        Windows of eq. 9 in s; default from the data (module docstring).
    dt4 : float, optional
        Span of ``W_1`` after ``t_s`` in s (default 1).
    anchor : {"sample", "fit"}, optional
        Amplitude of the decay in eq. 9 (see :func:`commutation_instants`).
    onset : {"constant", "unloading"}, optional
        Load speed before ``t_c`` in eq. 9: the paper's constant (default) or the
        unloading shaft's cubic fall (see :func:`commutation_instants`).
    level_window : float, optional
        Span in s before ``t_s`` over which the speed level that starts the model is
        averaged (default 1).
    n_grid : int, optional
        Grid points of the final search before refinement (default 21).
    workers : int, optional
        Threads for the simulations (default all cores).

    Attributes
    ----------
    theta_ : float
        Final estimate of the backlash half-width in rad.
    theta_ini_ : float
        Pre-estimate (eq. 6, mean over the records) in rad.
    theta_ini_per_record_ : list of float
        Eq. 6 per record, rad.
    commutations_ : list of Commutation
        ``t_s``, ``t_c``, ``t_b`` and windows per record.
    t_c_, t_b_ : list of float
        Per-record contact-loss and impact instants in s.
    bounds_ : tuple of float
        Final search interval ``theta_ini (1 -+ n_theta)`` in rad.
    cost_ : float
        ``W_1`` at ``theta_`` in (rad/s)^2.
    held_speed_gains_ : list of float
        :func:`held_speed_gain` per record (``records``, then the ``final_records``
        not among them): the held speeds over the prior's; one more than
        :data:`FAR_FROM_PRIOR` times off 1 raises a
        :class:`~backlashkit.errors.PriorMismatchWarning`.
    """

    method = "two-step"

    def __init__(
        self,
        prior: TwoMassDrive,
        *,
        n_theta: float = 0.1,
        cutoff_motor: float = 50.0,
        cutoff_load: float = 20.0,
        numtaps: int | None = None,
        dt1: float | None = None,
        dt2: float | None = None,
        dt3: float | None = None,
        dt4: float = DEFAULT_DT4,
        anchor: str = "sample",
        onset: str = "constant",
        level_window: float = 1.0,
        n_grid: int = 21,
        workers: int | None = None,
    ) -> None:
        self.prior = prior
        self.n_theta = n_theta
        self.cutoff_motor = cutoff_motor
        self.cutoff_load = cutoff_load
        self.numtaps = numtaps
        self.dt1, self.dt2, self.dt3, self.dt4 = dt1, dt2, dt3, dt4
        self.anchor = anchor
        self.onset = onset
        self.level_window = level_window
        self.n_grid = n_grid
        self.workers = workers

    def fit(self, records, final_records=None) -> TwoStepIdentifier:
        """Identify the backlash.

        Parameters
        ----------
        records : Record, tuple or sequence of them
            Step-down experiments for the pre-estimate (paper A's step 3,
            ``a_1 = 0.1 a_max``); a record may be a tuple ``(t, torque, w_motor,
            w_load)``.
        final_records : Record, tuple or sequence of them, optional
            Step-down experiments for the final least squares (step 7,
            ``a_2 = 0.6 a_max``); default ``records``.

        Returns
        -------
        TwoStepIdentifier
            ``self``, fitted.

        Raises
        ------
        InputError
            If a parameter is invalid, or a record has no step-down, no commutation
            the method can use, or a pre-estimate that is not positive (each message
            names the record).

        Warns
        -----
        PriorMismatchWarning
            If a record's held speeds are more than :data:`FAR_FROM_PRIOR` times off
            the prior's response (:func:`held_speed_gain`).
        """
        prior = check_prior(self.prior)
        n_theta = v.positive("n_theta", self.n_theta)
        if not n_theta < 1:
            raise InputError(f"n_theta must be < 1, got {self.n_theta!r}")
        dt4 = v.positive("dt4", self.dt4)
        level_window = v.positive("level_window", self.level_window)
        n_grid = v.integer("n_grid", self.n_grid, 2)
        # named here: the filter would only say "cutoff", not which one
        v.positive("cutoff_motor", self.cutoff_motor)
        v.positive("cutoff_load", self.cutoff_load)
        recs = as_records(records, prior=prior)
        finals = recs if final_records is None else as_records(final_records, "final_records",
                                                                prior=prior)
        gains = warn_held_speeds(recs + [f for f in finals if all(f is not r for r in recs)],
                                  prior)
        alpha = prior.f_L / prior.J_L
        comms, inis = [], []
        for rec in recs:
            com = commutation_instants(
                rec, alpha, dt1=self.dt1, dt2=self.dt2, dt3=self.dt3, anchor=self.anchor,
                onset=self.onset,
            )
            for name, cut in (("cutoff_motor", self.cutoff_motor),
                              ("cutoff_load", self.cutoff_load)):
                if not cut < math.pi / rec.ts:
                    raise InputError(
                        f"{name} must be below the Nyquist frequency pi/ts = "
                        f"{math.pi / rec.ts:.6g} rad/s of {rec.name}, got {cut!r}"
                    )
            wmf = fir_lowpass(rec.w_motor, self.cutoff_motor, rec.ts, numtaps=self.numtaps)
            wlf = fir_lowpass(rec.w_load, self.cutoff_load, rec.ts, numtaps=self.numtaps)
            ini = pre_estimate(wmf, wlf, rec.ts, com.i_c, com.i_b)
            if not ini > 0:
                raise InputError(
                    f"{rec.name}: the pre-estimate (eq. 6) between t_c = {com.t_c:.6g} s and "
                    f"t_b = {com.t_b:.6g} s is {ini:.3g} rad, not positive: no usable passage "
                    "through the backlash"
                )
            comms.append(com)
            inis.append(ini)
        theta_ini = float(np.mean(inis))
        segments = [_segment(r, dt4, level_window) for r in finals]
        lo, hi = theta_ini * (1 - n_theta), theta_ini * (1 + n_theta)
        self.theta_, self.cost_ = _search(prior, segments, lo, hi, n_grid, self.workers)
        self.theta_ini_ = theta_ini
        self.theta_ini_per_record_ = inis
        self.commutations_ = comms
        self.t_c_ = [c.t_c for c in comms]
        self.t_b_ = [c.t_b for c in comms]
        self.bounds_ = (lo, hi)
        self.held_speed_gains_ = gains
        return self

class RegressionIdentifier:
    """Paper A's baseline (Table 2): least squares on ``w_M`` over ``[0, theta_max]``.

    The criterion is ``W_1`` of :class:`TwoStepIdentifier` (model started at the
    measured steady state at ``t_s``, span ``dt4``) without the pre-estimate: a grid of
    ``n_grid`` points over ``[0, theta_max]`` and a bounded refinement around its best
    point.

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters (its ``theta`` is ignored).
    theta_max : float, optional
        Upper end of the search in rad (default 15 deg).
    dt4 : float, optional
        Span of the criterion after ``t_s`` in s (default 1).
    level_window : float, optional
        Span in s before ``t_s`` for the speed level that starts the model (default 1).
    n_grid : int, optional
        Grid points (default 61, a step of 0.25 deg over 15 deg).
    workers : int, optional
        Threads for the simulations (default all cores).

    Attributes
    ----------
    theta_ : float
        Estimate of the backlash half-width in rad.
    cost_ : float
        Criterion at ``theta_`` in (rad/s)^2.
    t_s_ : list of float
        Step-down instant per record in s.
    held_speed_gains_ : list of float
        :func:`held_speed_gain` per record: the held speeds over the prior's; one more
        than :data:`FAR_FROM_PRIOR` times off 1 raises a
        :class:`~backlashkit.errors.PriorMismatchWarning`.
    """

    method = "regression"

    def __init__(
        self,
        prior: TwoMassDrive,
        *,
        theta_max: float = float(np.deg2rad(15.0)),
        dt4: float = DEFAULT_DT4,
        level_window: float = 1.0,
        n_grid: int = 61,
        workers: int | None = None,
    ) -> None:
        self.prior = prior
        self.theta_max = theta_max
        self.dt4 = dt4
        self.level_window = level_window
        self.n_grid = n_grid
        self.workers = workers

    def fit(self, records) -> RegressionIdentifier:
        """Identify the backlash.

        Parameters
        ----------
        records : Record, tuple or sequence of them
            Step-down experiments (paper A: ``a_2 = 0.6 a_max``).

        Returns
        -------
        RegressionIdentifier
            ``self``, fitted.

        Raises
        ------
        InputError
            If a parameter is invalid or a record has no step-down.

        Warns
        -----
        PriorMismatchWarning
            If a record's held speeds are more than :data:`FAR_FROM_PRIOR` times off
            the prior's response (:func:`held_speed_gain`).
        """
        prior = check_prior(self.prior)
        theta_max = v.positive("theta_max", self.theta_max)
        dt4 = v.positive("dt4", self.dt4)
        level_window = v.positive("level_window", self.level_window)
        n_grid = v.integer("n_grid", self.n_grid, 2)
        recs = as_records(records, prior=prior)
        self.held_speed_gains_ = warn_held_speeds(recs, prior)
        segments = [_segment(r, dt4, level_window) for r in recs]
        self.theta_, self.cost_ = _search(prior, segments, 0.0, theta_max, n_grid, self.workers)
        self.t_s_ = [find_step_down(r)[1] for r in recs]
        return self
