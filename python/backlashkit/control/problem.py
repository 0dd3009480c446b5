"""A closed-loop problem packed for the kernels, and the run of it on a backend.

:func:`build_problem` turns the plant, the backlash, the controller and the signals
into the flat dict of arrays and scalars that both the NumPy reference
(:mod:`backlashkit._numpy_control`) and the compiled ``simulate_adaptive`` read;
:func:`run_problem` runs it on either.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .. import validate as v
from ..errors import InputError, Option
from ..lti import as_state_space
from ..nonlinearities import Backlash, InverseKind
from .adaptive import AdaptiveLaw
from .design import MRCDesign, companion

__all__ = ["DEFAULT_MAX_STEP", "MAX_ROWS", "MAX_STEPS", "ROUND_SLACK", "build_problem",
           "check_rows", "run_problem"]

#: Largest integration step in s when none is given: fine enough for paper B's
#: references and plants, whatever the output sample time.
DEFAULT_MAX_STEP = 1e-3
#: A ratio of times within this of a whole number counts as that number (``ts`` a
#: multiple of the step, ``duration`` a multiple of ``ts``, up to rounding).
ROUND_SLACK = 1e-9
#: Most output rows (``duration / ts``) a run may keep: 5e6 rows of the trace's 11
#: float64 columns take 440 MB.
MAX_ROWS = 5e6
#: Most integration steps (``duration / step``) a run may take: about 1 us each on
#: paper B's example (``benchmarks/bench_control.py``: 0.066 s for its 60 000 steps),
#: so some 20 s, and a signal given as a function is sampled on them (8 bytes a step:
#: 160 MB).
MAX_STEPS = 2e7
#: Where the classical Runge-Kutta method's stability region ends on the negative real
#: axis (``|1 + z + z^2/2 + z^3/6 + z^4/24| = 1`` at ``z = -2.7853``): a first-order
#: lag of rate ``a`` integrated with a step ``h`` diverges beyond ``a h`` of this
#: (``tests/test_qa_control_delay_fleet.py``: a smooth filter's ``alpha`` of 2 700 runs
#: at 1 ms; 2 900 diverged).
RK4_REAL_STABILITY = 2.785
#: A loop whose plant output exceeds this many times the reference's largest value
#: (or the output it starts from) has diverged: paper B's transients stay within tens
#: of it, and a sample time too long for an unstable plant grows the output to 1e44
#: and beyond while every value stays finite (a QA pass: a silent answer with an error
#: of 2.7e56).
RUNAWAY = 1e6
#: The integration step as the messages advise it (a scenario file words it as its
#: ``[simulation] step``).
STEP = Option("step", None)
#: Parameters of the kernels' compiled entry point that are integers, and matrices.
_KERNEL_INTS = {"kind", "n_steps", "n_sub"}
_KERNEL_MATRICES = {"ap", "al", "am", "ah"}


def _steps(duration: float, ts: float, step: float | None) -> tuple[float, int, int]:
    """Integration step ``h`` (a divisor of ``ts``), sub-steps per sample, total steps."""
    duration = v.positive("duration", duration)
    ts = v.positive("ts", ts)
    if ts > duration:
        raise InputError(f"ts must be <= duration ({duration!r} s), got {ts!r}")
    h_max = min(ts, DEFAULT_MAX_STEP) if step is None else v.positive("step", step)
    n_out = check_rows(duration, ts)
    if duration / h_max > MAX_STEPS * (1 + ROUND_SLACK):  # before any allocation
        which = "the default, min(ts, 1 ms)" if step is None else "given"
        raise InputError(
            f"duration / step gives {duration / h_max:.3g} integration steps (step "
            f"{h_max:.3g} s, {which}), more than {MAX_STEPS:,.0f}: give a larger ", STEP,
            " (at most ts) or a shorter ", Option("duration", None))
    n_sub = max(1, int(np.ceil(ts / h_max - ROUND_SLACK)))
    h = ts / n_sub
    return h, n_sub, n_out * n_sub


def check_rows(duration: float, ts: float) -> int:
    """The output samples after the first of a run of ``duration`` s at ``ts`` s.

    Parameters
    ----------
    duration : float
        Length of the run in s, a whole number of ``ts`` (to :data:`ROUND_SLACK`).
    ts : float
        Sample time in s.

    Returns
    -------
    int
        ``duration / ts``.

    Raises
    ------
    InputError
        If ``duration`` is not a whole number of ``ts`` (the run would stop short of
        it), or gives more than :data:`MAX_ROWS` samples.
    """
    ratio = duration / ts
    if ratio > MAX_ROWS:
        raise InputError(f"duration / ts gives {ratio:.3g} output samples, more than "
                         f"{MAX_ROWS:,.0f}: give a longer ts or a shorter duration")
    n_out = int(np.floor(ratio + ROUND_SLACK))
    if abs(ratio - round(ratio)) > ROUND_SLACK * max(ratio, 1.0):
        raise InputError(
            f"duration must be a whole number of ts = {ts!r} s (the run would stop at "
            f"{n_out * ts:.6g} s), got {duration!r}: give duration = {n_out * ts:.6g} or "
            f"{(n_out + 1) * ts:.6g}")
    return n_out


def _plant(plant: Any, initial_state: np.ndarray | None) -> dict[str, Any]:
    """The plant's realisation and initial state."""
    ap, bp, cp, dp = as_state_space(plant)
    if dp != 0.0:
        raise InputError("plant must be strictly proper (no direct feedthrough)")
    xp0 = (
        np.zeros(ap.shape[0])
        if initial_state is None
        else v.finite_array("initial_state", initial_state)
    )
    if xp0.size != ap.shape[0]:
        raise InputError(f"initial_state must have {ap.shape[0]} entries, got {xp0.size}")
    return {"ap": ap, "bp": bp, "cp": cp, "xp0": xp0}


