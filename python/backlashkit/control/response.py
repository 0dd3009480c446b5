"""The trace of a closed-loop run: :class:`ClosedLoopResponse` and its CSV form."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import validate as v
from ..errors import InputError
from .design import MRCDesign

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure

    from ..nonlinearities import InverseKind

__all__ = ["TRACE_COLUMNS", "ClosedLoopResponse", "write_trace"]

TRACE_COLUMNS = ("t", "r", "y", "y_m", "e", "u_d", "v", "u", "mc_r_hat", "m_hat", "mc_l_hat")
#: Slack in s on the start of an error window: the sample on it counts despite the
#: rounding of the start time.
_WINDOW_SLACK = 1e-12


@dataclass
class ClosedLoopResponse:
    """Trace of a closed-loop run (one row per output sample).

    Attributes
    ----------
    t, r, y, y_m, e, u_d, v, u : numpy.ndarray
        Time (s), reference, plant output, reference-model output, tracking error
        ``y - y_m``, desired control, backlash input, backlash output (for the ``v`` of
        the same row; includes any input disturbance).
    theta_b : numpy.ndarray, shape (N, 3)
        Estimates ``(mc_r, m, mc_l)``.
    design : MRCDesign
        The linear controller.
    inverse : InverseKind
        The inverse used.
    n_switches : int
        Number of located switches of the inverse's side.
    step : float
        Integration step in s.
    plant_state : numpy.ndarray or None, shape (N, n)
        State of the plant (realisation of :func:`backlashkit.lti.as_state_space`).
    """

    t: np.ndarray
    r: np.ndarray
    y: np.ndarray
    y_m: np.ndarray
    e: np.ndarray
    u_d: np.ndarray
    v: np.ndarray
    u: np.ndarray
    theta_b: np.ndarray
    design: MRCDesign
    inverse: InverseKind
    n_switches: int = 0
    step: float = 0.0
    plant_state: np.ndarray | None = None

    def _last(self, fraction: float) -> np.ndarray:
        fraction = v.finite_scalar("fraction", fraction)
        if not 0.0 < fraction <= 1.0:
            raise InputError(f"fraction must be in (0, 1] (a part of the run, from its end), "
                             f"got {fraction!r}")
        t0 = self.t[0] + (1.0 - fraction) * (self.t[-1] - self.t[0])
        return self.e[self.t >= t0 - _WINDOW_SLACK]

    def __repr__(self) -> str:
        # the dataclass's would print every array
        return (f"ClosedLoopResponse({self.t.size} samples, t = {self.t[0]:g} to "
                f"{self.t[-1]:g} s, inverse {self.inverse!r}, RMS tracking error over the "
                f"last third {self.rms_error_last():.3g})")

    def rms_error_last(self, fraction: float = 1.0 / 3.0) -> float:
        """RMS of ``e`` over the last ``fraction`` of the run.

        Parameters
        ----------
        fraction : float
            Part of the run, from the end (default one third).

        Returns
        -------
        float
            ``sqrt(mean(e^2))`` over that window.
        """
        e = self._last(fraction)
        return float(np.sqrt(np.mean(e * e)))

    def max_abs_error_last(self, fraction: float = 1.0 / 3.0) -> float:
        """Largest ``|e|`` over the last ``fraction`` of the run.

        Parameters
        ----------
        fraction : float
            Part of the run, from the end (default one third).

        Returns
        -------
        float
            ``max |e|`` over that window.
        """
        return float(np.max(np.abs(self._last(fraction))))

    def summary(self) -> dict[str, Any]:
        """The keys of ``backlashkit control --json`` that the run itself gives (the
        command adds ``delay_margin``, the linear loop's).

        Returns
        -------
        dict
            ``controller``, ``inverse``, ``inverse_parameters`` (``alpha`` of the smooth
            filter, ``beta_r`` and ``beta_l`` of the ramps, none otherwise),
            ``theta_b_final``, ``rms_error_last``, ``max_abs_error_last``,
            ``n_switches``, ``step``.
        """
        return {
            "controller": self.design.as_dict(),
            "inverse": self.inverse.name,
            "inverse_parameters": {f.name: float(getattr(self.inverse, f.name))
                                   for f in fields(self.inverse)},
            "theta_b_final": [float(x) for x in self.theta_b[-1]],
            "rms_error_last": self.rms_error_last(),
            "max_abs_error_last": self.max_abs_error_last(),
            "n_switches": int(self.n_switches),
            "step": float(self.step),
        }

    def table(self) -> np.ndarray:
        """The trace as a 2-D array with the columns of :data:`TRACE_COLUMNS`.

        Returns
        -------
        numpy.ndarray, shape (N, 11)
            ``t, r, y, y_m, e, u_d, v, u, mc_r_hat, m_hat, mc_l_hat``.
        """
        return np.column_stack(
            [self.t, self.r, self.y, self.y_m, self.e, self.u_d, self.v, self.u, self.theta_b]
        )

    def plot(self, ax: matplotlib.axes.Axes | Sequence[matplotlib.axes.Axes] | None = None
             ) -> matplotlib.figure.Figure:
        """Plot the run as paper B's Figs. 5/6 do.

        Parameters
        ----------
        ax : matplotlib Axes, or a sequence or array of five, optional
            One Axes: only ``y`` and ``y_m`` are drawn into it. Five (what
            ``plt.subplots(5, 1)[1]`` returns): the five panels, ``y`` and ``y_m``;
            ``e``; ``v``; ``u``; the estimates. None: those five in a new figure that
            pyplot does not manage.

        Returns
        -------
        matplotlib.figure.Figure
            The figure.
        """
        from ..report import axes_of, legend_outside

        if ax is not None and np.size(np.asarray(ax, dtype=object)) == 1:
            # one Axes (or an array of one): the outputs alone
            _, (ax,) = axes_of(ax, 1)
            ax.plot(self.t, self.y, label="y")
            ax.plot(self.t, self.y_m, "--", label="y_m")
            ax.set_xlabel("t [s]")
            legend_outside(ax)
            return ax.figure
        fig, axs = axes_of(ax, 5, figsize=(8, 10))
        axs[0].plot(self.t, self.y, label="y, plant output")
        axs[0].plot(self.t, self.y_m, "--", label="y_m, reference model")
        axs[0].set_ylabel("output")
        legend_outside(axs[0])
        axs[1].plot(self.t, self.e)
        axs[1].set_ylabel("error e = y - y_m")
        axs[2].plot(self.t, self.v)
        axs[2].set_ylabel("v, backlash input")
        axs[3].plot(self.t, self.u)
        axs[3].set_ylabel("u = B(v),\nbacklash output")
        for i, lab in enumerate(("mc_r hat", "m hat", "mc_l hat")):
            axs[4].plot(self.t, self.theta_b[:, i], label=lab)
        axs[4].set_ylabel("backlash estimates")
        legend_outside(axs[4])
        axs[4].set_xlabel("t [s]")
        axs[0].set_title(f"Adaptive backlash-inverse control, inverse: {self.inverse.name}")
        return fig


def write_trace(path: str | os.PathLike[str], response: ClosedLoopResponse) -> None:
    """Write a closed-loop trace as CSV, one row per sample, columns :data:`TRACE_COLUMNS`.

    Parameters
    ----------
    path : str or os.PathLike
        Output file (overwritten).
    response : ClosedLoopResponse
        The run.
    """
    np.savetxt(path, response.table(), delimiter=",", header=",".join(TRACE_COLUMNS),
               comments="", fmt="%.10g")
