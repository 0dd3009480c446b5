"""Plots of simulation results (and, later, identification reports).

Every plot function takes ``ax=`` and returns the figure; none calls ``plt.show()``
or changes matplotlib's global state (figures are created with
:class:`matplotlib.figure.Figure`, not through ``pyplot``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from .errors import InputError

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure

    from .simulate import DriveResponse

__all__ = ["plot_drive_response"]


def _axes(ax, n: int):
    if ax is None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(8, 2.4 * n), layout="constrained")
        return fig, list(fig.subplots(n, 1, sharex=True))
    axes = list(ax) if isinstance(ax, Sequence) else [ax]
    if len(axes) != n:
        raise InputError(f"ax must be a sequence of {n} Axes, got {len(axes)}")
    return axes[0].figure, axes


def plot_drive_response(
    response: DriveResponse, *, ax: Sequence[matplotlib.axes.Axes] | None = None
) -> matplotlib.figure.Figure:
    """Plot speeds, twists (with the gap) and shaft torques against time.

    Contact changes are marked by thin vertical lines on the twist axes.

    Parameters
    ----------
    response : DriveResponse
        A simulation result.
    ax : sequence of three matplotlib Axes, optional
        Axes for speeds, twists and shaft torques; new ones when omitted.

    Returns
    -------
    matplotlib.figure.Figure
        The figure holding the axes.
    """
    fig, (ax_w, ax_phi, ax_t) = _axes(ax, 3)
    t = response.t
    n = response.n_inertias
    names = ["motor", "load"] if n == 2 else [f"inertia {i + 1}" for i in range(n)]
    for i in range(n):
        ax_w.plot(t, response.speeds[:, i], label=names[i], lw=1)
    ax_w.set_ylabel("speed [rad/s]")
    ax_w.legend(loc="best", fontsize="small")
    for j in range(n - 1):
        line = ax_phi.plot(t, response.twists[:, j], lw=1, label=f"shaft {j + 1}")[0]
        th = response.drive.theta[j]
        for sign in (1, -1):
            ax_phi.axhline(sign * th, color=line.get_color(), ls="--", lw=0.7)
        ax_t.plot(t, response.shaft_torques[:, j], lw=1, color=line.get_color())
    for ev in response.events:
        ax_phi.axvline(ev.time, color="0.8", lw=0.5, zorder=0)
    ax_phi.set_ylabel("twist [rad]\n(dashed: ±theta)")
    ax_t.set_ylabel("shaft torque [N m]")
    ax_t.set_xlabel("time [s]")
    ax_w.set_title(
        f"drive response ({response.law.value} law, {len(response.events)} contact changes)"
    )
    return fig
