"""Self-contained HTML report of a backlash identification (paper A).

:func:`write_identification_report` writes ``index.html`` and its figures (PNG, and
SVG beside each) into a directory: relative links only, inline CSS, no external
resource, so the directory can be zipped, mailed or opened offline. It shows

* measured and simulated speeds over the criterion's span ``[t_s, t_s + dt_4]`` with
  the fit ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` in %, the model being the
  prior with the estimated ``theta``, started as in the criterion ``W_1`` of
  :class:`~backlashkit.identify.TwoStepIdentifier`;
* per record, the zoom on the commutation window: filtered speeds, ``t_s``, ``t_c``,
  ``t_b`` and the integral of ``w_M - w_L`` of eq. 6 shaded (as paper A's
  Figs. 4-6);
* the criterion ``W_1(theta)`` over a grid (recomputed here by simulating
  ``prior.with_theta(theta)`` with :func:`backlashkit.simulate_batch`), with the
  pre-estimate window ``theta_ini (1 +- n_theta)`` and the estimate marked;
* for the joint estimator, the profile likelihood of ``theta`` where its interval
  search evaluated it (``profile_``), with the 95 % level and interval;
* the autocorrelation of the motor-speed residual with the ``+-1.96 / sqrt(N)`` band
  of white noise;
* a table of the estimates (``std`` and ``ci95`` shown as "n/a" when the method
  gives none).

The plot helpers (:func:`plot_speed_fit`, :func:`plot_commutation`,
:func:`plot_cost`, :func:`plot_profile`, :func:`plot_residual_acf`) take ``ax=`` and
return the figure; they use :class:`matplotlib.figure.Figure`, never ``pyplot``.

The CLI hook is :func:`add_report_option` plus :func:`maybe_write_report`.
"""

from __future__ import annotations

import argparse
import html
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError
from ..htmlpage import figure, page, save_figure
from ..io import check_writable
from ..plants import TwoMassDrive
from .record import Record, as_records
from .step import find_step_down
from .two_step import (
    DEFAULT_DT4,
    _cost,
    _segment,
    fir_lowpass,
)

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure

__all__ = [
    "add_report_option",
    "autocorrelation",
    "cost_curve",
    "fit_percent",
    "maybe_write_report",
    "plot_commutation",
    "plot_cost",
    "plot_profile",
    "plot_residual_acf",
    "plot_speed_fit",
    "write_identification_report",
]

PathLike = str | os.PathLike[str]

# --- numbers -----------------------------------------------------------------------


def fit_percent(y: Sequence[float] | np.ndarray, y_hat: Sequence[float] | np.ndarray) -> float:
    """Normalised fit ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` in %.

    Parameters
    ----------
    y : array_like
        Measured signal.
    y_hat : array_like
        Model output, same length.

    Returns
    -------
    float
        100 for a perfect fit, 0 for the mean, negative when worse than the mean;
        NaN when ``y`` is constant.
    """
    y = np.asarray(y, float)
    y_hat = np.asarray(y_hat, float)
    if y.shape != y_hat.shape:
        raise InputError(f"y and y_hat must have the same shape, got {y.shape} and {y_hat.shape}")
    den = float(np.linalg.norm(y - y.mean()))
    if den == 0.0:
        return math.nan
    return 100.0 * (1.0 - float(np.linalg.norm(y - y_hat)) / den)