def _controller(design: MRCDesign) -> dict[str, Any]:
    """The filter, reference model and ``h`` of the linear controller in companion form."""
    al, bl, _ = companion(np.array([1.0]), design.filter)
    am, bm, cm = companion(np.array([1.0]), design.reference_model)
    ah, bh, ch = companion(design.h_num, design.h_den)
    return {
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
    }


def _adaptation(adaptation: AdaptiveLaw, inverse: InverseKind) -> dict[str, Any]:
    """Gains and initial estimate of the adaptive law (only ``m`` adapts under a
    gain-only inverse)."""
    adapted = np.array(inverse.adapted)
    return {
        "gamma": adaptation.gamma_diag * adapted,
        "sigma": adaptation.sigma,
        "sigma_bound": adaptation.sigma_bound,
        "m0": adaptation.m0,
        "thb0": np.where(adapted > 0, adaptation.theta_b0_array, 0.0),
    }


def _sampled(name: str, signal: Callable[[np.ndarray], np.ndarray] | None,
             h: float, n_steps: int) -> np.ndarray:
    """``signal`` on the integration grid of ``n_steps`` steps of ``h`` (empty without
    one)."""
    if signal is None:
        return np.zeros(0)
    if not callable(signal):
        raise InputError(f"{name} must be a function of the time array t (s), e.g. "
                         f"lambda t: 0.01 * rng.standard_normal(t.shape), got {signal!r}")
    t_grid = np.arange(n_steps + 1) * h
    values = signal(t_grid)
    try:
        values = np.broadcast_to(values, t_grid.shape)
    except ValueError:
        raise InputError(f"{name}(t) must give one value per time of t (shape "
                         f"{t_grid.shape}) or one for all, got shape {np.shape(values)}") from None
    return v.finite_array(f"{name}(t)", values)


