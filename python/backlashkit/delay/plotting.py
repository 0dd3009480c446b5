"""Figure of a :class:`~backlashkit.delay.DelayMarginResult` (no global matplotlib state)."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.ticker import LogFormatter

from ..report import axes_of
from .chen import SweepData, _grid, _track, frequency_bound, unit_circle_eigenvalues
from .spectral import default_nodes, spectral_scan

__all__ = ["plot_margin"]

#: Grid of the moduli panel when the result carries no sweep (Kronecker method).
N_OMEGA_PLOT = 300
#: Collocation degree of the plotted roots: this many, plus ``NODES_PER_UNIT`` per unit
#: of ``omega_max q h`` (``omega_max`` the largest crossing frequency, widened).
PLOT_MIN_NODES = 30
PLOT_NODES_PER_UNIT = 0.9
#: The rightmost root is drawn at this many more delays across this share of ``h_max``
#: about it: the default range runs to ten times ``h_max``, whose crossing its 60 even
#: steps would draw with a few points only.
NEAR_H_MAX = (0.8, 1.2)
N_NEAR_H_MAX = 9
#: The rightmost root's axis is linear within this share of its largest magnitude about
#: 0, logarithmic beyond.
SYMLOG_SHARE = 1e-3


def _rightmost(result, hs: np.ndarray) -> np.ndarray:
    """Rightmost real part at each delay; the collocation is sized for the crossing
    frequencies found (the roots that reach the axis), not the loose general bound, to
    keep a long delay range affordable."""
    system = result.system
    if not result.crossings:
        return spectral_scan(system, hs)
    wmax = max(c.omega for c in result.crossings)
    out = []
    for h in hs:
        nodes = min(default_nodes(system, h),
                    PLOT_MIN_NODES + math.ceil(PLOT_NODES_PER_UNIT * wmax * system.q * h))
        out.append(spectral_scan(system, [h], n_nodes=nodes)[0])
    return np.array(out)


def plot_margin(result, *, ax=None, h_range=(0.0, 1.0), n_h: int = 60):
    """Draw the two panels of :meth:`DelayMarginResult.plot`.

    Parameters
    ----------
    result : DelayMarginResult
    ax : sequence of two matplotlib Axes, optional
        Default: a new figure.
    h_range : (float, float)
        Delays of the second panel (s).
    n_h : int
        Delays evaluated.

    Returns
    -------
    matplotlib.figure.Figure
        The figure of the axes.
    """
    fig, (ax1, ax2) = axes_of(ax, 2, figsize=(10, 4), columns=2)
    system = result.system
    sweep = result.sweep
    if sweep is None and system.q:
        w = _grid(system, frequency_bound(system), N_OMEGA_PLOT)
        sweep = SweepData(w, _track(unit_circle_eigenvalues(system, w)))
    if sweep is not None:
        mod = sweep.moduli()
        mod = np.where(np.isfinite(mod), mod, np.nan)
        lines = ax1.semilogx(sweep.omega, mod, lw=1, color="C0")
        lines[0].set_label("moduli |z_i| (one line each)")
    ax1.axhline(1.0, color="k", ls="--", lw=0.8, label="unit circle")
    for k, c in enumerate(result.crossings):
        ax1.plot(c.omega, 1.0, "o", mfc="none", color="C3",
                 label="crossing" if k == 0 else None)
    ax1.set_yscale("log")
    # plain numbers (2, 3, 4), not 2 x 10^0, on the narrow ranges of the moduli
    ax1.yaxis.set_major_formatter(LogFormatter())
    ax1.yaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
    if sweep is not None:  # the log-spaced floor of the grid says nothing worth a decade each
        ax1.set_xlim(left=1e-3 * sweep.omega.max())
    ax1.set_xlabel("frequency omega (rad/s)")
    ax1.set_ylabel("|z_i(omega)|")
    ax1.set_title("generalized eigenvalues of the pencil")
    ax1.legend(loc="best")
    hs = np.linspace(*h_range, n_h + 1)
    if h_range[0] < result.h_max < h_range[1]:  # the crossing itself, drawn closely
        hs = np.union1d(hs, result.h_max * np.linspace(*NEAR_H_MAX, N_NEAR_H_MAX))
    re = _rightmost(result, hs)
    ax2.plot(hs, re, lw=1.2, label="rightmost root (spectral)")
    ax2.axhline(0.0, color="k", lw=0.8)
    # linear within a small band about 0, logarithmic beyond: a root just past the axis
    # stays visible beside the short delays' deeply stable ones
    ax2.set_yscale("symlog", linthresh=SYMLOG_SHARE * max(float(np.nanmax(np.abs(re))),
                                                          1e-300))
    if math.isfinite(result.h_max) and result.h_max > 0:
        ax2.axvline(result.h_max, color="C3", ls="--", lw=1,
                    label=f"h_max = {result.h_max:.6g} s")
    for k, (a, b) in enumerate(result.stability_windows(h_range)):
        ax2.axvspan(a, b, color="C2", alpha=0.12, label="stable" if k == 0 else None)
    ax2.set_xlabel("delay h (s)")
    ax2.set_ylabel("max Re s (1/s, symmetric log scale)")
    ax2.set_title("rightmost characteristic root")
    ax2.legend(loc="best")
    return fig