def autocorrelation(x: Sequence[float] | np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation ``r(k) / r(0)`` of a signal, mean removed.

    Parameters
    ----------
    x : array_like
        The signal, at least 2 samples.
    max_lag : int
        Largest lag, ``0 <= max_lag < len(x)``.

    Returns
    -------
    numpy.ndarray
        ``max_lag + 1`` values for lags ``0 .. max_lag`` (the first is 1; all zero for
        a constant signal).
    """
    x = np.asarray(x, float) - np.mean(x)
    if not 0 <= max_lag < x.size:
        raise InputError(f"max_lag must be in [0, {x.size - 1}], got {max_lag!r}")
    r0 = float(x @ x)
    if r0 == 0.0:
        return np.zeros(max_lag + 1)
    return np.array([float(x[: x.size - k] @ x[k:]) for k in range(max_lag + 1)]) / r0


def cost_curve(
    prior: TwoMassDrive,
    records: Any,
    thetas: Sequence[float] | np.ndarray,
    *,
    dt4: float = DEFAULT_DT4,
    level_window: float = 1.0,
    workers: int | None = None,
) -> np.ndarray:
    """Paper A's criterion ``W_1(theta)`` (sum over records) on a grid of ``theta``.

    The same criterion as the final step of
    :class:`~backlashkit.identify.TwoStepIdentifier`: squared error of the motor speed
    over ``[t_s, t_s + dt4]``, the model ``prior.with_theta(theta)`` started at the
    measured steady state (simulated with :func:`backlashkit.simulate_batch`).

    Parameters
    ----------
    prior : TwoMassDrive
        Prior linear parameters.
    records : Record or sequence of Record
        Step-down experiments.
    thetas : array_like
        Backlash half-widths in rad, >= 0.
    dt4 : float, optional
        Span of the criterion after ``t_s`` in s (default 1).
    level_window : float, optional
        Span in s before ``t_s`` over which the starting speed is averaged (default 1).
    workers : int, optional
        Threads for the simulations (default all cores).

    Returns
    -------
    numpy.ndarray
        ``W_1`` in (rad/s)^2 per entry of ``thetas``.
    """
    recs = as_records(records)
    th = np.asarray(thetas, float).reshape(-1)
    if th.size == 0 or not np.isfinite(th).all() or (th < 0).any():
        raise InputError("thetas must be a non-empty array of finite values >= 0 (rad)")
    segments = [_segment(r, dt4, level_window) for r in recs]
    return _cost(prior, segments, th, workers)


@dataclass
class _Fit:
    record: Record
    t: np.ndarray
    w_motor: np.ndarray
    w_load: np.ndarray
    sim_motor: np.ndarray
    sim_load: np.ndarray
    fit_motor: float
    fit_load: float


def _simulate_fit(prior: TwoMassDrive, rec: Record, theta: float, dt4: float,
                  level_window: float) -> _Fit:
    from ..simulate import simulate_batch

    seg = _segment(rec, dt4, level_window)
    i_s = find_step_down(rec)[0]
    sl = slice(i_s, i_s + seg.t.size)
    x0 = np.array([[seg.w0, seg.w0, theta + prior.f_L * seg.w0 / prior.k_sh]])
    (r,) = simulate_batch([prior.with_theta(theta)], seg.t, seg.torque, initial_state=x0,
                          workers=1)
    wm, wl = rec.w_motor[sl], rec.w_load[sl]
    return _Fit(rec, seg.t, wm, wl, r.w_motor, r.w_load,
                fit_percent(wm, r.w_motor), fit_percent(wl, r.w_load))


# --- plot helpers ---------------------------------------------------------------------


def _ax(ax, figsize=(8.0, 3.2)):
    if ax is None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=figsize, layout="constrained")
        return fig, fig.subplots()
    return ax.figure, ax


def plot_speed_fit(
    t: Sequence[float] | np.ndarray,
    measured: Sequence[float] | np.ndarray,
    simulated: Sequence[float] | np.ndarray,
    *,
    label: str = "w_M",
    ax: matplotlib.axes.Axes | None = None,
) -> matplotlib.figure.Figure:
    """Plot a measured and a simulated speed with the fit in % in the legend.

    Parameters
    ----------
    t : array_like
        Time in s.
    measured, simulated : array_like
        Speeds in rad/s, one per ``t``.
    label : str, optional
        Name of the speed (default ``"w_M"``).
    ax : matplotlib.axes.Axes, optional
        Axes to draw in; a new figure when omitted.

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding the axes.
    """
    fig, ax = _ax(ax)
    fit = fit_percent(measured, simulated)
    ax.plot(t, measured, color="0.55", lw=0.8, label=f"{label} measured")
    ax.plot(t, simulated, color="C3", lw=1.3, label=f"{label} simulated (fit {fit:.1f} %)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"{label} [rad/s]")
    ax.legend(loc="best", fontsize="small")
    ax.grid(alpha=0.3)
    return fig


def plot_commutation(
    record: Record,
    t_c: float,
    t_b: float,
    *,
    cutoff_motor: float = 50.0,
    cutoff_load: float = 20.0,
    margin: float | None = None,
    ax: matplotlib.axes.Axes | None = None,
) -> matplotlib.figure.Figure:
    """Zoom on the passage through the backlash after the step-down (paper A, Figs. 4-6).

    Raw speeds in grey, FIR-filtered speeds in colour, ``t_s``, ``t_c`` and ``t_b``
    marked, and the area between the filtered speeds over ``[t_c, t_b]`` shaded: eq. 6
    gives ``theta_ini = -0.5`` times its signed integral (shown in the title).

    Parameters
    ----------
    record : Record
        The experiment.
    t_c, t_b : float
        Contact-loss and impact instants in s.
    cutoff_motor, cutoff_load : float, optional
        FIR cut-offs in rad/s (default 50 and 20, as the identifier's).
    margin : float, optional
        Time shown before ``t_s`` and after ``t_b`` in s; default half of
        ``t_b - t_s``.
    ax : matplotlib.axes.Axes, optional
        Axes to draw in; a new figure when omitted.

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding the axes.
    """
    fig, ax = _ax(ax)
    _, t_s, _, _ = find_step_down(record)
    ts = record.ts
    wmf = fir_lowpass(record.w_motor, cutoff_motor, ts)
    wlf = fir_lowpass(record.w_load, cutoff_load, ts)
    margin = 0.5 * (t_b - t_s) if margin is None else margin
    t = record.t
    win = (t >= t_s - margin) & (t <= t_b + margin)
    ax.plot(t[win], record.w_motor[win], color="C0", alpha=0.25, lw=0.6)
    ax.plot(t[win], record.w_load[win], color="C1", alpha=0.25, lw=0.6)
    ax.plot(t[win], wmf[win], color="C0", lw=1.4, label="w_M filtered")
    ax.plot(t[win], wlf[win], color="C1", lw=1.4, label="w_L filtered")
    i_c = int(np.argmin(np.abs(t - t_c)))
    i_b = int(np.argmin(np.abs(t - t_b)))
    sl = slice(i_c, i_b + 1)
    ax.fill_between(t[sl], wmf[sl], wlf[sl], color="C2", alpha=0.3,
                    label="integral of w_M - w_L")
    d = wmf[sl] - wlf[sl]
    theta_ini = -0.5 * ts * (d.sum() - 0.5 * (d[0] + d[-1]))
    for x, name, style in ((t_s, "t_s", ":"), (t_c, "t_c", "--"), (t_b, "t_b", "--")):
        ax.axvline(x, color="k", ls=style, lw=0.8)
        ax.annotate(name, (x, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -12),
                    textcoords="offset points", fontsize="small")
    ax.set_title(f"{_short(record.name)}: t_c = {t_c:.4f} s, t_b = {t_b:.4f} s, "
                 f"-0.5 integral = {theta_ini:.4g} rad", fontsize="medium")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("speed [rad/s]")
    ax.legend(loc="best", fontsize="small")
    ax.grid(alpha=0.3)
    return fig


def plot_cost(
    thetas: Sequence[float] | np.ndarray,
    costs: Sequence[float] | np.ndarray,
    *,
    theta: float | None = None,
    theta_ini: float | None = None,
    bounds: tuple[float, float] | None = None,
    ax: matplotlib.axes.Axes | None = None,
) -> matplotlib.figure.Figure:
    """Plot the criterion against ``theta`` with the search window and estimates.

    Parameters
    ----------
    thetas : array_like
        Backlash half-widths in rad.
    costs : array_like
        Criterion per ``theta`` in (rad/s)^2.
    theta : float, optional
        Final estimate in rad (marked).
    theta_ini : float, optional
        Pre-estimate in rad (marked).
    bounds : tuple of float, optional
        Search window in rad, e.g. ``theta_ini (1 -+ n_theta)`` (shaded).
    ax : matplotlib.axes.Axes, optional
        Axes to draw in; a new figure when omitted.

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding the axes.
    """
    fig, ax = _ax(ax)
    deg = 180.0 / math.pi
    th = np.asarray(thetas, float)
    ax.plot(th * deg, costs, color="k", lw=1.2, marker=".", ms=3, label="W_1(theta)")
    if bounds is not None:
        ax.axvspan(bounds[0] * deg, bounds[1] * deg, color="C2", alpha=0.2,
                   label="search window")
    if theta_ini is not None:
        ax.axvline(theta_ini * deg, color="C2", ls="--", lw=1,
                   label=f"theta_ini = {theta_ini:.4g} rad")
    if theta is not None:
        ax.axvline(theta * deg, color="C3", lw=1.3, label=f"theta = {theta:.4g} rad")
    c = np.asarray(costs, float)
    if c.size and c.min() > 0 and c.max() / c.min() > 20:  # several decades: log scale
        ax.set_yscale("log")
    ax.set_xlabel("theta (half-width) [deg]")
    ax.set_ylabel("W_1 [(rad/s)^2]")
    ax.legend(loc="best", fontsize="small")
    ax.grid(alpha=0.3, which="both")
    return fig


def plot_profile(
    profile: Sequence[Sequence[float]] | np.ndarray,
    *,
    ci95: tuple[float, float] | None = None,
    theta: float | None = None,
    std: float | None = None,
    ax: matplotlib.axes.Axes | None = None,
) -> matplotlib.figure.Figure:
    """Plot a profile likelihood of ``theta`` with the 95 % level and interval.

    With ``theta`` and its Fisher ``std`` the quadratic the Fisher interval assumes,
    ``(log(t / theta) / (std / theta))^2``, is drawn too: where the points leave it,
    the likelihood is not quadratic and the two intervals differ.

    Parameters
    ----------
    profile : array_like, shape (k, 2)
        Rows ``(theta, rise)``: half-width in rad and the cost rise of the refit with
        ``theta`` held, in chi-square units (``JointIdentifier.profile_``).
    ci95 : tuple of float, optional
        The interval in rad (shaded).
    theta : float, optional
        The estimate in rad.
    std : float, optional
        Its Fisher standard error in rad.
    ax : matplotlib.axes.Axes, optional
        Axes to draw in; a new figure when omitted.

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding the axes.
    """
    from .intervals import CHI2_95

    fig, ax = _ax(ax)
    deg = 180.0 / math.pi
    p = np.asarray(profile, float).reshape(-1, 2)
    if theta is not None and std is not None and theta > 0 and std > 0:
        lo, hi = float(np.min(p[:, 0])), float(np.max(p[:, 0]))
        span = max(hi - lo, 4.0 * std)
        grid = np.linspace(max(lo - 0.15 * span, theta * 1e-3), hi + 0.15 * span, 200)
        ax.plot(grid * deg, (np.log(grid / theta) / (std / theta)) ** 2, color="C0",
                ls=":", lw=1.2, label="Fisher (quadratic)")
    ax.plot(p[:, 0] * deg, p[:, 1], color="k", ls="none", marker="o", ms=5,
            label="refit with theta held")
    ax.axhline(CHI2_95, color="C3", ls="--", lw=1, label="95 % level (3.84)")
    if ci95 is not None:
        ax.axvspan(ci95[0] * deg, ci95[1] * deg, color="C0", alpha=0.15,
                   label="95 % interval")
    ax.set_xlabel("theta (half-width) [deg]")
    ax.set_ylabel("cost rise [chi-square units]")
    ax.legend(loc="best", fontsize="small")
    ax.grid(alpha=0.3)
    return fig


def plot_residual_acf(
    residual: Sequence[float] | np.ndarray,
    *,
    ts: float = 1.0,
    max_lag: int | None = None,
    label: str | None = None,
    ax: matplotlib.axes.Axes | None = None,
) -> matplotlib.figure.Figure:
    """Plot the residual's normalised autocorrelation with the 95 % white-noise band.

    Parameters
    ----------
    residual : array_like
        Measured minus simulated output.
    ts : float, optional
        Sample time in s (the lag axis is in ms; default 1).
    max_lag : int, optional
        Largest lag in samples; default ``min(N // 4, 200)``.
    label : str, optional
        Legend label of the curve.
    ax : matplotlib.axes.Axes, optional
        Axes to draw in; a new figure when omitted (a second call with the same
        axes adds a curve).

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding the axes.
    """
    fig, ax = _ax(ax)
    e = np.asarray(residual, float)
    n = e.size
    max_lag = min(n // 4, 200) if max_lag is None else max_lag
    r = autocorrelation(e, max_lag)
    lags = np.arange(max_lag + 1) * ts * 1e3
    ax.plot(lags, r, lw=1.0, marker=".", ms=2, label=label)
    band = 1.96 / math.sqrt(n)
    ax.axhspan(-band, band, color="0.5", alpha=0.15)
    ax.axhline(band, color="0.4", ls="--", lw=0.8)
    ax.axhline(-band, color="0.4", ls="--", lw=0.8)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("lag [ms]")
    ax.set_ylabel("autocorrelation")
    ax.set_title(f"residual w_M - w_M,sim (band ±1.96/sqrt(N), N = {n})", fontsize="medium")
    if label is not None:
        ax.legend(loc="best", fontsize="small")
    ax.grid(alpha=0.3)
    return fig


# --- the report -----------------------------------------------------------------------


def _short(name: str, width: int = 40) -> str:
    return name if len(name) <= width else "..." + name[-(width - 3):]


def _fmt(x: Any, spec: str = ".5g") -> str:
    if x is None:
        return "n/a"
    if isinstance(x, (tuple, list, np.ndarray)):
        return "[" + ", ".join(_fmt(v, spec) for v in x) + "]"
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return html.escape(str(x))
    return "n/a" if not math.isfinite(xf) else format(xf, spec)


def _deg(x: Any) -> str:
    if x is None:
        return "n/a"
    if isinstance(x, (tuple, list, np.ndarray)):
        return _fmt([math.degrees(float(v)) for v in x], ".4g")
    return _fmt(math.degrees(float(x)), ".4g")


def check_report_directory(out: Path, *, force: bool) -> None:
    """Refuse a report directory that is a file, or holds files, unless ``force``.

    Parameters
    ----------
    out : pathlib.Path
        The report directory (it may not exist yet).
    force : bool
        Write into a directory that is not empty.

    Raises
    ------
    InputError
        If ``out`` is a file, or a directory that is not empty and ``force`` is False.
    """
    if out.exists() and not out.is_dir():
        raise InputError(f"cannot write the report into {out}: it is a file, not a directory")
    if out.is_dir() and any(out.iterdir()) and not force:  # the user's files stay theirs
        index = out / "index.html"
        what = f"{index} already exists" if index.exists() else f"{out} is not empty"
        raise InputError(
            f"{what}; pass --force (force=True from Python) to write the report there "
            "anyway (its files are overwritten), or choose another directory"
        )
    check_writable(out, "the report into", directory=True)


def write_identification_report(
    directory: PathLike,
    records: Any,
    result: Any,
    *,
    prior: TwoMassDrive,
    force: bool = False,
    final_records: Any = None,
    title: str = "Backlash identification report",
) -> Path:
    """Write an HTML report of a fitted identifier into ``directory``.

    Parameters
    ----------
    directory : str or os.PathLike
        Output directory, created if absent; ``index.html`` and the figures
        (``fit.png``, ``commutation.png``, ``cost.png``, ``residual_acf.png`` and
        their ``.svg``) go into it.
    records : Record or sequence of Record
        The experiments the identifier was fitted on (for the pre-estimate).
    result : object
        A fitted identifier (duck-typed): ``theta_`` in rad is required; read when
        present: ``theta_ini_``, ``t_c_``, ``t_b_``, ``bounds_``, ``std_``, ``ci95_``,
        ``cost_``, ``method``, ``theta_ini_per_record_``, ``n_theta``, ``dt4``,
        ``level_window``, ``cutoff_motor``, ``cutoff_load``.
    prior : TwoMassDrive
        Prior linear parameters used by the fit.
    force : bool, optional
        Write into a directory that is not empty, overwriting the report's files
        (default False: refuse).
    final_records : Record or sequence of Record, optional
        Experiments of the final least squares when they differ from ``records``
        (paper A's step 2); the fits, cost curve and residuals use them.
    title : str, optional
        Heading of the page.

    Returns
    -------
    pathlib.Path
        Path of the written ``index.html``.

    Raises
    ------
    InputError
        If the directory is not empty and ``force`` is False, the directory cannot be
        created, or the result lacks a finite ``theta_``.
    """
    if not isinstance(prior, TwoMassDrive):
        raise InputError(f"prior must be a TwoMassDrive, got {type(prior).__name__}")
    theta = getattr(result, "theta_", None)
    try:
        theta = float(theta)
    except (TypeError, ValueError):
        theta = math.nan
    if not math.isfinite(theta) or theta < 0:
        raise InputError(
            f"result must be a fitted identifier with a finite theta_ >= 0 (rad), got "
            f"{getattr(result, 'theta_', None)!r}; call fit() first"
        )
    out = Path(directory)
    index = out / "index.html"
    check_report_directory(out, force=force)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the report directory {out}: {exc.strerror}") from None

    recs = as_records(records)
    finals = recs if final_records is None else as_records(final_records, "final_records")
    dt4 = float(getattr(result, "dt4", DEFAULT_DT4))
    if not hasattr(result, "dt4"):  # the joint fit has no window: show what was recorded
        dt4 = min([dt4] + [r.t[-1] - find_step_down(r)[1] - r.ts for r in finals])
    level_window = float(getattr(result, "level_window", 1.0))
    cut_m = float(getattr(result, "cutoff_motor", 50.0))
    cut_l = float(getattr(result, "cutoff_load", 20.0))
    theta_ini = getattr(result, "theta_ini_", None)
    bounds = getattr(result, "bounds_", None)
    t_c = getattr(result, "t_c_", None)
    t_b = getattr(result, "t_b_", None)
    method = str(getattr(result, "method", type(result).__name__))
    workers = getattr(result, "workers", None)

    from matplotlib.figure import Figure

    # 1. measured vs simulated
    fits = [_simulate_fit(prior, r, theta, dt4, level_window) for r in finals]
    fig = Figure(figsize=(9, 2.6 * len(fits) + 0.4), layout="constrained")
    axes = fig.subplots(len(fits), 2, squeeze=False)
    for k, f in enumerate(fits):
        plot_speed_fit(f.t, f.w_motor, f.sim_motor, label="w_M", ax=axes[k, 0])
        plot_speed_fit(f.t, f.w_load, f.sim_load, label="w_L", ax=axes[k, 1])
        axes[k, 0].set_title(_short(f.record.name), fontsize="medium", loc="left")
    save_figure(fig, out, "fit")

    # 2. commutation windows
    has_comm = (t_c is not None and t_b is not None and len(t_c) == len(recs)
                and all(x is not None for x in (*t_c, *t_b)))
    if has_comm:
        fig = Figure(figsize=(9, 3.2 * len(recs) + 0.3), layout="constrained")
        axes = fig.subplots(len(recs), 1, squeeze=False)[:, 0]
        for rec, c, b, ax in zip(recs, t_c, t_b, axes, strict=True):
            plot_commutation(rec, float(c), float(b), cutoff_motor=cut_m, cutoff_load=cut_l,
                             ax=ax)
        save_figure(fig, out, "commutation")

    # 3. cost curve
    top = 2.0 * theta
    if bounds is not None:
        top = max(top, 1.3 * float(bounds[1]))
    if theta_ini is not None:
        top = max(top, 2.5 * float(theta_ini))
    if bounds is None and getattr(result, "theta_max", None) is not None:
        top = max(top, float(result.theta_max))  # regression: its whole search range
    top = top if top > 0 else math.radians(5.0)
    grid = np.linspace(0.0, top, 61)
    if bounds is not None:
        grid = np.union1d(grid, np.linspace(float(bounds[0]), float(bounds[1]), 21))
    grid = np.union1d(grid, [theta])
    costs = cost_curve(prior, finals, grid, dt4=dt4, level_window=level_window,
                       workers=workers)
    fig = plot_cost(grid, costs, theta=theta,
                    theta_ini=None if theta_ini is None else float(theta_ini),
                    bounds=None if bounds is None else (float(bounds[0]), float(bounds[1])))
    save_figure(fig, out, "cost")

    # 3b. profile likelihood (joint estimator with ProfileLikelihood)
    profile = getattr(result, "profile_", None)
    if profile is not None:
        fig = plot_profile(profile, ci95=getattr(result, "ci95_", None), theta=theta,
                           std=getattr(result, "std_", None))
        save_figure(fig, out, "profile")

    # 4. residual autocorrelation
    fig = Figure(figsize=(8, 3.2), layout="constrained")
    ax = fig.subplots()
    for f in fits:
        plot_residual_acf(f.w_motor - f.sim_motor, ts=f.record.ts,
                          label=_short(f.record.name, 30) if len(fits) > 1 else None, ax=ax)
    save_figure(fig, out, "residual_acf")

    # the page
    std = getattr(result, "std_", None)
    ci95 = getattr(result, "ci95_", None)
    kind = {"profile": ", profile likelihood", "fisher": ", Fisher",
            "bootstrap": ", parametric bootstrap"}.get(getattr(result, "interval_", None), "")
    cost = getattr(result, "cost_", None)
    n_theta = getattr(result, "n_theta", None)
    rows = [
        ("theta (half-width)", _fmt(theta), _deg(theta), _fmt(std), _fmt(ci95)),
        ("theta_ini (eq. 6)", _fmt(theta_ini), _deg(theta_ini), "n/a", "n/a"),
        ("search interval", _fmt(bounds), _deg(bounds), "", ""),
    ]
    est_rows = "\n".join(
        f'<tr><td class="l">{a}</td><td>{b}</td><td>{c}</td><td>{d}</td><td>{e}</td></tr>'
        for a, b, c, d, e in rows
    )
    per_ini = getattr(result, "theta_ini_per_record_", None) or [None] * len(recs)
    rec_rows = []
    for k, rec in enumerate(recs):
        t_s = find_step_down(rec)[1]
        rec_rows.append(
            f'<tr><td class="l">{html.escape(rec.name)}</td><td>{t_s:.4f}</td>'
            f"<td>{_fmt(t_c[k] if has_comm else None, '.4f')}</td>"
            f"<td>{_fmt(t_b[k] if has_comm else None, '.4f')}</td>"
            f"<td>{_fmt(per_ini[k] if k < len(per_ini) else None)}</td></tr>"
        )
    fit_rows = "\n".join(
        f'<tr><td class="l">{html.escape(f.record.name)}</td><td>{f.fit_motor:.2f}</td>'
        f"<td>{f.fit_load:.2f}</td><td>{f.t.size}</td></tr>"
        for f in fits
    )
    p = prior
    prior_txt = ", ".join(
        f"{k} = {getattr(p, k):.4g}" for k in ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh")
    )
    window = (
        f"theta_ini (1 ± n_theta), n_theta = {_fmt(n_theta)}"
        if n_theta is not None and bounds is not None
        else "the method's search interval" if bounds is not None else "none"
    )
    sections = [
        f"<h1>{html.escape(title)}</h1>",
        f'<p class="note">Method <b>{html.escape(method)}</b>. theta is the backlash '
        "<b>half-width</b> (dead zone [-theta, theta], total gap 2 theta). SI units. "
        f"Prior: {prior_txt}.</p>",
        "<h2>Estimates</h2>",
        '<table><tr><th class="l">quantity</th><th>rad</th><th>deg</th><th>std (rad)</th>'
        f"<th>95 % interval (rad{kind})</th></tr>\n{est_rows}</table>",
        f'<p class="note">Criterion at the estimate W_1 = {_fmt(cost)} (rad/s)^2 '
        f"over dt_4 = {dt4:g} s after t_s.</p>",
        '<table><tr><th class="l">record</th><th>t_s (s)</th><th>t_c (s)</th>'
        "<th>t_b (s)</th><th>theta_ini (rad)</th></tr>\n" + "\n".join(rec_rows) + "</table>",
        "<h2>Measured and simulated speeds</h2>",
        '<table><tr><th class="l">record</th><th>fit w_M (%)</th><th>fit w_L (%)</th>'
        f"<th>samples</th></tr>\n{fit_rows}</table>",
        '<p class="note">fit = 100 (1 - ||y - y_hat|| / ||y - mean(y)||) over '
        f"[t_s, t_s + {dt4:g} s]; model: prior with the estimated theta, started at the "
        "measured steady state.</p>",
        figure("fit", "Measured (grey) and simulated (red) motor and load speeds"),
    ]
    if has_comm:
        sections += [
            "<h2>Commutation window</h2>",
            figure(
                "commutation",
                "Filtered speeds around the step-down: contact loss t_c, impact t_b and the "
                "integral of w_M - w_L (shaded) whose -1/2 is the pre-estimate (eq. 6)",
            ),
        ]
    sections += [
        "<h2>Criterion against theta</h2>",
        figure("cost", f"W_1(theta) on w_M; shaded: {window}"),
    ]
    if profile is not None:
        sections += [
            "<h2>Profile likelihood of theta</h2>",
            figure("profile", "Cost rise of the refit with theta held (the other "
                   "estimated parameters re-optimised), where the interval search "
                   "evaluated it; the 95 % interval ends where it reaches 3.84"),
        ]
    sections += [
        "<h2>Residual autocorrelation</h2>",
        figure(
            "residual_acf",
            "Normalised autocorrelation of w_M - w_M,sim; inside the dashed band "
            "±1.96/sqrt(N) the residual is compatible with white noise",
        ),
    ]
    if hasattr(result, "correlation_message"):  # the joint estimator's noise model
        ar = getattr(result, "noise_ar_", None)
        model = "white" if ar is None else f"autoregressive of order {ar.shape[-1]}"
        message = result.correlation_message()
        sections.append(
            f'<p class="note">Noise model: {model}. '
            + (f"<b>Note:</b> {html.escape(message)}." if message else
               "The residuals the likelihood treats as white are, to lag-1 correlation "
               f"0.2 (largest: {float(np.max(np.abs(result.residual_lag1_))):.3f}).")
            + "</p>"
        )
    index.write_text(page(title, sections), encoding="utf-8")
    return index


# --- CLI hook ---------------------------------------------------------------------------


def add_report_option(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add ``--report DIR`` and ``--force`` to the ``identify`` subcommand's parser.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The subcommand's parser.

    Returns
    -------
    argparse.ArgumentParser
        The same parser.
    """
    parser.add_argument(
        "--report",
        metavar="DIR",
        default=None,
        help="write an HTML report (index.html and PNG/SVG figures) into DIR",
    )
    parser.add_argument(
        "--force", action="store_true", help="write the report into DIR even if it is not "
        "empty (the report's files are overwritten)"
    )
    return parser


def maybe_write_report(
    args: argparse.Namespace,
    records: Any,
    result: Any,
    prior: TwoMassDrive,
    final_records: Any = None,
) -> Path | None:
    """Write the report if ``--report`` was given.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments with ``report`` and ``force`` (see :func:`add_report_option`).
    records : Record or sequence of Record
        Experiments given to the identifier.
    result : object
        The fitted identifier.
    prior : TwoMassDrive
        The prior drive.
    final_records : Record or sequence of Record, optional
        Experiments of the final least squares, when given separately.

    Returns
    -------
    pathlib.Path or None
        Path of ``index.html``, or None when no report was asked for.
    """
    directory = getattr(args, "report", None)
    if directory is None:
        return None
    return write_identification_report(
        directory, records, result, prior=prior, force=bool(getattr(args, "force", False)),
        final_records=final_records,
    )
