"""Figures of a backlash identification, each on its own axes.

The plot helpers take ``ax=`` and return the figure; they use
:class:`matplotlib.figure.Figure`, never ``pyplot``, and change no global state.
:func:`backlashkit.identify.report.write_identification_report` puts them on a page.

Every ``theta`` is the backlash **half-width** in rad. Units are SI; the plots show
``theta`` in degrees (axes and legends alike), the tables beside them in rad. Legends
sit to the right of the axes, off the data.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..report import legend_outside
from .commutation import fir_lowpass
from .record import Record
from .step import find_step_down

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure

__all__ = [
    "autocorrelation",
    "fit_percent",
    "plot_commutation",
    "plot_cost",
    "plot_profile",
    "plot_residual_acf",
    "plot_speed_fit",
]


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


def _short(name: str, width: int = 40) -> str:
    return name if len(name) <= width else "..." + name[-(width - 3):]


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
    legend_outside(ax)
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
    marked, and the area between the filtered speeds over ``[t_c, t_b]`` shaded: the
    pre-estimate is ``theta_ini = -0.5`` times its signed integral (shown in the title,
    in degrees).

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
    ax.plot(t[win], record.w_motor[win], color="C0", alpha=0.25, lw=0.6, label="w_M raw")
    ax.plot(t[win], record.w_load[win], color="C1", alpha=0.25, lw=0.6, label="w_L raw")
    ax.plot(t[win], wmf[win], color="C0", lw=1.4, label="w_M filtered")
    ax.plot(t[win], wlf[win], color="C1", lw=1.4, label="w_L filtered")
    i_c = int(np.argmin(np.abs(t - t_c)))
    i_b = int(np.argmin(np.abs(t - t_b)))
    sl = slice(i_c, i_b + 1)
    ax.fill_between(t[sl], wmf[sl], wlf[sl], color="C2", alpha=0.3,
                    label="area between the filtered speeds")
    d = wmf[sl] - wlf[sl]
    theta_ini = -0.5 * ts * (d.sum() - 0.5 * (d[0] + d[-1]))
    # t_s labelled at the bottom: t_c often follows it within a few samples
    for x, name, style, y, dy in ((t_s, "t_s", ":", 0.0, 4), (t_c, "t_c", "--", 1.0, -12),
                                  (t_b, "t_b", "--", 1.0, -12)):
        ax.axvline(x, color="k", ls=style, lw=0.8)
        ax.annotate(name, (x, y), xycoords=("data", "axes fraction"), xytext=(2, dy),
                    textcoords="offset points", fontsize="small")
    ax.set_title(f"{_short(record.name, 60)}\ncontact lost at t_c = {t_c:.4f} s, impact at "
                 f"t_b = {t_b:.4f} s; -1/2 of the area = {math.degrees(theta_ini):.3g} deg",
                 fontsize="medium")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("speed [rad/s]")
    legend_outside(ax)
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

    The ``theta`` axis and the legend are in degrees.

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
    ax.plot(th * deg, costs, color="k", lw=1.2, marker=".", ms=3, label="squared error")
    if bounds is not None:
        ax.axvspan(bounds[0] * deg, bounds[1] * deg, color="C2", alpha=0.2,
                   label=f"search interval\n[{bounds[0] * deg:.3g}, {bounds[1] * deg:.3g}] deg")
    if theta_ini is not None:
        ax.axvline(theta_ini * deg, color="C2", ls="--", lw=1,
                   label=f"pre-estimate theta_ini\n= {theta_ini * deg:.4g} deg")
    if theta is not None:
        ax.axvline(theta * deg, color="C3", lw=1.3,
                   label=f"estimate theta\n= {theta * deg:.4g} deg")
    c = np.asarray(costs, float)
    if c.size and c.min() > 0 and c.max() / c.min() > 20:  # several decades: log scale
        ax.set_yscale("log")
    ax.set_xlabel("theta (half-width) [deg]")
    ax.set_ylabel("squared motor-speed error [(rad/s)^2]")
    ax.set_title("Squared motor-speed error of the prior with each theta",
                 fontsize="medium")
    legend_outside(ax)
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
    from .intervals import CHI2_95, reaches_zero

    p = np.asarray(profile, float)
    p = p.reshape(0, 2) if p.size == 0 else p
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"profile must be rows (theta in rad, cost rise), shape (k, 2), "
                         f"got shape {p.shape}: give JointIdentifier.profile_")
    fig, ax = _ax(ax)
    deg = 180.0 / math.pi
    if theta is not None and std is not None and theta > 0 and std > 0:
        lo, hi = float(np.min(p[:, 0])), float(np.max(p[:, 0]))
        span = max(hi - lo, 4.0 * std)
        # quadratic in log theta, as fitted; in theta where its interval reaches 0 (the
        # profile is then followed in rad, ProfileLikelihood)
        near_zero = reaches_zero(theta, std)
        grid = np.linspace(0.0 if near_zero else max(lo - 0.15 * span, theta * 1e-3),
                           hi + 0.15 * span, 200)
        quad = ((grid - theta) / std) ** 2 if near_zero else (
            np.log(grid / theta) / (std / theta)) ** 2
        ax.plot(grid * deg, quad, color="C0", ls=":", lw=1.2, label="Fisher (quadratic)")
    ax.plot(p[:, 0] * deg, p[:, 1], color="k", ls="none", marker="o", ms=5,
            label="refit with theta held")
    ax.axhline(CHI2_95, color="C3", ls="--", lw=1, label="95 % level (3.84)")
    if ci95 is not None:
        ax.axvspan(ci95[0] * deg, ci95[1] * deg, color="C0", alpha=0.15,
                   label="95 % interval")
    ax.set_xlabel("theta (half-width) [deg]")
    ax.set_ylabel("cost rise [chi-square units]")
    ax.set_title("Profile likelihood of theta", fontsize="medium")
    legend_outside(ax)
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
    first = not ax.lines  # the band and its legend entry once per axes
    e = np.asarray(residual, float)
    n = e.size
    max_lag = min(n // 4, 200) if max_lag is None else max_lag
    r = autocorrelation(e, max_lag)
    lags = np.arange(max_lag + 1) * ts * 1e3
    ax.plot(lags, r, lw=1.0, marker=".", ms=2, label=label or "w_M - w_M,sim")
    band = 1.96 / math.sqrt(n)
    ax.axhspan(-band, band, color="0.5", alpha=0.15,
               label="white noise: 95 % within\n±1.96/sqrt(N)" if first else None)
    ax.axhline(band, color="0.4", ls="--", lw=0.8)
    ax.axhline(-band, color="0.4", ls="--", lw=0.8)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("lag [ms]")
    ax.set_ylabel("autocorrelation")
    what = "the motor-speed residual" if label is None else f"the residual {label}"
    ax.set_title(f"Autocorrelation of {what} (N = {n} samples)", fontsize="medium")
    legend_outside(ax)
    ax.grid(alpha=0.3)
    return fig
