"""Experiment signals on a uniform time grid, and measurement noise.

Every generator takes the time grid ``t`` (s, uniform and strictly increasing, at
least two samples; build one with :func:`time_grid`) and returns one value per
sample, ready to be used as the zero-order-hold motor torque of
:func:`backlashkit.simulate.simulate_drive` (``u[i]`` acts on ``[t[i], t[i+1])``).

A switching instant that falls between two samples takes effect at the first sample
at or after it. To keep a switching instant that lies on the grid from being moved a
sample late by floating-point rounding (``40000 * 1e-3`` need not equal ``40.0``), a
sample counts as "at or after" ``t_x`` when ``t >= t_x - 1e-6 * Ts``.

Units are SI: times in s, angular frequencies in **rad/s** (not Hz), phases in rad,
torques in N m.

**Signal-to-noise ratio.** Paper A leaves the definition of its SNRs open; this
project defines (see the project's ``NOTES.md``)::

    SNR_dB = 10 log10( mean(signal**2) / noise_variance )

with ``mean(signal**2)`` the mean square of the **noise-free** signal over the whole
record (its mean is *not* removed: a speed held at a constant level has the power
of that level) and ``noise_variance`` the variance of the additive white Gaussian
noise. :func:`add_noise` draws noise with exactly that variance;
:func:`measure_snr_db` measures the ratio of a noisy record to its clean version.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from . import validate as v
from .errors import InputError

__all__ = [
    "add_noise",
    "from_table",
    "highpass_noise_std",
    "measure_snr_db",
    "prbs",
    "sine",
    "step",
    "step_down",
    "time_grid",
]

ArrayLike = Sequence[float] | np.ndarray
Seed = int | np.random.Generator | np.random.SeedSequence

#: Tolerance, as a fraction of the sample time, when comparing grid times with
#: switching instants and table ends.
_SNAP = 1e-6

#: Largest grid :func:`time_grid` builds (400 MB of float64).
MAX_SAMPLES = 50_000_000

#: Smallest LFSR order used by :func:`prbs` (period 1023 bits), so that different
#: seeds give visibly different sequences even for short records.
_MIN_PRBS_ORDER = 10
#: Largest LFSR order (period ``2**32 - 1`` bits) known to :func:`scipy.signal.max_len_seq`.
_MAX_PRBS_ORDER = 32


def _grid(t: ArrayLike) -> tuple[np.ndarray, float]:
    return v.time_grid(t)


def _at_or_after(t: np.ndarray, ts: float, instant: float) -> np.ndarray:
    return t >= instant - _SNAP * ts


def as_generator(name: str, rng: Seed) -> np.random.Generator:
    """Return a :class:`numpy.random.Generator` from a generator or a seed.

    Parameters
    ----------
    name : str
        Name of the parameter, for the error message.
    rng : numpy.random.Generator, numpy.random.SeedSequence or int
        A generator (used as is, so its state advances) or a seed (an integer
        >= 0, or a :class:`~numpy.random.SeedSequence`).

    Returns
    -------
    numpy.random.Generator
        The generator.

    Raises
    ------
    InputError
        If ``rng`` is none of these (``None`` included: results must be
        reproducible, so a seed is always required).
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, np.random.SeedSequence):
        return np.random.default_rng(rng)
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        if rng < 0:
            raise InputError(f"{name} must be a seed >= 0 or a numpy.random.Generator, got {rng!r}")
        return np.random.default_rng(int(rng))
    raise InputError(
        f"{name} must be an integer seed >= 0 or a numpy.random.Generator, got {rng!r}"
    )


def time_grid(duration: float, ts: float) -> np.ndarray:
    """Uniform time grid ``t_k = k ts`` starting at 0.

    Parameters
    ----------
    duration : float
        Length of the record in s, > 0 and at least one sample time.
    ts : float
        Sample time in s, > 0.

    Returns
    -------
    numpy.ndarray
        ``t_k = k * ts`` for ``k = 0 .. floor(duration / ts)``: the grid includes
        ``duration`` itself when it is a multiple of ``ts`` (so a 80 s record at 1 ms
        has 80001 samples).

    Raises
    ------
    InputError
        If a parameter is not a positive finite number, ``duration < ts``, or the
        grid would exceed :data:`MAX_SAMPLES` samples.

    Examples
    --------
    >>> time_grid(0.003, 1e-3)
    array([0.   , 0.001, 0.002, 0.003])
    """
    d = v.positive("duration", duration)
    h = v.positive("ts", ts)
    steps = math.floor(d / h + _SNAP)
    if steps < 1:
        raise InputError(
            f"duration must be at least one sample time (ts = {h!r} s), got {duration!r} s"
        )
    if steps + 1 > MAX_SAMPLES:
        raise InputError(
            f"duration / ts gives {steps + 1} samples, more than the limit of {MAX_SAMPLES}; "
            "use a longer sample time ts or a shorter duration"
        )
    return np.arange(steps + 1, dtype=np.float64) * h


