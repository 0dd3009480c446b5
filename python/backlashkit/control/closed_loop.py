"""Continuous-time closed loop of paper B: known plant, unknown input backlash,
model-reference controller (3.2), adaptive inverse (2.7)/(2.8) and adaptive law (3.11).

How the numerics handle the jumps of the inverse: fixed-step RK4 on the continuous
states with the side of the inverse (``chi_r``) as a discrete mode, switched at the
zero crossings of ``du_d/dt`` located inside the step by regula falsi (to 1e-12 of
the step); ``v`` jumps at the located instant and the backlash (play operator) sees
the value before and after the jump. See :mod:`backlashkit._numpy_control` for the
details; the compiled kernel (``crates/core/src/control.rs``) is the same algorithm.

:func:`simulate_closed_loop` is the public face; the pieces it joins live beside it:
the references in :mod:`~backlashkit.control.references`, the packing of a problem for
the kernels in :mod:`~backlashkit.control.problem` and the result in
:mod:`~backlashkit.control.response` (all importable from here as before).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import InputError
from ..nonlinearities import Backlash, ExactInverse, InverseKind, inverse_kind_error
from .adaptive import AdaptiveLaw
from .design import design_mrc
from .problem import build_problem, run_problem
from .references import Reference, SumOfSines, TableReference
from .response import TRACE_COLUMNS, ClosedLoopResponse, write_trace

__all__ = [
    "TRACE_COLUMNS",
    "ClosedLoopResponse",
    "Reference",
    "SumOfSines",
    "TableReference",
    "build_problem",
    "run_problem",
    "simulate_closed_loop",
    "write_trace",
]


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
        raise inverse_kind_error(inverse)
    adaptation = AdaptiveLaw() if adaptation is None else adaptation
    if not isinstance(adaptation, AdaptiveLaw):
        raise InputError(f"adaptation must be an AdaptiveLaw, got {type(adaptation).__name__}")
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
