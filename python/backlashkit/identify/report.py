"""Self-contained HTML report of a backlash identification (paper A).

:func:`write_identification_report` writes ``index.html`` and its figures (PNG, and
SVG beside each) into a directory: relative links only, inline CSS, no external
resource, so the directory can be zipped, mailed or opened offline. It shows

* measured and simulated speeds with the fit ``100 (1 - ||y - y_hat|| / ||y -
  mean(y)||)`` in %: for the joint estimator its own model over the span it fitted
  (``fit_percent_``, as the command line prints); for the other methods over the
  criterion's span ``[t_s, t_s + dt_4]``, the model being the prior with the estimated
  ``theta``, started as in the criterion ``W_1`` of
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
* a table of the estimates in rad and degrees, with the rows the method gives values
  for (a method without ``std`` and ``ci95`` gets a sentence saying so, not empty
  cells).

The plot helpers (:func:`plot_speed_fit`, :func:`plot_commutation`,
:func:`plot_cost`, :func:`plot_profile`, :func:`plot_residual_acf`) take ``ax=`` and
return the figure; they use :class:`matplotlib.figure.Figure`, never ``pyplot``.

:func:`cost_curve` is paper A's criterion (:mod:`backlashkit.identify.two_step`),
imported here for the report's cost plot.
"""

from __future__ import annotations

import html
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, Option, word_parts
from ..htmlpage import figure, page, save_figure, table
from ..io import check_writable
from ..plants import TwoMassDrive
from .plots import (
    _short,
    fit_percent,
    plot_commutation,
    plot_cost,
    plot_profile,
    plot_residual_acf,
    plot_speed_fit,
)
from .record import Record, as_records
from .step import find_step_down
from .two_step import DEFAULT_DT4, cost_curve, criterion_window

__all__ = [
    "check_report_directory",
    "write_identification_report",
]

PathLike = str | os.PathLike[str]



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

    seg = criterion_window(rec, dt4, level_window)
    i_s = find_step_down(rec)[0]
    sl = slice(i_s, i_s + seg.t.size)
    # the shaft carries the load's friction, as in W_1's start
    x0 = np.array([[seg.w0, seg.w0, theta + (prior.f_L * seg.w0 + prior.fc_L) / prior.k_sh]])
    (r,) = simulate_batch([prior.with_theta(theta)], seg.t, seg.torque, initial_state=x0,
                          workers=1)
    wm, wl = rec.w_motor[sl], rec.w_load[sl]
    return _Fit(rec, seg.t, wm, wl, r.w_motor, r.w_load,
                fit_percent(wm, r.w_motor), fit_percent(wl, r.w_load))


def _terms_text(result: Any) -> str:
    """What the joint fit's model has beyond paper A's, as words after "the drive"."""
    parts = []
    if getattr(result, "friction_", "viscous") == "coulomb":
        parts.append(f"Coulomb friction {result.fc_M_:.3g} / {result.fc_L_:.3g} N m")
    if getattr(result, "tau_i_", 0.0):
        parts.append(f"a current loop of {1e3 * result.tau_i_:.3g} ms")
    return f" with {' and '.join(parts)}" if parts else ""


def _fitted_model(result: Any, recs: list[Record], finals: list[Record]
                  ) -> list[_Fit] | None:
    """The joint estimator's own model over what it fitted (the speeds less its
    residuals, with its friction and current loop) and its fit % (``fit_percent_``,
    the figure the command line prints); None for the other methods, whose fits the
    report simulates from the held speed."""
    residuals = getattr(result, "residuals_", None)
    if residuals is None:
        return None
    every = recs if finals is recs else recs + finals
    if len(residuals) != len(every):
        return None
    out = []
    for rec, (em, el), (fm, fl) in zip(every, residuals, result.fit_percent_, strict=True):
        sl = slice(rec.t.size - em.size, None)  # a span runs to the record's end
        wm, wl = rec.w_motor[sl], rec.w_load[sl]
        out.append(_Fit(rec, rec.t[sl], wm, wl, wm - em, wl - el, float(fm), float(fl)))
    return out


