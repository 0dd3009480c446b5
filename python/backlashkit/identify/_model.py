"""The model the joint estimator fits: which parameters, which samples, how simulated.

A record is fitted over a :class:`Span`: from rest at its first sample, or from the
model's own steady state ``pre_window`` seconds before the torque step-down. The
parameters are packed in the row layout of the compiled kernel
(:func:`backlashkit.simulate.simulate_packed`), and :func:`simulate_span` simulates many
rows at once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from .. import validate as v
from ..actuator import CurrentLoop
from ..errors import InputError
from ..plants import TwoMassDrive
from ..simulate import PackedRun, simulate_packed_runs
from .record import Record
from .step import find_step_down

#: Linear parameters of a :class:`~backlashkit.TwoMassDrive`, in the fitted order.
LINEAR_PARAMS = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh")

#: Order of a two-mass drive's values in a packed kernel parameter row
#: (:class:`~backlashkit.DriveChain` fields ``J, f, k, d, theta``)...
PACKED = ("J_M", "J_L", "f_M", "f_L", "k_sh", "f_sh", "theta")
#: ... and of the long row of a model with friction or a current loop (``fc, fs,
#: tau_i``; :mod:`backlashkit.identify.terms`).
PACKED_LONG = (*PACKED, "fc_M", "fc_L", "fs_M", "fs_L", "tau_i")
#: Breakaway torques tied to the Coulomb torques (``fs = fc``) in the long row.
TIED = {"fs_M": "fc_M", "fs_L": "fc_L"}
#: Column of ``tau_i`` in the long row.
TAU_COL = PACKED_LONG.index("tau_i")

#: A record starts at rest when its first speeds are within this many noise standard
#: deviations of 0 (a Gaussian sample exceeds 4 sigma once in 16 000)...
REST_SIGMAS = 4.0
#: ... or below this fraction of their mean over the last REST_WINDOW samples before
#: the step-down: a high-pass noise estimate misses most of a filtered noise, whose
#: first sample can then exceed REST_SIGMAS of its "standard deviations".
REST_FRACTION = 0.25
REST_WINDOW = 20

#: Longest coarse step in s of the exact simulation through a held torque: the flow of
#: a held torque is exact whatever the step, so this only bounds the rounding.
HOLD_STEP = 0.02


def packed_row(drive: TwoMassDrive, tau_i: float = 0.0) -> np.ndarray:
    """The kernel's parameter row of ``drive`` (``theta`` set) with a current loop of
    time constant ``tau_i`` (0: none): short without friction or loop, else long."""
    if drive.fc_M == drive.fc_L == 0 and tau_i == 0:
        return np.array([getattr(drive, n) for n in PACKED], float)
    chain = drive.to_chain()
    return np.array([getattr(drive, n) for n in PACKED] + [*chain.fc, *chain.fs, tau_i],
                    float)


def drive_with(base: TwoMassDrive, names: Sequence[str], values: np.ndarray) -> TwoMassDrive:
    """``base`` with the parameters ``names`` set to ``values``."""
    return replace(base, **{n: float(x) for n, x in zip(names, values, strict=True)})


def rel_std(prior_rel_std, names: Sequence[str], extra: Sequence[str] = ()
            ) -> dict[str, float | None]:
    """Parameter -> relative std (None: estimated without penalty); absent = fixed.
    A dict may also give the parameters ``extra`` (a term's, fitted or not by its own
    option; kept at 0 too, for the term to refuse: :meth:`Term.check_prior`); a float
    or None applies to ``names`` alone."""
    if prior_rel_std is None:
        return {n: None for n in names}
    if isinstance(prior_rel_std, Mapping):
        out: dict[str, float | None] = {}
        allowed = (*names, *extra)
        if not prior_rel_std:  # the CLI refuses an empty [uncertainty] table alike
            raise InputError("prior_rel_std is an empty dict: give 0 to hold the linear "
                             "parameters at the prior, None to estimate them from the data, "
                             "or a dict of their relative stds")
        for key, val in prior_rel_std.items():
            if key == "theta":  # as the CLI refuses it in the [uncertainty] table
                raise InputError("prior_rel_std['theta']: the backlash is what the fit "
                                 "estimates, without a prior; remove it")
            if key not in allowed:
                raise InputError(
                    f"prior_rel_std has unknown parameter {key!r}; allowed: {', '.join(allowed)}"
                )
            x = v.nonnegative(f"prior_rel_std[{key!r}]", val)
            if x > 0 or key in extra:
                out[key] = x
        return out
    x = v.nonnegative("prior_rel_std", prior_rel_std)
    return {n: x for n in names} if x > 0 else {}


@dataclass
class Span:
    """The part of a record the model is fitted to, and how the model starts there."""

    record: Record
    k: int  # index of the record (its noise levels)
    i0: int
    t: np.ndarray
    torque: np.ndarray
    y_m: np.ndarray
    y_l: np.ndarray
    level: float | None  # torque held before the step-down (steady start) or None (rest)
    hold: float | None = None  # start: from rest after `level` held this long (s)
    # measured angles from the span's first sample (rad), fitted instead of the speeds
    p_m: np.ndarray | None = None
    p_l: np.ndarray | None = None

    @property
    def positions(self) -> bool:
        """Whether the model is fitted to the angles (the record's encoders)."""
        return self.p_m is not None

    def cut(self, i: int, j: int | None = None, **kw) -> Span:
        """The samples ``i`` to ``j`` of the span (angles again from the first)."""
        sl = slice(i, j)
        pos = {} if self.p_m is None else {"p_m": self.p_m[sl] - self.p_m[i],
                                           "p_l": self.p_l[sl] - self.p_l[i]}
        return replace(self, i0=self.i0 + i, t=self.t[sl], torque=self.torque[sl],
                       y_m=self.y_m[sl], y_l=self.y_l[sl], **pos, **kw)


def starts_at_rest(rec: Record, s_m: float, s_l: float) -> bool:
    """Whether both speeds start at rest (``start="auto"``)."""
    if (abs(rec.w_motor[0]) <= REST_SIGMAS * s_m + 1e-12
            and abs(rec.w_load[0]) <= REST_SIGMAS * s_l + 1e-12):
        return True
    try:
        i_s = find_step_down(rec)[0]
    except InputError:
        return False
    before = slice(max(0, i_s - REST_WINDOW), i_s)
    return all(abs(w[0]) <= REST_FRACTION * abs(float(np.mean(w[before])))
               for w in (rec.w_motor, rec.w_load))


def spans(recs: list[Record], start: str, pre_window: float, sig0) -> list[Span]:
    """One span per record: from rest, or from ``pre_window`` s before the step-down."""
    out = []
    for k, rec in enumerate(recs):
        s_m, s_l = sig0[k]
        mode = ("rest" if starts_at_rest(rec, s_m, s_l) else "steady") if start == "auto" \
            else start
        if mode == "rest":
            i0, level = 0, None
        else:
            i_s, t_s, level, _ = find_step_down(rec)
            n_pre = int(round(pre_window / rec.ts))
            if n_pre > i_s:
                raise InputError(
                    f"{rec.name}: the record starts {rec.t[i_s] - rec.t[0]:.6g} s before the "
                    f"step-down at t = {t_s:.6g} s: record at least {pre_window:g} s of the held "
                    "torque before it (start='steady' fits the model from there, "
                    "pre_window)"
                )
            i0 = i_s - n_pre
        sl = slice(i0, None)
        pos = {} if not rec.has_positions else {"p_m": rec.phi_motor[sl] - rec.phi_motor[i0],
                                                "p_l": rec.phi_load[sl] - rec.phi_load[i0]}
        out.append(Span(rec, k, i0, rec.t[sl], rec.torque[sl], rec.w_motor[sl],
                        rec.w_load[sl], level, **pos))
    return out


def screen_spans(spans_: list[Span]) -> list[Span]:
    """Cheaper spans for the short-horizon stages of the fit (same model, exactly).

    A record started from rest whose torque is one level held until the step-down is
    fitted there only in short windows after ``t = 0`` and after the step-down, yet the
    model must be simulated through the whole hold to reach the second window. The
    record is split into the rest start up to the step-down and a span from the
    step-down on, whose initial state is simulated through the hold on a coarse grid
    (steps of at most :data:`HOLD_STEP`): the engine's flow is exact for a held torque
    whatever the step, and it locates the contact changes inside a step, so only the
    samples nobody looks at are skipped. Once the start's contact changes are over the
    engine proves that no other can follow and runs the flow alone (it settles,
    ``docs/simulator.md``), so a hold costs little more than its first seconds.
    """
    out = []
    for sp in spans_:
        if sp.level is not None:
            out.append(sp)
            continue
        try:
            i_s, _, level, _ = find_step_down(sp.record)
        except InputError:
            out.append(sp)
            continue
        if i_s < 3 or np.any(sp.torque[:i_s] != level):
            out.append(sp)
            continue
        out.append(sp.cut(0, i_s))
        out.append(sp.cut(i_s, level=level, hold=float(sp.t[i_s] - sp.t[0])))
    return out


def has_loop(p: np.ndarray) -> bool:
    """Whether packed rows ``p`` (one layout for all) have a current loop (one more
    state: the motor torque)."""
    return p.shape[1] == len(PACKED_LONG) and bool(p[0, TAU_COL] > 0)


def initial_states(p: np.ndarray, level: float | None, torque0: float = 0.0) -> np.ndarray:
    """Initial states for packed parameter rows ``p``: rest (under the torque
    ``torque0``, the current loop's start), or steady under ``level``."""
    loop = has_loop(p)
    if level is None:
        x0 = np.zeros((p.shape[0], 4 if loop else 3))
        if loop:
            x0[:, 3] = torque0
        return x0
    fs = p[:, 2] + p[:, 3]
    if not np.all(fs > 0):
        raise InputError(
            "start='steady' needs f_M + f_L > 0 (a finite steady state), got "
            f"f_M + f_L = {float(np.min(fs))!r}"
        )
    fc_m, fc_l = (p[:, 7], p[:, 8]) if p.shape[1] == len(PACKED_LONG) else (0.0, 0.0)
    sign = 1.0 if level >= 0 else -1.0
    # Coulomb friction eats fc_M + fc_L of the held torque (a drive it holds stuck: 0)
    w = sign * np.maximum(abs(level) - fc_m - fc_l, 0.0) / fs
    twist = (p[:, 3] * w + sign * fc_l) / p[:, 4]
    cols = [w, w, sign * p[:, 6] + twist]
    if loop:
        cols.append(np.full(p.shape[0], float(level)))
    return np.column_stack(cols)


def steady_sensitivity(drive: TwoMassDrive, level: float, names: Sequence[str]
                       ) -> np.ndarray:
    """``d x / d p`` of the steady state under ``level`` (:func:`initial_states`, no
    current loop), ``(3, len(names))``: the speeds and the shaft angle by the parameters
    ``names`` (of :data:`backlashkit._sensitivity.PARAMS`), in their SI units."""
    sign = 1.0 if level >= 0 else -1.0
    f_sum, k = drive.f_M + drive.f_L, drive.k_sh
    moving = abs(level) - drive.fc_M - drive.fc_L > 0  # else held stuck: w = 0
    w = sign * (abs(level) - drive.fc_M - drive.fc_L) / f_sum if moving else 0.0
    dw = {"f_M": -w / f_sum, "f_L": -w / f_sum, "fc_M": -sign / f_sum,
          "fc_L": -sign / f_sum} if moving else {}
    twist = (drive.f_L * w + sign * drive.fc_L) / k
    # twist = (f_L w + sign fc_L) / k, differentiated through w
    direct = {"f_L": w / k, "fc_L": sign / k, "k_sh": -twist / k}
    out = np.zeros((3, len(names)))
    for c, n in enumerate(names):
        out[0, c] = out[1, c] = dw.get(n, 0.0)
        out[2, c] = drive.f_L * dw.get(n, 0.0) / k + direct.get(n, 0.0) \
            + (sign if n == "theta" else 0.0)
    return out


@dataclass(frozen=True)
class SpanRun:
    """One parameter row's simulation of a span, which the compiled sensitivities can
    follow without simulating it again (:func:`span_start`,
    :func:`backlashkit._sensitivity.sensitivities_along`): the held torque's run on its
    coarse grid (None without a hold) and the span's own run."""

    hold: PackedRun | None
    span: PackedRun


def hold_grid(span: Span) -> tuple[int, float]:
    """Steps and step in s of the coarse grid a span's hold is simulated on: the
    fewest steps of at most :data:`HOLD_STEP`, and at least 2."""
    n = max(2, math.ceil(span.hold / HOLD_STEP))
    return n, span.hold / n


def span_start(drive: TwoMassDrive, span: Span, names: Sequence[str],
               hold: PackedRun | None = None, *, actuator: CurrentLoop | None = None
               ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The state ``[w_M, w_L, phi]`` (and the motor torque ``T`` behind the current
    loop ``actuator``, then the motor's angle, 0, where the span fits angles) the model
    starts ``span`` from and its sensitivity to ``names`` (``(n, len(names))``), for
    the compiled sensitivities: ``(None, None)`` from rest; the end of the held
    torque's run on the coarse grid of :func:`simulate_span` (along ``hold``, that run
    of ``drive``, where given); or the steady state and :func:`steady_sensitivity` (the
    loop's torque is the held level, whatever the parameters)."""
    x0, s0 = _drive_start(drive, span, names, hold, actuator)
    if x0 is None or not span.positions:
        return x0, s0
    # the angles are measured from the span's first sample, whatever the parameters
    return np.append(x0, 0.0), np.vstack([s0, np.zeros((1, len(names)))])


def _drive_start(drive: TwoMassDrive, span: Span, names: Sequence[str],
                 hold: PackedRun | None, actuator: CurrentLoop | None
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """:func:`span_start` without the motor's angle."""
    from .._sensitivity import sensitivity_at_end_along, trajectory_and_sensitivities

    kw = {"params": names, "actuator": actuator}
    if span.hold is not None:
        if hold is not None:
            return hold.states[-1], sensitivity_at_end_along(drive, hold, **kw)
        n, _ = hold_grid(span)  # the grid's step as time_grid finds it: hold / n
        p = packed_row(drive, 0.0 if actuator is None else actuator.tau_i)[np.newaxis, :]
        x, sens = trajectory_and_sensitivities(
            drive, np.linspace(0.0, span.hold, n + 1), np.full(n + 1, span.level),
            initial_state=initial_states(p, None, span.level)[0], **kw)
        return x[-1], sens[-1]
    if span.level is None:
        return None, None
    p = packed_row(drive, 0.0 if actuator is None else actuator.tau_i)[np.newaxis, :]
    x0 = initial_states(p, span.level)[0]
    sens = steady_sensitivity(drive, span.level, names)
    return x0, np.vstack([sens, np.zeros((x0.size - sens.shape[0], len(names)))])


def simulate_span(p: np.ndarray, span: Span, law, workers, end: int | None = None, *,
                  runs: list[SpanRun] | None = None) -> np.ndarray:
    """States ``(len(p), end, S)`` of packed parameter rows ``p`` over a span: the two
    speeds and the shaft angle, the motor torque with a current loop, and the motor's
    angle from 0 at the span's start where the span fits angles. ``runs``, where given
    for a single row, gets that row's :class:`SpanRun`.

    What the compiled core refuses (contact chatter, a mode too fast for the sample
    time) becomes an :class:`InputError` naming the record; the searches catch it as
    the ``ValueError`` it still is.
    """
    try:
        held = None
        if span.hold is not None:  # from rest through the held torque, on a coarse grid
            n, step = hold_grid(span)
            held = simulate_packed_runs(2, p, 0.0, step, np.full((1, n + 1), span.level),
                                        initial_states(p, None, span.level), law=law,
                                        workers=workers)
            x0 = held.states[:, -1, :]
        else:
            x0 = initial_states(p, span.level, float(span.torque[0]))
        if span.positions:
            x0 = np.column_stack([x0, np.zeros(len(x0))])
        end = span.t.size if end is None else max(end, 2)
        out = simulate_packed_runs(2, p, span.t[0], span.record.ts,
                                   span.torque[np.newaxis, :end], x0, law=law,
                                   workers=workers, track_angle=span.positions)
    except InputError:
        raise
    except ValueError as exc:
        text = " ".join(str(exc).split())
        raise InputError(f"{span.record.name}: cannot simulate the drive on this record: "
                         f"{text}") from exc
    if runs is not None and len(p) == 1:
        runs.append(SpanRun(None if held is None else held.run(0), out.run(0)))
    return out.states


def model_commutation(drive: TwoMassDrive, span: Span, law: str, tau_i: float = 0.0):
    """``(t_s, t_c, t_b)`` of the identified model on a span: the step-down and its first
    contact loss and the next contact made (``None`` for what does not happen)."""
    try:
        _, t_s, _, _ = find_step_down(span.record)
    except InputError:
        return (None, None, None)
    p = packed_row(drive, tau_i)[np.newaxis, :]
    x0 = initial_states(p, span.level, float(span.torque[0]))[0]
    actuator = CurrentLoop(tau_i) if tau_i > 0 else None
    res = drive.simulate(span.t, span.torque, law=law, initial_state=x0, actuator=actuator)
    lost = next((e.time for e in res.events if e.time >= t_s and e.kind == "contact_lost"), None)
    made = None
    if lost is not None:
        made = next((e.time for e in res.events if e.time > lost and e.kind == "contact_made"),
                    None)
    return (float(t_s), None if lost is None else float(lost),
            None if made is None else float(made))


def model_angles(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The motor's and load's angles from the span's first sample, in rad, of states
    ``x`` (``(b, n, S)``, simulated with the motor angle: :func:`simulate_span`). The
    load turns by the motor's angle less the change of the shaft angle."""
    motor = x[:, :, -1]
    return motor, motor - (x[:, :, 2] - x[:, :1, 2])