def step(t: ArrayLike, amplitude: float, *, t_step: float = 0.0) -> np.ndarray:
    """Step from 0 to ``amplitude`` at ``t_step``.

    Parameters
    ----------
    t : array_like
        Uniform, strictly increasing time grid in s.
    amplitude : float
        Level after the step.
    t_step : float, optional
        Instant of the step in s (default 0: the step is at or before the first
        sample when ``t[0] >= 0``).

    Returns
    -------
    numpy.ndarray
        ``0`` for ``t < t_step``, ``amplitude`` from the first sample at or after
        ``t_step``.
    """
    arr, ts = _grid(t)
    a = v.finite_scalar("amplitude", amplitude)
    ti = v.finite_scalar("t_step", t_step)
    return np.where(_at_or_after(arr, ts, ti), a, 0.0)


def step_down(t: ArrayLike, a: float, *, t_s: float, b: float = 0.0) -> np.ndarray:
    """Paper A's experiment: hold ``a`` until ``t_s``, then ``b``.

    Paper A (Section 5) applies ``a = 0.157`` N m from rest for ``t_s = 40`` s and then
    steps down to ``b = 0``: the drive reaches a steady state with the shaft on its
    positive flank, and the step-down makes it cross the backlash gap.

    Parameters
    ----------
    t : array_like
        Uniform, strictly increasing time grid in s.
    a : float
        Level for ``t < t_s``.
    t_s : float
        Instant of the step-down in s.
    b : float, optional
        Level from the first sample at or after ``t_s`` on (default 0).

    Returns
    -------
    numpy.ndarray
        The signal, one value per sample of ``t``.

    Raises
    ------
    InputError
        If a level is not finite, or ``t_s`` lies outside ``(t[0], t[-1]]``: the
        signal would hold one level throughout, no step-down.
    """
    arr, ts = _grid(t)
    a_ = v.finite_scalar("a", a)
    b_ = v.finite_scalar("b", b)
    ti = v.finite_scalar("t_s", t_s)
    step = _at_or_after(arr, ts, ti)
    if step[0] or not step[-1]:
        raise InputError(f"t_s must lie within the grid, after its first sample: in "
                         f"({arr[0]:g}, {arr[-1]:g}] s, got {t_s!r} (no step-down otherwise)")
    return np.where(step, b_, a_)


def sine(t: ArrayLike, amplitude: float, frequency: float, *, phase: float = 0.0) -> np.ndarray:
    """Sine wave ``amplitude * sin(frequency * t + phase)``.

    Parameters
    ----------
    t : array_like
        Uniform, strictly increasing time grid in s.
    amplitude : float
        Peak value.
    frequency : float
        Angular frequency in **rad/s** (not Hz), >= 0 and below the Nyquist
        frequency ``pi / Ts``.
    phase : float, optional
        Phase at ``t = 0`` in rad (default 0).

    Returns
    -------
    numpy.ndarray
        The signal, one value per sample of ``t``.

    Raises
    ------
    InputError
        If ``frequency`` is negative or at/above the Nyquist frequency (the samples
        would alias to a different sine).
    """
    arr, ts = _grid(t)
    a = v.finite_scalar("amplitude", amplitude)
    w = v.nonnegative("frequency", frequency)
    p = v.finite_scalar("phase", phase)
    nyquist = math.pi / ts
    if w >= nyquist:
        raise InputError(
            f"frequency must be below the Nyquist frequency pi/Ts = {nyquist:.6g} rad/s for "
            f"Ts = {ts:.6g} s, got {frequency!r} rad/s (frequency is in rad/s, not Hz)"
        )
    return a * np.sin(w * arr + p)