# --- the report -----------------------------------------------------------------------


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
            f"{what}; pass ", Option("force"), " to write the report there "
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
    notes: Sequence[str] = (),
    spell: Callable[[Option], str | None] | None = None,
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
    notes : sequence of str, optional
        What the reader must know of the answer (the command line's notes), listed
        under the estimates.
    spell : callable, optional
        ``spell(option)`` words an option the page advises for the front end that
        wrote it (the command line's flag), or returns None for Python's words
        (default).

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
    shown = _Shown.of(result, theta, recs, finals)
    fits = _draw_fits(out, prior, recs, finals, shown, result)
    _draw_criterion(out, prior, finals, shown, result)
    index.write_text(page(title, _sections(title, prior, recs, fits, shown, result,
                                           notes, spell)), encoding="utf-8")
    return index


@dataclass
class _Shown:
    """What the report reads from a fitted identifier (duck-typed)."""

    theta: float
    dt4: float
    level_window: float
    cutoff_motor: float
    cutoff_load: float
    theta_ini: Any
    bounds: Any
    t_c: Any
    t_b: Any
    method: str
    workers: Any
    has_comm: bool

    @classmethod
    def of(cls, result: Any, theta: float, recs: list[Record], finals: list[Record]) -> _Shown:
        dt4 = float(getattr(result, "dt4", DEFAULT_DT4))
        if not hasattr(result, "dt4"):  # the joint fit has no window: show what was recorded
            dt4 = min([dt4] + [r.t[-1] - find_step_down(r)[1] - r.ts for r in finals])
        t_c, t_b = getattr(result, "t_c_", None), getattr(result, "t_b_", None)
        has_comm = (t_c is not None and t_b is not None and len(t_c) == len(recs)
                    and all(x is not None for x in (*t_c, *t_b)))
        return cls(theta, dt4, float(getattr(result, "level_window", 1.0)),
                   float(getattr(result, "cutoff_motor", 50.0)),
                   float(getattr(result, "cutoff_load", 20.0)),
                   getattr(result, "theta_ini_", None), getattr(result, "bounds_", None),
                   t_c, t_b, str(getattr(result, "method", type(result).__name__)),
                   getattr(result, "workers", None), has_comm)


def _commutation_caption(result: Any) -> str:
    """What the commutation figure shows: the joint fit's window is its model's own,
    not the one the two-step pre-estimate detected in the speeds."""
    head = ("Filtered speeds around the step-down: contact lost at t_c, impact at t_b, "
            "and the area between the speeds (shaded)")
    if hasattr(result, "residuals_"):
        return (f"{head}. Here t_c and t_b are those of the identified model, so -1/2 of "
                "the area (in the title) is the backlash the speeds show over the model's "
                "window; the pre-estimate theta_ini in the table takes its own t_c and t_b "
                "from the speeds, and differs from it")
    return f"{head}, whose -1/2 is the pre-estimate theta_ini"


def _draw_fits(out: Path, prior: TwoMassDrive, recs: list[Record], finals: list[Record],
               shown: _Shown, result: Any) -> list[_Fit]:
    """The figures of the speeds: measured against simulated, the commutation windows
    and the residuals' autocorrelation."""
    from matplotlib.figure import Figure

    fits = _fitted_model(result, recs, finals)
    if fits is None:  # paper A's methods: the prior with the friction of their model
        model = replace(prior, fc_M=float(getattr(result, "fc_M_", prior.fc_M)),
                        fc_L=float(getattr(result, "fc_L_", prior.fc_L)), fs_M=None,
                        fs_L=None)
        fits = [_simulate_fit(model, r, shown.theta, shown.dt4, shown.level_window)
                for r in finals]
    fig = Figure(figsize=(9, 4.4 * len(fits) + 0.4), layout="constrained")
    axes = fig.subplots(2 * len(fits), 1, squeeze=False)[:, 0]
    for k, f in enumerate(fits):  # one above the other: the legends sit beside them
        plot_speed_fit(f.t, f.w_motor, f.sim_motor, label="w_M", ax=axes[2 * k])
        plot_speed_fit(f.t, f.w_load, f.sim_load, label="w_L", ax=axes[2 * k + 1])
        axes[2 * k].set_title(f"{_short(f.record.name, 60)}: motor and load speeds",
                              fontsize="medium", loc="left")
    save_figure(fig, out, "fit")
    if shown.has_comm:
        fig = Figure(figsize=(9, 3.2 * len(recs) + 0.3), layout="constrained")
        axes = fig.subplots(len(recs), 1, squeeze=False)[:, 0]
        for rec, c, b, ax in zip(recs, shown.t_c, shown.t_b, axes, strict=True):
            plot_commutation(rec, float(c), float(b), cutoff_motor=shown.cutoff_motor,
                             cutoff_load=shown.cutoff_load, ax=ax)
        save_figure(fig, out, "commutation")
    fig = Figure(figsize=(8, 3.2), layout="constrained")
    ax = fig.subplots()
    for f in fits:
        plot_residual_acf(f.w_motor - f.sim_motor, ts=f.record.ts,
                          label=_short(f.record.name, 30) if len(fits) > 1 else None, ax=ax)
    save_figure(fig, out, "residual_acf")
    return fits


def _draw_criterion(out: Path, prior: TwoMassDrive, finals: list[Record], shown: _Shown,
                    result: Any) -> None:
    """The figures of theta: the criterion over a grid, and the profile likelihood of
    the joint estimator."""
    theta, bounds, theta_ini = shown.theta, shown.bounds, shown.theta_ini
    top = 2.0 * theta
    if bounds is not None:
        top = max(top, 1.3 * float(bounds[1]))
    if theta_ini is not None:
        top = max(top, 2.5 * float(theta_ini))
    search = getattr(result, "search", None)  # the joint estimator's JointSearch
    theta_max = search.grid.theta_max if search is not None else getattr(
        result, "theta_max", None)
    if bounds is None and theta_max is not None:
        top = max(top, float(theta_max))  # regression, joint: the whole search range
    top = top if top > 0 else math.radians(5.0)
    grid = np.linspace(0.0, top, 61)
    if bounds is not None:
        grid = np.union1d(grid, np.linspace(float(bounds[0]), float(bounds[1]), 21))
    grid = np.union1d(grid, [theta])
    costs = cost_curve(prior, finals, grid, dt4=shown.dt4, level_window=shown.level_window,
                       workers=shown.workers)
    fig = plot_cost(grid, costs, theta=theta,
                    theta_ini=None if theta_ini is None else float(theta_ini),
                    bounds=None if bounds is None else (float(bounds[0]), float(bounds[1])))
    save_figure(fig, out, "cost")
    profile = getattr(result, "profile_", None)
    if profile is not None:
        fig = plot_profile(profile, ci95=getattr(result, "ci95_", None), theta=theta,
                           std=getattr(result, "std_", None))
        save_figure(fig, out, "profile")


def _estimate_rows(shown: _Shown, result: Any) -> list[tuple[str, str, str]]:
    """The rows of the estimates' table that have a value: (quantity, rad, deg)."""
    kind = {"profile": "profile likelihood", "fisher": "Fisher information",
            "bootstrap": "parametric bootstrap",
            "quantisation": "spread over the encoders' offsets"}.get(
                getattr(result, "interval_", None))
    std, ci95 = getattr(result, "std_", None), getattr(result, "ci95_", None)
    rows = [("theta, the backlash half-width", shown.theta),
            ("standard error of theta", std),
            (f"95 % interval of theta ({kind})" if kind else "95 % interval of theta", ci95),
            ("pre-estimate theta_ini (area between the speeds)", shown.theta_ini),
            ("search interval of theta", shown.bounds)]
    return [(name, _fmt(x), _deg(x)) for name, x in rows if _given(x)]


def _given(x: Any) -> bool:
    """Whether a value (number or pair) is there to show."""
    if x is None:
        return False
    values = list(x) if isinstance(x, (tuple, list, np.ndarray)) else [x]
    try:
        return bool(values) and all(math.isfinite(float(v)) for v in values)
    except (TypeError, ValueError):
        return False


def _record_table(recs: list[Record], shown: _Shown, result: Any) -> str:
    """Per record: the step-down, the contact changes and the pre-estimate, in columns
    that hold a value for every record."""
    per_ini = list(getattr(result, "theta_ini_per_record_", None) or [])
    has_ini = len(per_ini) == len(recs) and all(_given(x) for x in per_ini)
    header = ["record", "step-down t_s (s)"]
    if shown.has_comm:
        header += ["contact lost t_c (s)", "impact t_b (s)"]
    if has_ini:
        header += ["theta_ini (rad)"]
    rows = []
    for k, rec in enumerate(recs):
        row = [rec.name, f"{find_step_down(rec)[1]:.4f}"]
        if shown.has_comm:
            row += [f"{float(shown.t_c[k]):.4f}", f"{float(shown.t_b[k]):.4f}"]
        if has_ini:
            row += [_fmt(per_ini[k])]
        rows.append(row)
    return table(header, rows)


def _cost_sentence(shown: _Shown, result: Any) -> str:
    cost = getattr(result, "cost_", None)
    if not _given(cost):
        return ""
    if hasattr(result, "dt4"):  # the two-step and regression criterion
        return (f'<p class="note">Criterion at the estimate: {_fmt(cost)} (rad/s)^2, the '
                f"squared motor-speed error summed over the {shown.dt4:g} s after the "
                "step-down t_s.</p>")
    return (f'<p class="note">Cost at the optimum: {_fmt(cost)}, the sum of squared '
            "residuals each divided by its noise level (no unit), plus the prior's "
            "penalty.</p>")


def _noise_note(result: Any, spell: Callable[[Option], str | None] | None) -> str:
    """The joint estimator's noise model and what its residuals say of it."""
    from .joint import CORRELATED_LAG1

    ar = getattr(result, "noise_ar_", None)
    model = "white" if ar is None else f"autoregressive of order {ar.shape[-1]}"
    # the command line's words for the advice where it wrote the page
    message = (result.correlation_message() if spell is None
               else _worded(result._correlation_parts(), spell))
    if message:
        said = f"<b>Note:</b> {html.escape(message)}."
    else:
        largest = float(np.max(np.abs(result.residual_lag1_)))
        said = (f"The residuals are as uncorrelated as the likelihood assumes: their "
                f"largest lag-1 correlation is {largest:.3f} (a note appears above "
                f"{CORRELATED_LAG1:g}).")
    return f'<p class="note">Noise model: {model}. {said}</p>'


def _worded(parts, spell) -> str | None:
    return None if parts is None else word_parts(parts, spell)


def _prior_text(prior: TwoMassDrive, result: Any) -> str:
    """The prior as the fit read it: its parameters, and their relative stds."""
    names = ["J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh"]
    names += [n for n in ("fc_M", "fc_L") if getattr(prior, n)]
    text = ", ".join(f"{k} = {getattr(prior, k):.4g}" for k in names)
    rel = getattr(result, "prior_rel_std", None)
    if isinstance(rel, Mapping):
        text += "; relative stds " + ", ".join(f"{k} {x:g}" for k, x in rel.items())
    elif rel is not None:
        text += f"; relative std {rel:g} on each linear parameter"
    return text


def _notes_list(notes: Sequence[str]) -> str:
    if not notes:
        return ""
    items = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    return f'<h2>Notes</h2><ul class="note">{items}</ul>'


def _sections(title: str, prior: TwoMassDrive, recs: list[Record], fits: list[_Fit],
              shown: _Shown, result: Any, notes: Sequence[str] = (),
              spell: Callable[[Option], str | None] | None = None) -> list[str]:
    """The page's HTML sections."""
    bounds, dt4, method = shown.bounds, shown.dt4, shown.method
    profile = getattr(result, "profile_", None)
    n_theta = getattr(result, "n_theta", None)
    no_spread = ("" if _given(getattr(result, "std_", None))
                 or _given(getattr(result, "ci95_", None)) else
                 f'<p class="note">The {html.escape(method)} method gives no standard '
                 "error or interval of theta.</p>")
    fit_rows = [(f.record.name, f"{f.fit_motor:.2f}", f"{f.fit_load:.2f}", str(f.t.size))
                for f in fits]
    prior_txt = _prior_text(prior, result)
    shaded = (f"; shaded: the search interval theta_ini (1 ± n_theta), n_theta = "
              f"{_fmt(n_theta)}" if n_theta is not None and bounds is not None
              else "; shaded: the method's search interval" if bounds is not None else "")
    sections = [
        f"<h1>{html.escape(title)}</h1>",
        f'<p class="note">Method <b>{html.escape(method)}</b>. theta is the backlash '
        "<b>half-width</b> (dead zone [-theta, theta], total gap 2 theta). SI units; "
        "the figures show theta in degrees. "
        f"Prior: {prior_txt}.</p>",
        "<h2>Estimates</h2>",
        table(("quantity", "rad", "deg"), _estimate_rows(shown, result)),
        no_spread,
        _notes_list(notes),
        _cost_sentence(shown, result),
        _record_table(recs, shown, result),
        "<h2>Measured and simulated speeds</h2>",
        table(("record", "fit w_M (%)", "fit w_L (%)", "samples"), fit_rows),
        '<p class="note">fit = 100 (1 - ||y - y_hat|| / ||y - mean(y)||) over '
        + (f"the fitted span of each record (the figure the command line prints); model: "
           f"the identified drive{_terms_text(result)}.</p>"
           if hasattr(result, "residuals_") else
           f"[t_s, t_s + {dt4:g} s]; model: prior with the estimated theta, started at "
           "the measured steady state.</p>"),
        figure("fit", "Measured (grey) and simulated (red) motor and load speeds of each "
               "record"),
    ]
    if shown.has_comm:
        sections += [
            "<h2>Commutation window</h2>",
            figure("commutation", _commutation_caption(result)),
        ]
    sections += [
        "<h2>Criterion against theta</h2>",
        figure("cost", "Squared motor-speed error of the prior with each theta (the two-step "
                       f"method's criterion; the joint fit also refits the drive){shaded}"),
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
        sections.append(_noise_note(result, spell))
    return [s for s in sections if s]
