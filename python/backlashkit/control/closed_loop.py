"""Continuous-time closed loop of paper B: known plant, unknown input backlash,
model-reference controller (3.2), adaptive inverse (2.7)/(2.8) and adaptive law (3.11).

How the numerics handle the jumps of the inverse: fixed-step RK4 on the continuous
states with the side of the inverse (``chi_r``) as a discrete mode, switched at the
zero crossings of ``du_d/dt`` located inside the step by regula falsi (to 1e-12 of
the step); ``v`` jumps at the located instant and the backlash (play operator) sees
the value before and after the jump. See :mod:`backlashkit._numpy_control` for the
details; the compiled kernel (``crates/core/src/control.rs``) is the same algorithm.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import validate as _v
from ..errors import InputError
from ..lti import as_state_space
from ..nonlinearities import (
    Backlash,
    ExactInverse,
    GainOnlyInverse,
    InverseKind,
)
from .adaptive import AdaptiveLaw
from .design import MRCDesign, companion, design_mrc

if TYPE_CHECKING:
    import matplotlib.axes
    import matplotlib.figure

__all__ = [
    "ClosedLoopResponse",
    "SumOfSines",
    "TableReference",
    "simulate_closed_loop",
    "write_trace",
]

TRACE_COLUMNS = ("t", "r", "y", "y_m", "e", "u_d", "v", "u", "mc_r_hat", "m_hat", "mc_l_hat")


@dataclass(frozen=True)
class SumOfSines:
    """Reference ``r(t) = sum_i amplitude_i sin(frequency_i t + phase_i)``.

    Parameters
    ----------
    amplitude : sequence of float
        Amplitudes (units of the plant output's reference).
    frequency : sequence of float
        Angular frequencies in rad/s.
    phase : sequence of float, optional
        Phases in rad (default zeros).
    """

    amplitude: Sequence[float]
    frequency: Sequence[float]
    phase: Sequence[float] | None = None

    def __post_init__(self) -> None:
        a = _v.finite_array("amplitude", np.atleast_1d(np.asarray(self.amplitude, dtype=float)))
        w = _v.finite_array("frequency", np.atleast_1d(np.asarray(self.frequency, dtype=float)))
        if a.size != w.size or a.size == 0:
            raise InputError(
                f"amplitude and frequency must be non-empty lists of equal length, got "
                f"{a.size} and {w.size}"
            )
        ph = (
            np.zeros_like(a)
            if self.phase is None
            else _v.finite_array("phase", np.atleast_1d(np.asarray(self.phase, dtype=float)))
        )
        if ph.size != a.size:
            raise InputError(f"phase must have {a.size} values, got {ph.size}")
        object.__setattr__(self, "amplitude", a)
        object.__setattr__(self, "frequency", w)
        object.__setattr__(self, "phase", ph)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Evaluate ``r`` at times ``t`` (s).

        Parameters
        ----------
        t : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            ``r(t)``.
        """
        t = np.asarray(t, dtype=float)
        return np.sum(
            self.amplitude * np.sin(np.multiply.outer(t, self.frequency) + self.phase), axis=-1
        )

    def derivative(self, t: np.ndarray) -> np.ndarray:
        """Evaluate ``dr/dt`` at times ``t``.

        Parameters
        ----------
        t : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            ``dr/dt``.
        """
        t = np.asarray(t, dtype=float)
        return np.sum(
            self.amplitude
            * self.frequency
            * np.cos(np.multiply.outer(t, self.frequency) + self.phase),
            axis=-1,
        )


@dataclass(frozen=True)
class TableReference:
    """Reference given as a table, linearly interpolated (held at the ends).

    Parameters
    ----------
    t : sequence of float
        Strictly increasing times in s.
    r : sequence of float
        Reference values.
    """

    t: Sequence[float]
    r: Sequence[float]

    def __post_init__(self) -> None:
        tt = _v.finite_array("reference t", self.t)
        rr = _v.finite_array("reference r", self.r)
        if tt.size < 2 or tt.size != rr.size:
            raise InputError(
                "reference table needs >= 2 rows and equal-length t and r, "
                f"got {tt.size} and {rr.size}"
            )
        if not (np.diff(tt) > 0).all():
            raise InputError("reference t must be strictly increasing")
        object.__setattr__(self, "t", tt)
        object.__setattr__(self, "r", rr)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Evaluate ``r`` at times ``t`` (s).

        Parameters
        ----------
        t : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            Interpolated reference.
        """
        return np.interp(t, self.t, self.r)

    def derivative(self, t: np.ndarray) -> np.ndarray:
        """Slope of the interpolant at times ``t`` (0 outside the table).

        Parameters
        ----------
        t : array_like
            Times in s.

        Returns
        -------
        numpy.ndarray
            ``dr/dt``.
        """
        t = np.asarray(t, dtype=float)
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, self.t.size - 2)
        s = np.diff(self.r) / np.diff(self.t)
        out = s[i]
        return np.where((t < self.t[0]) | (t >= self.t[-1]), 0.0, out)


Reference = SumOfSines | TableReference


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
        t0 = self.t[0] + (1.0 - fraction) * (self.t[-1] - self.t[0])
        return self.e[self.t >= t0 - 1e-12]

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
        """The keys of ``backlashkit control --json``.

        Returns
        -------
        dict
            ``controller``, ``inverse``, ``theta_b_final``, ``rms_error_last``,
            ``max_abs_error_last``, ``n_switches``, ``step``.
        """
        return {
            "controller": self.design.as_dict(),
            "inverse": self.inverse.name,
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

    def plot(self, ax: matplotlib.axes.Axes | None = None) -> matplotlib.figure.Figure:
        """Plot the run as paper B's Figs. 5/6 do.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            If given, only ``y`` and ``y_m`` are drawn into it. Otherwise a new figure
            with five panels (``y`` and ``y_m``; ``e``; ``v``; ``u``; the estimates).

        Returns
        -------
        matplotlib.figure.Figure
            The figure.
        """
        from matplotlib.figure import Figure

        if ax is not None:
            ax.plot(self.t, self.y, label="y")
            ax.plot(self.t, self.y_m, "--", label="y_m")
            ax.set_xlabel("t [s]")
            ax.legend(loc="best")
            return ax.figure
        fig = Figure(figsize=(8, 10), layout="constrained")
        axs = fig.subplots(5, 1, sharex=True)
        axs[0].plot(self.t, self.y, label="y")
        axs[0].plot(self.t, self.y_m, "--", label="y_m")
        axs[0].legend(loc="upper right")
        axs[1].plot(self.t, self.e)
        axs[1].set_ylabel("e = y - y_m")
        axs[2].plot(self.t, self.v)
        axs[2].set_ylabel("v")
        axs[3].plot(self.t, self.u)
        axs[3].set_ylabel("u = B(v)")
        for i, lab in enumerate(("mc_r hat", "m hat", "mc_l hat")):
            axs[4].plot(self.t, self.theta_b[:, i], label=lab)
        axs[4].legend(loc="upper right")
        axs[4].set_xlabel("t [s]")
        axs[0].set_title(f"adaptive backlash-inverse control, inverse: {self.inverse.name}")
        return fig


def _reference_arrays(reference: Any) -> dict[str, np.ndarray]:
    empty = np.zeros(0)
    if isinstance(reference, SumOfSines):
        return {
            "amps": np.asarray(reference.amplitude),
            "freqs": np.asarray(reference.frequency),
            "phases": np.asarray(reference.phase),
            "table_t": empty,
            "table_r": empty,
        }
    if isinstance(reference, TableReference):
        return {
            "amps": empty,
            "freqs": empty,
            "phases": empty,
            "table_t": np.asarray(reference.t),
            "table_r": np.asarray(reference.r),
        }
    raise InputError(
        f"reference must be a SumOfSines or a TableReference, got {type(reference).__name__}"
    )


def build_problem(
    plant: Any,
    backlash: Backlash,
    *,
    inverse: InverseKind,
    adaptation: AdaptiveLaw,
    reference: Any,
    duration: float,
    ts: float,
    step: float | None,
    design: MRCDesign,
    output_noise: Callable[[np.ndarray], np.ndarray] | None = None,
    input_disturbance: Callable[[np.ndarray], np.ndarray] | None = None,
    initial_state: np.ndarray | None = None,
) -> dict[str, Any]:
    """Pack a closed-loop problem for the kernels (see :func:`simulate_closed_loop`).

    Parameters
    ----------
    plant, backlash, inverse, adaptation, reference, duration, ts, step, design,
    output_noise, input_disturbance, initial_state
        As in :func:`simulate_closed_loop`.

    Returns
    -------
    dict
        Arrays and scalars read by ``_numpy_control.simulate_adaptive`` and the
        compiled ``simulate_adaptive``.
    """
    duration = _v.positive("duration", duration)
    ts = _v.positive("ts", ts)
    if ts > duration:
        raise InputError(f"ts must be <= duration ({duration!r} s), got {ts!r}")
    h_max = min(ts, 1e-3) if step is None else _v.positive("step", step)
    n_sub = max(1, int(np.ceil(ts / h_max - 1e-9)))
    h = ts / n_sub
    n_out = int(np.floor(duration / ts + 1e-9))
    n_steps = n_out * n_sub
    ap, bp, cp, dp = as_state_space(plant)
    if dp != 0.0:
        raise InputError("plant must be strictly proper (no direct feedthrough)")
    xp0 = (
        np.zeros(ap.shape[0])
        if initial_state is None
        else _v.finite_array("initial_state", initial_state)
    )
    if xp0.size != ap.shape[0]:
        raise InputError(f"initial_state must have {ap.shape[0]} entries, got {xp0.size}")
    al, bl, _ = companion(np.array([1.0]), design.filter)
    am, bm, cm = companion(np.array([1.0]), design.reference_model)
    ah, bh, ch = companion(design.h_num, design.h_den)
    gamma = adaptation.gamma_diag
    thb0 = adaptation.theta_b0_array
    if isinstance(inverse, GainOnlyInverse):
        gamma = gamma * np.array([0.0, 1.0, 0.0])
        thb0 = np.array([0.0, thb0[1], 0.0])
    t_grid = np.arange(n_steps + 1) * h
    noise = (
        np.zeros(0)
        if output_noise is None
        else _v.finite_array(
            "output_noise(t)", np.broadcast_to(output_noise(t_grid), t_grid.shape)
        )
    )
    dist = (
        np.zeros(0)
        if input_disturbance is None
        else _v.finite_array(
            "input_disturbance(t)", np.broadcast_to(input_disturbance(t_grid), t_grid.shape)
        )
    )
    p1, p2 = inverse.params()
    prob = {
        "ap": ap,
        "bp": bp,
        "cp": cp,
        "xp0": xp0,
        "m": backlash.m,
        "c_r": backlash.c_r,
        "c_l": backlash.c_l,
        "u0": 0.0,
        "al": al,
        "bl": bl,
        "th1": design.theta_1.copy(),
        "th2": design.theta_2.copy(),
        "th3": design.theta_3,
        "am": am,
        "bm": bm,
        "cm": cm,
        "ah": ah,
        "bh": bh,
        "ch": ch,
        "gamma": gamma,
        "sigma": adaptation.sigma,
        "sigma_bound": adaptation.sigma_bound,
        "m0": adaptation.m0,
        "thb0": thb0,
        "kind": inverse.code,
        "p1": p1,
        "p2": p2,
        "h": h,
        "n_steps": n_steps,
        "n_sub": n_sub,
        "noise": noise,
        "dist": dist,
    }
    prob.update(_reference_arrays(reference))
    return {
        k: (np.ascontiguousarray(v, dtype=float) if isinstance(v, np.ndarray) else v)
        for k, v in prob.items()
    }


def run_problem(prob: dict[str, Any], *, backend: str = "rust") -> dict[str, np.ndarray]:
    """Run a packed problem on a backend.

    Parameters
    ----------
    prob : dict
        From :func:`build_problem`.
    backend : {"rust", "numpy"}
        Compiled kernel or NumPy reference.

    Returns
    -------
    dict
        Raw output arrays (``t, r, y, ym, ud, v, u, thb, n_switches``).
    """
    if backend == "numpy":
        from .._numpy_control import simulate_adaptive

        return simulate_adaptive(prob)
    if backend != "rust":
        raise InputError(f"backend must be 'rust' or 'numpy', got {backend!r}")
    from .. import _core

    ints = {"kind", "n_steps", "n_sub"}
    mats = {"ap", "al", "am", "ah"}
    args = {}
    for k, v in prob.items():
        if k in ints:
            args[k] = int(v)
        elif k in mats:
            args[k] = np.ascontiguousarray(v, dtype=float)
        elif isinstance(v, np.ndarray):
            args[k] = np.ascontiguousarray(v, dtype=float).ravel()
        else:
            args[k] = float(v)
    try:
        raw = _core.simulate_adaptive(args)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    out = {k: np.asarray(v) for k, v in raw.items()}
    out["thb"] = out["thb"].reshape(-1, 3)
    out["xp"] = out["xp"].reshape(out["thb"].shape[0], -1)
    return out


def simulate_closed_loop(
    plant: Any,
    backlash: Backlash,
    *,
    reference: Any,
    duration: float,
    ts: float = 0.01,
    inverse: InverseKind | None = None,
    adaptation: AdaptiveLaw | None = None,
    reference_model: Any = None,
    filter: Any = None,  # noqa: A002 - the paper's name
    step: float | None = None,
    output_noise: Callable[[np.ndarray], np.ndarray] | None = None,
    input_disturbance: Callable[[np.ndarray], np.ndarray] | None = None,
    initial_state: np.ndarray | None = None,
    backend: str = "rust",
) -> ClosedLoopResponse:
    """Simulate paper B's adaptive backlash-inverse control loop.

    Parameters
    ----------
    plant : tuple or python-control or scipy.signal LTI object
        Known linear part ``G(s)`` (must meet A1-A2, see :func:`design_mrc`).
    backlash : Backlash
        The true (unknown to the controller) backlash at the plant input.
    reference : SumOfSines or TableReference
        Reference ``r(t)``.
    duration : float
        Length of the run in s.
    ts : float
        Sample time of the returned trace in s (default 0.01).
    inverse : InverseKind, optional
        :class:`ExactInverse` (default), :class:`SmoothFilterInverse`,
        :class:`SmoothRampInverse`, :class:`NoInverse` or :class:`GainOnlyInverse`.
    adaptation : AdaptiveLaw, optional
        Gains and initial estimate; default paper B's ``Gamma = 5 I``,
        ``theta_b(0) = (1.51, 0.2, -0.55)``.
    reference_model, filter : array_like, optional
        ``R_m(s)`` and ``Lambda(s)`` (see :func:`design_mrc`).
    step : float, optional
        Largest integration step in s (default ``min(ts, 1e-3)``); the step actually
        used divides ``ts``.
    output_noise : callable, optional
        ``n(t)`` added to the measured output (``t`` is the array of integration grid
        instants; the value is held over each step).
    input_disturbance : callable, optional
        ``d(t)`` added to the backlash output before the plant, held over each step.
    initial_state : array_like, optional
        Plant state at ``t = 0`` (in the realisation of :func:`as_state_space`).
    backend : {"rust", "numpy"}
        Compiled kernel (default) or the NumPy reference.

    Returns
    -------
    ClosedLoopResponse
        The trace at ``ts``.
    """
    if not isinstance(backlash, Backlash):
        raise InputError(f"backlash must be a Backlash, got {type(backlash).__name__}")
    inverse = ExactInverse() if inverse is None else inverse
    if not isinstance(inverse, InverseKind):
        raise InputError(f"inverse must be an InverseKind object, got {type(inverse).__name__}")
    adaptation = AdaptiveLaw() if adaptation is None else adaptation
    design = design_mrc(plant, reference_model=reference_model, filter=filter)
    prob = build_problem(
        plant,
        backlash,
        inverse=inverse,
        adaptation=adaptation,
        reference=reference,
        duration=duration,
        ts=ts,
        step=step,
        design=design,
        output_noise=output_noise,
        input_disturbance=input_disturbance,
        initial_state=initial_state,
    )
    raw = run_problem(prob, backend=backend)
    return ClosedLoopResponse(
        t=raw["t"],
        r=raw["r"],
        y=raw["y"],
        y_m=raw["ym"],
        e=raw["y"] - raw["ym"],
        u_d=raw["ud"],
        v=raw["v"],
        u=raw["u"],
        theta_b=raw["thb"],
        design=design,
        inverse=inverse,
        n_switches=int(raw["n_switches"]),
        step=float(prob["h"]),
        plant_state=raw["xp"],
    )


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