def prbs(
    t: ArrayLike,
    amplitude: float,
    *,
    bit_time: float,
    seed: Seed,
    order: int | None = None,
) -> np.ndarray:
    """Pseudo-random binary sequence with values ``+amplitude`` / ``-amplitude``.

    The bits are a maximal-length sequence of a linear-feedback shift register
    (:func:`scipy.signal.max_len_seq`) of ``order`` bits, whose period is
    ``2**order - 1`` bits; ``seed`` chooses its (non-zero) initial register state, so
    the signal is fully determined by the arguments. Bit ``j`` (1 mapped to
    ``+amplitude``, 0 to ``-amplitude``) holds from ``t[0] + j * bit_time`` on.

    Parameters
    ----------
    t : array_like
        Uniform, strictly increasing time grid in s.
    amplitude : float
        Level of the signal (the two values are ``+-amplitude``).
    bit_time : float
        Duration of one bit in s, >= the sample time. A bit boundary between two
        samples takes effect at the next sample.
    seed : int, numpy.random.SeedSequence or numpy.random.Generator
        Chooses the initial register state.
    order : int, optional
        Register length, 2 .. 32. Default: the smallest order (at least 10) whose
        period covers the record, so the sequence does not repeat.

    Returns
    -------
    numpy.ndarray
        The signal, one value per sample of ``t``.
    """
    from scipy.signal import max_len_seq

    arr, ts = _grid(t)
    a = v.finite_scalar("amplitude", amplitude)
    tb = v.positive("bit_time", bit_time)
    if tb < ts * (1 - _SNAP):
        raise InputError(
            f"bit_time must be at least the sample time Ts = {ts!r} s, got {bit_time!r} s"
        )
    index = np.floor((arr - arr[0]) / tb + _SNAP * ts / tb).astype(np.int64)
    n_bits = int(index[-1]) + 1
    if order is None:
        order = max(_MIN_PRBS_ORDER, math.ceil(math.log2(n_bits + 1)))
        order = min(order, _MAX_PRBS_ORDER)
    elif (
        isinstance(order, bool)
        or not isinstance(order, (int, np.integer))
        or not 2 <= order <= _MAX_PRBS_ORDER
    ):
        raise InputError(f"order must be an integer between 2 and {_MAX_PRBS_ORDER}, got {order!r}")
    rng = as_generator("seed", seed)
    state = np.zeros(int(order), dtype=np.int8)
    while not state.any():
        state = rng.integers(0, 2, int(order), dtype=np.int8)
    bits, _ = max_len_seq(int(order), state=state, length=n_bits)
    return np.where(bits[index] == 1, a, -a)


def from_table(
    t: ArrayLike,
    table_t: ArrayLike,
    table_values: ArrayLike,
    *,
    hold: str = "zoh",
) -> np.ndarray:
    """Resample a table of (time, value) pairs onto the grid ``t``.

    Parameters
    ----------
    t : array_like
        Uniform, strictly increasing time grid in s. It must lie inside
        ``[table_t[0], table_t[-1]]`` (to within ``1e-6 Ts``).
    table_t : array_like
        Strictly increasing times of the table in s (need not be uniform).
    table_values : array_like
        Values of the table, one per entry of ``table_t``.
    hold : {"zoh", "linear"}, optional
        ``"zoh"`` (default): zero-order hold, each grid sample takes the value of the
        last table entry at or before it. ``"linear"``: linear interpolation.

    Returns
    -------
    numpy.ndarray
        The table's values on the grid.

    Raises
    ------
    InputError
        If the table is malformed or does not cover the grid.

    Examples
    --------
    >>> from_table([0.0, 0.5, 1.0, 1.5], [0.0, 1.0, 1.5], [1.0, 2.0, 3.0])
    array([1., 1., 2., 3.])
    """
    arr, ts = _grid(t)
    tt = v.finite_array("table_t", table_t)
    vals = v.finite_array("table_values", table_values)
    if tt.size < 1:
        raise InputError("table_t must have at least one entry, got none")
    if vals.shape != tt.shape:
        raise InputError(
            f"table_values must have one value per entry of table_t ({tt.size}), got {vals.size}"
        )
    dt = np.diff(tt)
    if not (dt > 0).all():
        i = int(np.argmax(~(dt > 0)))
        raise InputError(
            f"table_t must be strictly increasing; table_t[{i + 1}] = {float(tt[i + 1])!r} "
            f"follows table_t[{i}] = {float(tt[i])!r}"
        )
    if hold not in ("zoh", "linear"):
        raise InputError(f"hold must be 'zoh' or 'linear', got {hold!r}")
    tol = _SNAP * ts
    if arr[0] < tt[0] - tol:
        raise InputError(
            f"t starts at {float(arr[0])!r} s, before the first time of the table, "
            f"table_t[0] = {float(tt[0])!r} s; the table must cover the whole grid"
        )
    if arr[-1] > tt[-1] + tol:
        raise InputError(
            f"t ends at {float(arr[-1])!r} s, after the last time of the table, "
            f"table_t[-1] = {float(tt[-1])!r} s; the table must cover the whole grid"
        )
    if hold == "linear":
        return np.interp(arr, tt, vals)
    j = np.searchsorted(tt, arr + tol, side="right") - 1
    return vals[np.clip(j, 0, tt.size - 1)]


