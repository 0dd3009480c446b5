"""Plots of simulation results, and the legend placement every plot shares.

Every plot function takes ``ax=`` and returns the figure; none calls ``plt.show()``
or changes matplotlib's global state (figures are created with
:class:`matplotlib.figure.Figure`, not through ``pyplot``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from .errors import InputError

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure

    from .simulate import DriveResponse

__all__ = ["axes_of", "legend_outside", "plot_drive_response"]


def legend_outside(ax: matplotlib.axes.Axes, **kwargs) -> None:
    """Put the legend of ``ax`` to the right of its axes, where it covers no data.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Axes with labelled artists (nothing is drawn when none is labelled).
    **kwargs
        Passed to :meth:`matplotlib.axes.Axes.legend` (e.g. ``handles``, ``title``).
    """
    handles = kwargs.pop("handles", None)
    if handles is None and not ax.get_legend_handles_labels()[0]:
        return
    kwargs.setdefault("fontsize", "small")
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0),
              borderaxespad=0.0, **kwargs)


def axes_of(ax, n: int, *, figsize: tuple[float, float] | None = None, columns: int = 1):
    """The figure and the ``n`` axes a plot function draws on.

    Parameters
    ----------
    ax : matplotlib Axes, sequence or array of them, or None
        The caller's axes (what ``plt.subplots`` returns serves as it is), or None for a
        new figure, not registered with pyplot.
    n : int
        Axes the plot needs.
    figsize : tuple of float, optional
        Size of a new figure in inches (default 9 wide, 2.4 high per row).
    columns : int, optional
        Columns of a new figure's grid (default 1: the axes one above the other,
        sharing x).

    Returns
    -------
    tuple
        ``(figure, list of Axes)``.

    Raises
    ------
    InputError
        If ``ax`` does not hold ``n`` Axes.
    """
    if ax is None:
        from matplotlib.figure import Figure

        rows = -(-n // columns)
        fig = Figure(figsize=figsize or (9, 2.4 * rows), layout="constrained")
        grid = fig.subplots(rows, columns, sharex=columns == 1, squeeze=False)
        return fig, list(grid.ravel()[:n])
    axes = (list(np.ravel(np.asarray(ax, dtype=object)))
            if isinstance(ax, (Sequence, np.ndarray)) else [ax])
    if len(axes) != n:
        raise InputError(f"ax must be {n} Axes (a sequence or an array of them, as "
                         f"plt.subplots returns), got {len(axes)}")
    for a in axes:  # duck-typed: matplotlib is imported only to draw
        if not (hasattr(a, "plot") and hasattr(a, "figure")):
            raise InputError(f"ax must be matplotlib Axes, got {type(a).__name__}")
    return axes[0].figure, axes


def plot_drive_response(
    response: DriveResponse, *, ax: Sequence[matplotlib.axes.Axes] | None = None,
    measured: Sequence[np.ndarray] | None = None,
) -> matplotlib.figure.Figure:
    """Plot speeds, torques (applied and in the shafts) and twists against time.

    The applied motor torque is drawn under the speeds, with the shaft torques; the
    twist panel marks the gap's edges ``±theta`` (dashed) and every contact change (a
    thin grey line; where contacts chatter the lines merge into a grey band). Legends
    sit to the right of the axes.

    Parameters
    ----------
    response : DriveResponse
        A simulation result.
    ax : sequence of three matplotlib Axes, optional
        Axes for the speeds, the torques and the twists; new ones when omitted.
    measured : sequence of numpy.ndarray, optional
        The speeds as measured (noisy, or an encoder's), one per inertia in rad/s:
        drawn faintly behind the simulated ones, which are then labelled noise-free.

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding the axes.
    """
    from matplotlib.lines import Line2D

    t = response.t
    n = response.n_inertias
    if measured is not None and (np.ndim(measured[0]) != 1 or len(measured) != n or any(
            np.shape(w) != t.shape for w in measured)):
        got = (f"one array of shape {np.shape(measured)}" if np.ndim(measured[0]) != 1
               else f"{len(measured)} of shapes {[np.shape(w) for w in measured]}")
        raise InputError(
            f"measured must hold {n} speed arrays, one per inertia, each of {t.size} "
            f"samples like the response's t, got {got}")
    fig, (ax_w, ax_t, ax_phi) = axes_of(ax, 3)
    names = ["motor", "load"] if n == 2 else [f"inertia {i + 1}" for i in range(n)]
    for i in range(n):
        line = ax_w.plot(t, response.speeds[:, i], lw=1, zorder=3,
                         label=names[i] if measured is None else f"{names[i]} (noise-free)")[0]
        if measured is not None:
            ax_w.plot(t, measured[i], lw=0.5, alpha=0.45, color=line.get_color(), zorder=2,
                      label=f"{names[i]} as measured")
    ax_w.set_ylabel("speed [rad/s]")
    ax_t.plot(t, response.torque, color="k", lw=1.2, drawstyle="steps-post", zorder=3,
              label="applied (motor)")
    if response.loop_torque is not None:
        ax_t.plot(t, response.loop_torque, color="0.45", lw=1, ls="--",
                  label="delivered by the current loop")
    for j in range(n - 1):
        shaft = "shaft" if n == 2 else f"shaft {j + 1}"
        line = ax_phi.plot(t, response.twists[:, j], lw=1, label=f"{shaft} twist")[0]
        th = response.drive.theta[j]
        for sign in (1, -1):
            ax_phi.axhline(sign * th, color=line.get_color(), ls="--", lw=0.7)
        ax_t.plot(t, response.shaft_torques[:, j], lw=1, color=line.get_color(),
                  label=f"{shaft} torque")
    contacts = response.contact_events
    for ev in contacts:
        ax_phi.axvline(ev.time, color="0.8", lw=0.5, zorder=0)
    twists = ax_phi.get_legend_handles_labels()[0]
    handles = twists + [
        Line2D([], [], color=twists[0].get_color() if n == 2 else "0.3", ls="--", lw=0.7,
               label="gap edges ±theta"),
        Line2D([], [], color="0.8", lw=4, label="contact changes"),
    ]
    ax_t.set_ylabel("torque [N m]")
    ax_phi.set_ylabel("twist [rad]")
    ax_phi.set_xlabel("time [s]")
    for a in (ax_w, ax_t):
        legend_outside(a)
    legend_outside(ax_phi, handles=handles)
    ax_w.set_title(f"Simulated drive: speeds, torques and shaft twist "
                   f"({len(contacts)} contact changes)")
    return fig