def _reference(reference: Any) -> dict[str, np.ndarray]:
    kernel_arrays = getattr(reference, "kernel_arrays", None)
    if kernel_arrays is None:
        raise InputError(
            f"reference must be a SumOfSines or a TableReference, got {type(reference).__name__}"
        )
    return kernel_arrays()


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
    """Pack a closed-loop problem for the kernels.

    The arguments are those of :func:`~backlashkit.control.simulate_closed_loop`, with
    the defaults resolved.

    Parameters
    ----------
    plant : tuple or python-control or scipy.signal LTI object
        Known linear part ``G(s)``, strictly proper.
    backlash : Backlash
        The true backlash at the plant input.
    inverse : InverseKind
        The backlash inverse of the controller.
    adaptation : AdaptiveLaw
        Gains and initial estimate of the adaptive law.
    reference : SumOfSines or TableReference
        Reference ``r(t)``.
    duration : float
        Length of the run in s.
    ts : float
        Sample time of the output in s.
    step : float or None
        Largest integration step in s (``None``: ``min(ts, DEFAULT_MAX_STEP)``).
    design : MRCDesign
        The linear controller.
    output_noise, input_disturbance : callable, optional
        ``n(t)`` and ``d(t)`` on the integration grid; default none.
    initial_state : array_like, optional
        Plant state at ``t = 0``; default zeros.

    Returns
    -------
    dict
        Arrays and scalars read by ``_numpy_control.simulate_adaptive`` and the
        compiled ``simulate_adaptive``.
    """
    h, n_sub, n_steps = _steps(duration, ts, step)
    if inverse.rate * h > RK4_REAL_STABILITY:
        raise InputError(
            f"{inverse!r} with the integration step {h:.3g} s: alpha * step = "
            f"{inverse.rate * h:.3g} is beyond the integration's stability (classical "
            f"Runge-Kutta, {RK4_REAL_STABILITY:g}); give ", STEP,
            f" <= {RK4_REAL_STABILITY / inverse.rate:.3g} s or a smaller ",
            Option("alpha", None))
    plant_arrays = _plant(plant, initial_state)
    controller = _controller(design)
    adaptive = _adaptation(adaptation, inverse)
    noise = _sampled("output_noise", output_noise, h, n_steps)
    dist = _sampled("input_disturbance", input_disturbance, h, n_steps)
    p1, p2 = inverse.params()
    prob = {
        **plant_arrays,
        "m": backlash.m,
        "c_r": backlash.c_r,
        "c_l": backlash.c_l,
        "u0": 0.0,
        **controller,
        **adaptive,
        "kind": inverse.code,
        "p1": p1,
        "p2": p2,
        "h": h,
        "n_steps": n_steps,
        "n_sub": n_sub,
        "noise": noise,
        "dist": dist,
    }
    prob.update(_reference(reference))
    reference.check_covers(duration)
    return {
        k: (np.ascontiguousarray(val, dtype=float) if isinstance(val, np.ndarray) else val)
        for k, val in prob.items()
    }


def _diverged_advice(message: str, h: float) -> tuple[str | Option, ...]:
    """The kernel's ``message``, with the integration step's part where it diverged: an
    explicit step far above a fast time constant diverges as wrong units would."""
    if not message.startswith("the simulation diverged"):
        return (message,)
    return (f"{message}, or give a smaller ", STEP, f" (now {h:.3g} s): a fast part (a "
            "plant pole, the filter, a smooth inverse's alpha) needs a step well under its "
            "time constant")


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

    Raises
    ------
    InputError
        If the run diverges: a non-finite value, or a plant output beyond
        :data:`RUNAWAY` times the reference's largest value (or its first output).
    """
    if backend == "numpy":
        from .._numpy_control import simulate_adaptive

        out = simulate_adaptive(prob)
        _check_runaway(out, prob["h"])
        return out
    if backend != "rust":
        raise InputError(f"backend must be 'rust' or 'numpy', got {backend!r}")
    from .. import _core

    args = {}
    for k, value in prob.items():
        if k in _KERNEL_INTS:
            args[k] = int(value)
        elif k in _KERNEL_MATRICES:
            args[k] = np.ascontiguousarray(value, dtype=float)
        elif isinstance(value, np.ndarray):
            args[k] = np.ascontiguousarray(value, dtype=float).ravel()
        else:
            args[k] = float(value)
    try:
        raw = _core.simulate_adaptive(args)
    except ValueError as exc:
        raise InputError(*_diverged_advice(str(exc), prob["h"])) from None
    out = {k: np.asarray(val) for k, val in raw.items()}
    out["thb"] = out["thb"].reshape(-1, 3)
    out["xp"] = out["xp"].reshape(out["thb"].shape[0], -1)
    _check_runaway(out, prob["h"])
    return out


def _check_runaway(out: dict[str, np.ndarray], h: float) -> None:
    """Refuse a run whose plant output grew past :data:`RUNAWAY` times the larger of
    the reference's largest value and the output it starts from, every value finite."""
    y = out["y"]
    scale = max(float(np.max(np.abs(out["r"]), initial=0.0)), abs(float(y[0])))
    beyond = np.flatnonzero(np.abs(y) > RUNAWAY * scale) if scale > 0 else []
    if len(beyond):
        i = int(beyond[0])
        raise InputError(
            f"the simulation diverged (the plant output reached {y[i]:.3g}, over "
            f"{RUNAWAY:g} times the reference's largest value) at t = {out['t'][i]:.6g} s; "
            "check the parameters' units and magnitudes (the adaptation's gamma among "
            "them), or give a smaller ", STEP,
            f" (now {h:.3g} s)")