#: Largest |SNR| in dB that :func:`add_noise` accepts (300 dB: noise 1e-15 of the signal).
SNR_LIMIT_DB = 300.0


def add_noise(signal: ArrayLike, snr_db: float, *, rng: Seed) -> np.ndarray:
    """Add white Gaussian measurement noise at a given signal-to-noise ratio.

    The noise is zero-mean, independent from sample to sample, with variance
    ``mean(signal**2) / 10**(snr_db / 10)``: the SNR is defined as
    ``10 log10(mean(signal**2) / noise_variance)`` over the whole record (the
    project's decision; see the module docstring and ``NOTES.md``). The mean square
    includes the signal's mean value.

    Parameters
    ----------
    signal : array_like
        Noise-free signal, 1-D, finite, not identically zero.
    snr_db : float
        Requested signal-to-noise ratio in dB, between -300 and 300.
    rng : numpy.random.Generator, numpy.random.SeedSequence or int
        Source of the noise: a generator (its state advances) or a seed.

    Returns
    -------
    numpy.ndarray
        ``signal + noise``, a new array.

    Raises
    ------
    InputError
        If ``signal`` is empty, non-finite or identically zero (its SNR is then
        undefined), ``snr_db`` is not within +-300 dB, or ``rng`` is not a generator or
        seed.

    Examples
    --------
    >>> noisy = add_noise(np.ones(100_000), 20.0, rng=0)
    >>> round(measure_snr_db(np.ones(100_000), noisy))
    20
    """
    s = v.finite_array("signal", signal)
    if s.size == 0:
        raise InputError("signal must have at least one sample, got none")
    snr = v.finite_scalar("snr_db", snr_db)
    if not -SNR_LIMIT_DB <= snr <= SNR_LIMIT_DB:  # 10**(snr / 10) must stay a float
        raise InputError(f"snr_db must be between -{SNR_LIMIT_DB:g} and {SNR_LIMIT_DB:g} dB, "
                         f"got {snr_db!r}")
    gen = as_generator("rng", rng)
    power = float(np.mean(s**2))
    if power == 0.0:
        raise InputError(
            "signal is identically zero, so a signal-to-noise ratio is undefined; "
            f"cannot add noise at snr_db = {snr_db!r}"
        )
    sigma = math.sqrt(power / 10.0 ** (snr / 10.0))
    return s + sigma * gen.standard_normal(s.size)


def measure_snr_db(clean: ArrayLike, noisy: ArrayLike) -> float:
    """Signal-to-noise ratio of a noisy record, in dB, by the project's definition.

    Parameters
    ----------
    clean : array_like
        The noise-free signal.
    noisy : array_like
        The same signal with noise, same length.

    Returns
    -------
    float
        ``10 log10(mean(clean**2) / var(noisy - clean))``; ``inf`` when the two are
        equal.
    """
    c = v.finite_array("clean", clean)
    n = v.finite_array("noisy", noisy)
    if c.shape != n.shape:
        raise InputError(f"noisy must have the shape of clean {c.shape}, got {n.shape}")
    if c.size < 2:
        raise InputError(f"clean must have at least 2 samples, got {c.size}")
    var = float(np.var(n - c))
    power = float(np.mean(c**2))
    if var == 0.0:
        return math.inf
    if power == 0.0:
        return -math.inf
    return 10.0 * math.log10(power / var)


def highpass_noise_std(y: np.ndarray) -> float:
    """Noise standard deviation of a signal from its robust second difference.

    Public because the estimators start their noise weights from it
    (:mod:`backlashkit.identify`).

    Parameters
    ----------
    y : numpy.ndarray
        Uniformly sampled signal (1-D).

    Returns
    -------
    float
        ``1.4826 MAD(diff(y, 2)) / sqrt(6)``: the standard deviation of white noise on
        a signal smooth at the sample scale (a second difference of white noise has
        variance ``6 s^2``; 1.4826 turns a median absolute deviation into a Gaussian
        std). 0 for fewer than 5 samples.
    """
    d2 = np.diff(y, 2)
    if d2.size < 3:
        return 0.0
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))
