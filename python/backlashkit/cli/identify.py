"""``backlashkit identify``: identify the backlash from step-down experiments.

Reads one or more experiment files (CSV, columns ``t,torque,w_motor,w_load`` in SI, as
written by ``backlashkit simulate --experiment step-down``, or other layouts, units,
``.mat`` and ``.npz`` through the options of :func:`backlashkit.identify.readers.read_records`)
and a prior drive file (``[drive]`` with the linear parameters; a ``theta`` in it is
ignored; an optional ``[uncertainty]`` table gives relative standard deviations for the
joint method), and runs the joint maximum-likelihood fit of theta and the linear
parameters with its standard error (default), paper A's two-step method or its
regression baseline. See
:mod:`backlashkit.identify` and :mod:`backlashkit.identify.joint` for the methods and
their documented choices.
"""

from __future__ import annotations

import argparse
import inspect
import json
import math
import warnings
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import (
    CorrelatedResidualsWarning,
    Diagnostic,
    InputError,
    Option,
    PriorMismatchWarning,
    QuantisedSpeedsWarning,
    SearchEdgeWarning,
    StepDownWarning,
)
from ..identify.intervals import ParametricBootstrap
from ..identify.joint import LINEAR_PARAMS
from ..identify.noise import ARNoise, noise_label
from ..identify.readers import SPEED_UNITS, read_records
from ..identify.record import Record
from ..identify.report import check_report_directory
from ..identify.step import REFUSE_FROM_PRIOR
from ..identify.terms import FRICTION_CHOICES, TermChoice
from ..identify.torque import torque_levels
from ..identify.two_step import DEFAULT_DT4, RegressionIdentifier, TwoStepIdentifier
from ..io import read_actuator_toml, read_drive_toml, read_uncertainty_toml
from ._identify_text import print_result
from .files import add_file_options, file_options, reader_errors
from .main import flag_names, word
from .report import add_report_option, maybe_write_report

__all__ = ["add_parser", "run"]

METHODS = ("two-step", "regression", "joint")
#: Method used without ``--method``: ``joint`` is the most accurate and the only one
#: with an uncertainty.
DEFAULT_METHOD = "joint"

_DESCRIPTION = f"""\
Identify the backlash half-width theta (rad) of a two-mass drive from torque
step-down experiments (paper A, Ravanbod-Shirazi & Besancon-Voda 2002).

two-step (paper A's method): locates the contact loss t_c and the impact on the other
flank t_b after each step-down on the load speed, pre-estimates theta_ini as half the
area between the low-pass filtered load and motor speeds from t_c to t_b, then fits
the motor speed over the {DEFAULT_DT4:g} s after the step-down by least squares, theta
searched in theta_ini (1 +- n_theta). regression (paper A's baseline): the same least squares
with theta searched over [0, 15 deg] and no pre-estimate. joint (default): maximum
likelihood over theta AND the linear parameters, on every record and both speeds
(each weighted by its own noise level, estimated from the data), the prior entering
as a Gaussian penalty with the relative std of the [uncertainty] table of the --drive
file (or --prior-rel-std); without either, the linear parameters are refined from the
data alone. The table may also give the Coulomb torques fc_M, fc_L a relative std about
their values in [drive]. It reports the standard error std (Fisher information) and a 95% interval
ci95 of theta (profile likelihood; --interval fisher: theta +- 1.96 std), and says
when the residuals are correlated from sample to sample (filtered speeds: --noise ar
models the noise as autoregressive instead of white); its t_c, t_b are the contact
changes of the identified model (located between samples), theta_ini is the area
pre-estimate it also starts from.

Each EXP.csv holds columns t,torque,w_motor,w_load (SI) with one step-down of the
torque from a positive level (other names, separators, decimal commas, rpm, a sample
time instead of a time column, encoder angles phi_motor,phi_load instead of speeds,
.mat and .npz files: see the reading options).
Paper A's protocol uses a small step (about 0.1 of the largest torque) for the
pre-estimate and a larger one (about 0.6) for the least squares: give the latter with
--final (the positional files are then used for the pre-estimate only; the joint
method fits all files together).
"""

_EPILOG = """\
examples:
  backlashkit simulate examples/paper_drive.toml --experiment step-down \\
      --amplitude 0.157 --hold 40 --snr-motor 30 --snr-load 30 --seed 1 --out exp.csv
  backlashkit identify exp.csv --drive examples/paper_drive.toml --json
  backlashkit identify exp.csv --drive examples/paper_drive.toml --method joint
"""


def _default(cls: Any, name: str) -> Any:
    """The library's default of a parameter (said in the help, never retyped)."""
    return inspect.signature(cls).parameters[name].default


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``identify`` subcommand.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The object returned by ``parser.add_subparsers()``.

    Returns
    -------
    argparse.ArgumentParser
        The subcommand's parser (its ``func`` default is :func:`run`).
    """
    p = subparsers.add_parser(
        "identify",
        help="identify the backlash from step-down experiments (paper A)",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "records", metavar="EXP.csv", nargs="+",
        help="experiment file(s): CSV with columns t,torque,w_motor,w_load (SI), or .mat "
        "(v7.3 too) / .npz with variables of those names (a file may hold several records)",
    )
    p.add_argument(
        "--drive",
        metavar="PRIOR.toml",
        required=True,
        help="prior linear parameters: [drive] with J_M, J_L, k_sh, f_M, f_L, f_sh (SI), "
        "optionally the Coulomb torques fc_M, fc_L (N m: the fit's start, and its prior "
        "with an [uncertainty]); theta, if present, is ignored",
    )
    p.add_argument("--method", choices=METHODS, default=DEFAULT_METHOD,
                   help=f"default {DEFAULT_METHOD}")
    p.add_argument(
        "--final",
        metavar="EXP.csv",
        action="append",
        help="two-step: experiment(s) for the final least squares (a larger step, about "
        "0.6 of the largest torque); default the positional files; joint: fitted with the "
        "positional files. May be repeated",
    )
    p.add_argument(
        "--n-theta", type=float, default=None, help="two-step: relative search half-width "
        f"around theta_ini (default {_default(TwoStepIdentifier, 'n_theta'):g})"
    )
    p.add_argument(
        "--cutoff-motor", type=float, default=None, help="two-step: FIR cut-off for w_motor in "
        f"rad/s (default {_default(TwoStepIdentifier, 'cutoff_motor'):g})"
    )
    p.add_argument(
        "--cutoff-load", type=float, default=None, help="two-step: FIR cut-off for w_load in "
        f"rad/s (default {_default(TwoStepIdentifier, 'cutoff_load'):g})"
    )
    p.add_argument(
        "--onset", choices=("constant", "unloading"), default=None,
        help="two-step: the load speed's course before the contact loss t_c, when "
        "locating it: constant (paper A's) or the unloading shaft's cubic fall (exact t_c "
        "on noise-free data; no better with noise) "
        f"(default {_default(TwoStepIdentifier, 'onset')})"
    )
    p.add_argument(
        "--allow-far-from-prior", action="store_true",
        help=f"answer even when a linear parameter ends more than {REFUSE_FROM_PRIOR:g} "
        f"times off the prior (joint), or the speeds under the torque held before the "
        f"step-down are more than {REFUSE_FROM_PRIOR:g} times the prior's (two-step, "
        "regression) (default: refused, a unit or column mistake being likelier)"
    )
    _add_joint_options(p)
    g = p.add_argument_group("reading the experiment files (all files alike)")
    add_file_options(g, columns_help="the file's names of our columns t, torque, w_motor, "
                     "w_load, e.g. 't=time,w_motor=n_mot,w_load=n_load' (unmapped ones keep "
                     "our names)")
    g.add_argument("--speed-unit", choices=tuple(SPEED_UNITS), default=None,
                   help="unit of the speeds in the files; rpm and deg/s are converted "
                   f"(default {_default(read_records, 'speed_unit')})")
    g.add_argument("--angles", action="store_true",
                   help="the files hold the encoders' angles phi_motor, phi_load in rad "
                   "instead of the speeds (fitted as angles)")
    g.add_argument("--counts-per-rev", type=float, default=None, metavar="N",
                   help="the files hold the angles phi_motor, phi_load as encoder counts, N "
                   "per revolution (implies --angles)")
    g.add_argument("--torque-levels", action="store_true",
                   help="replace a noisy measured torque by its piecewise-constant levels "
                   "(the model takes the torque as its exact input; default: a noisy torque "
                   "is an error)")
    p.add_argument("--json", action="store_true", help="print only a JSON object on stdout")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar on stderr (of the joint fit's stages and of the "
                   "--bootstrap refits; there is none when stderr is not a terminal either)")
    add_report_option(p)
    p.set_defaults(func=run)
    return p


def _add_joint_options(p: argparse.ArgumentParser) -> None:
    """The options of the joint method (and ``--friction``, shared with the others)."""
    p.add_argument(
        "--prior-rel-std", type=float, default=None, metavar="REL",
        help="joint: relative std of every linear parameter of the prior (overrides the "
        "[uncertainty] table, its Coulomb torques too; 0 = known exactly)"
    )
    p.add_argument(
        "--interval", choices=("profile", "fisher"), default=None,
        help="joint: ci95 from the profile likelihood (default) or theta +- 1.96 std "
        "(Fisher information; no extra fits)"
    )
    p.add_argument(
        "--bootstrap", type=int, default=None, metavar="N",
        help="joint: std and ci95 from N parametric-bootstrap refits instead (N + 1 fits)"
    )
    p.add_argument("--seed", type=int, default=None,
                   help="joint --bootstrap: seed of the resamples' noise (default "
                   f"{_default(ParametricBootstrap, 'seed')})")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="joint --bootstrap: run the refits on N processes (the same "
                   "result as on one; default 1)")
    p.add_argument(
        "--noise", choices=("auto", "white", "ar"), default=None,
        help="joint: measurement noise model, white, autoregressive (for filtered "
        "speeds, whose noise is correlated from sample to sample: the residuals are "
        "whitened, the interval widened accordingly) or auto (default: autoregressive "
        "where the speeds' noise on the level held before the step-down is correlated)"
    )
    p.add_argument("--noise-order", type=int, default=None, metavar="P",
                   help="joint --noise ar or auto: order of the autoregressive model "
                   f"(default {_default(ARNoise, 'order')})")
    p.add_argument(
        "--friction", choices=FRICTION_CHOICES, default=None,
        help="Coulomb friction torques fc_M, fc_L fitted and kept where the data call for "
        "them (auto), never (viscous) or always (coulomb); default auto for joint, viscous "
        "(paper A's model) for two-step and regression"
    )
    p.add_argument(
        "--current-loop", default=None, metavar="auto|none|TAU",
        help="joint: the drive's current loop, a first-order lag of the torque: its time "
        "constant fitted and kept where the data call for it (auto), none, or known (TAU "
        "in s); default: the --drive file's [actuator] tau_i where it has one, else auto"
    )
    p.add_argument(
        "--final-horizon", type=float, default=None, metavar="S",
        help="joint: final fit and interval on S seconds after the start and every torque "
        "jump of each record instead of the whole record (where the shaft rattles: "
        "better calibrated intervals, larger std)"
    )


def read_experiments(args: argparse.Namespace, paths: list[str]) -> list[Record]:
    """Read the experiment files with the reader options of ``args``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments holding the file options and ``speed_unit``.
    paths : list of str
        The files.

    Returns
    -------
    list of Record
        Every record of every file, in order.
    """
    options = file_options(args)
    if args.speed_unit is not None:
        options["speed_unit"] = args.speed_unit
    options.update(angles=args.angles, counts_per_rev=args.counts_per_rev)
    out: list[Record] = []
    for path in paths:
        if path == "-":
            raise InputError("'-': identify reads files, not the standard input; give a "
                             "file name (or /dev/stdin)")
        with reader_errors():
            out += read_records(path, **options)
    return out




def _noise_model_flag(option: Option) -> str:
    return "--noise ar"


#: Library parameters set from a flag of ``identify`` -> the flag.
FLAGS = {
    "n_theta": "--n-theta", "cutoff_motor": "--cutoff-motor", "cutoff_load": "--cutoff-load",
    "n_resamples": "--bootstrap", "seed": "--seed", "final_horizon": "--final-horizon",
    "order": "--noise-order", "sample_time": "--sample-time",
    "allow_far_from_prior": "--allow-far-from-prior",
    "method": "--method", "torque_levels": "--torque-levels", "noise_model": _noise_model_flag,
    "force": "--force", "friction": "--friction", "actuator": "--current-loop",
    "speed_unit": "--speed-unit", "counts_per_rev": "--counts-per-rev", "angles": "--angles",
}

#: Warnings of the library that ``identify`` says as notes (printed after theta, and
#: the ``notes`` of ``--json``).
NOTED = (PriorMismatchWarning, StepDownWarning, CorrelatedResidualsWarning,
         SearchEdgeWarning, QuantisedSpeedsWarning)


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _pair(x: tuple[float, float] | None) -> list[float | None] | None:
    return None if x is None else [_num(v) for v in x]


def _test_json(c: TermChoice) -> dict[str, Any]:
    """One term's likelihood-ratio test (:class:`~backlashkit.identify.TermChoice`)
    as numbers: ``widening`` in ``log theta`` (down, up), the intervals in rad."""
    return {"term": c.term, "kept": c.kept, "rise": _num(c.rise),
            "threshold": _num(c.threshold), "shift": _num(c.shift),
            "screened": c.screened, "determined": c.determined,
            "other_ci95": _pair(c.other_ci95), "widening": _pair(c.widening),
            "held_ci95": _pair(c.held_ci95)}


def run(args: argparse.Namespace) -> int:
    """Run ``backlashkit identify``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments.

    Returns
    -------
    int
        Exit status (0 on success; bad input raises :class:`InputError`, whose
        message names the flag, e.g. ``--final-horizon``, not the parameter).
    """
    flags: dict[str, Any] = dict(FLAGS)
    if args.prior_rel_std is not None:  # else the [uncertainty] table gave the values
        flags["prior_rel_std"] = "--prior-rel-std"
    else:  # a std the table gave, named where it is
        flags["prior_rel_std"] = partial(_table_entry, args.drive)
    flags["prior_value"] = partial(_drive_entry, args.drive)
    flags["hold_at_prior"] = partial(_held_entry, args.drive)
    with flag_names(flags):
        return _run(args, flags)


def _table_entry(drive: str, option: Any) -> str:
    """Where the drive file gave a prior std (``terms.prior_std_option``)."""
    name, value = option.value
    return f"{drive}: [uncertainty] {name} = {value:g}"


def _drive_entry(drive: str, option: Any) -> str:
    """Where the drive file gives a prior value (``Term.check_prior``)."""
    return f"{option.value} in the [drive] table of {drive}"


def _held_entry(drive: str, option: Any) -> str:
    """How the drive file holds a parameter at its value
    (``joint.check_estimated_nonzero``)."""
    return (f"an [uncertainty] table in {drive} that lists the others and not "
            f"{option.value}, without --prior-rel-std")


def _check_options(args: argparse.Namespace) -> None:
    """Refuse a flag that the chosen method does not read."""
    for option, value in (("--bootstrap", args.bootstrap), ("--interval", args.interval),
                          ("--current-loop", args.current_loop),
                          ("--final-horizon", args.final_horizon), ("--noise", args.noise),
                          ("--noise-order", args.noise_order),
                          ("--prior-rel-std", args.prior_rel_std)):
        if value is not None and args.method != "joint":
            raise InputError(f"{option} only applies with --method joint")
    for option, value in (("--n-theta", args.n_theta), ("--cutoff-motor", args.cutoff_motor),
                          ("--cutoff-load", args.cutoff_load), ("--onset", args.onset)):
        if value is not None and args.method != "two-step":
            raise InputError(f"{option} only applies with --method two-step")
    if args.seed is not None and args.bootstrap is None:
        raise InputError("--seed only applies with --bootstrap (the seed of its resamples)")
    if args.jobs is not None and args.bootstrap is None:
        raise InputError("--jobs only applies with --bootstrap (the processes of its refits)")
    if args.final and args.method == "regression":
        raise InputError("--final only applies with --method two-step or joint (the default)")
    if args.bootstrap is not None and args.interval is not None:
        raise InputError("give --interval or --bootstrap, not both")
    if args.noise_order is not None and args.noise == "white":
        raise InputError("--noise-order only applies with --noise ar or auto")


def _level_torques(groups: list[list[Record]]) -> list[str]:
    """``--torque-levels``: each record's torque replaced by its levels, in place; the
    notes saying what was done."""
    notes = []
    for group in groups:
        for k, rec in enumerate(group):
            group[k] = torque_levels(rec)
            if group[k] is rec:
                notes.append(f"{rec.name}: the torque is piecewise constant already; "
                             "--torque-levels left it as it is")
                continue
            levels = np.unique(group[k].torque).size
            removed = float(np.sqrt(np.mean((rec.torque - group[k].torque) ** 2)))
            notes.append(f"{rec.name}: torque replaced by its {levels} piecewise-constant "
                         f"levels (the removed noise has an rms of {removed:.3g} N m)")
    return notes


def _run(args: argparse.Namespace, flags: dict[str, Any]) -> int:
    if args.report is not None:  # before the fit, not after it
        if not args.report.strip():
            raise InputError("--report needs a directory name, got an empty one")
        check_report_directory(Path(args.report), force=bool(args.force))
    prior = read_drive_toml(args.drive, require_theta=False)
    prior = prior.with_theta(None) if prior.theta is not None else prior
    records = read_experiments(args, args.records)
    finals = None if not args.final else read_experiments(args, args.final)
    read_notes = _level_torques([records, finals or []]) if args.torque_levels else []
    _check_options(args)
    fit = {"joint": _fit_joint, "two-step": _fit_two_step,
           "regression": _fit_regression}[args.method]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est, out = fit(args, prior, records, finals)
    shown = set()
    for w in caught:  # the others as they would have been shown: once each
        if not issubclass(w.category, NOTED) and (w.category, str(w.message)) not in shown:
            shown.add((w.category, str(w.message)))
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    # the record's notes first; the joint fit's distance to the prior with its result
    first = (StepDownWarning,) if args.method == "joint" else (StepDownWarning,
                                                              PriorMismatchWarning)
    notes = read_notes + _noted(caught, flags, first) + _notes(args, est, caught, flags)
    report = maybe_write_report(args, records, est, prior, final_records=finals,
                                notes=notes, flags=flags)
    result = {
        "command": "identify",
        "method": args.method,
        "drive": str(args.drive),
        "theta": _num(est.theta_),
        "theta_deg": _num(math.degrees(est.theta_)),
        "theta_ini": _num(out["theta_ini"]),
        "std": _num(out.get("std")),
        "ci95": out.get("ci95"),
        "search_interval": out["bounds"],
        "cost": _num(est.cost_),
        "records": out["per_record"],
        "final_records": [r.name for r in finals] if finals else None,
        "report": str(report) if report else None,
        **out.get("extra", {}),
        "notes": notes,
    }
    if args.json:
        print(json.dumps(result, allow_nan=False))
        return 0
    print_result(args, est, out, notes, records + (finals or []))
    return 0


def _noted(caught: list[warnings.WarningMessage], flags: dict[str, Any],
           categories: tuple[type, ...]) -> list[str]:
    """The library's warnings of ``categories``, worded, once each."""
    out: list[str] = []
    for w in caught:
        if not issubclass(w.category, categories):
            continue
        message = w.message
        text = word(message, flags) if isinstance(message, Diagnostic) else str(message)
        if text not in out:
            out.append(text)
    return out


def _joint_identifier(args: argparse.Namespace, prior: Any) -> Any:
    """The joint estimator the flags ask for (unfitted)."""
    from ..identify.intervals import FisherInterval, ParametricBootstrap, ProfileLikelihood
    from ..identify.joint import JointIdentifier
    from ..identify.noise import ARNoise, AutoNoise, WhiteNoise
    from ..identify.search import JointSearch

    if args.prior_rel_std is not None:
        rel: Any = args.prior_rel_std
    else:
        rel = read_uncertainty_toml(args.drive) or None
    interval: Any = FisherInterval() if args.interval == "fisher" else ProfileLikelihood()
    if args.bootstrap is not None:
        seed = {} if args.seed is None else {"seed": args.seed}
        # a bar on stderr unless --quiet; the library draws it only on a terminal
        interval = ParametricBootstrap(args.bootstrap, **seed, progress=not args.quiet,
                                       jobs=args.jobs)
    order = {} if args.noise_order is None else {"order": args.noise_order}
    noise_model: Any = WhiteNoise()
    if args.noise == "ar":
        noise_model = ARNoise(**order)
    elif args.noise in (None, "auto"):
        noise_model = AutoNoise(**order)
    terms: dict[str, Any] = {}
    if args.friction is not None:
        terms["friction"] = args.friction
    if args.current_loop is not None:
        terms["actuator"] = _current_loop(args.current_loop)
    elif (known := read_actuator_toml(args.drive)) is not None:  # as simulate reads it
        terms["actuator"] = known
    return JointIdentifier(prior, prior_rel_std=rel, interval=interval,
                           noise_model=noise_model, **terms,
                           search=JointSearch(final_horizon=args.final_horizon),
                           allow_far_from_prior=args.allow_far_from_prior,
                           progress=not args.quiet)


def _current_loop(text: str) -> Any:
    """``--current-loop``: "auto", "none" or a time constant in s."""
    from ..actuator import CurrentLoop

    if text in ("auto", "none"):
        return None if text == "none" else "auto"
    try:
        tau = float(text)
    except ValueError:
        raise InputError(f"--current-loop must be auto, none or a time constant in s, got "
                         f"{text!r}") from None
    try:
        return CurrentLoop(tau_i=tau)
    except InputError as exc:
        raise InputError(f"--current-loop: {exc}") from None


def _fit_joint(args: argparse.Namespace, prior: Any, records: list[Record],
               finals: list[Record] | None) -> tuple[Any, dict[str, Any]]:
    everything = records + (finals or [])
    est = _joint_identifier(args, prior).fit(everything)
    per_record = []
    rows = zip(everything, est.fit_percent_, est.model_start_, est.noise_std_,
               est.commutations_, est.residual_lag1_, est.held_noise_lag1_, strict=True)
    for k, (rec, fitp, how, noise, (t_s, t_c, t_b), lag1, held) in enumerate(rows):
        per_record.append(
            {"file": rec.name, "t_s": t_s, "t_c": t_c, "t_b": t_b,
             "theta_ini": None, "fit_percent": [float(x) for x in fitp],
             "model_start": how, "noise_std": [float(x) for x in noise],
             "noise_ar": None if est.noise_ar_ is None else est.noise_ar_[k].tolist(),
             "residual_lag1": [float(x) for x in lag1],
             "held_noise_lag1": [_num(x) for x in held],
             "commutation": "model"}
        )
    extra = {
        "interval": est.interval_,
        "ci95_bounded": list(est.ci95_bounded_),
        "ambiguous": est.ambiguous_,
        "rival_basins": est.rival_basins_,
        "misfit_restarted": est.misfit_restarted_,
        "misfit_restart_won": est.misfit_restart_won_,
        "noise_model": noise_label(est.noise_ar_),
        "residuals_correlated": est.correlation_message() is not None,
        "final_horizon": est.search.final_horizon,
        "std_fisher": est.param_std_["theta"],
        "params": est.params_,
        "estimated": list(est.estimated_),
        "param_std": est.param_std_,
        # fc_M and fc_L are often determined mostly by their sum: their stds alone hide it
        "correlation": _correlation(est.covariance_),
        "prior_rel_std": est.prior_rel_std,
        "far_from_prior": est.far_from_prior_,
        "prior_pull": est.prior_pull_,
        **_terms_json(est),
    }
    return est, {"theta_ini": est.theta_ini_, "per_record": per_record,
                 "bounds": [float(x) for x in est.search.grid.bounds],
                 "std": est.std_, "ci95": [float(x) for x in est.ci95_], "extra": extra}


def _terms_json(est: Any) -> dict[str, Any]:
    """What the model chose of friction and current loop, with standard errors (None
    where a value was not estimated)."""
    out: dict[str, Any] = {"friction": est.friction_}
    for name in ("fc_M", "fc_L", "tau_i"):
        out[name] = est.params_[name]
        out[f"{name}_std"] = _num(est.param_std_.get(name))
    out["model_choices"] = [c.reason() for c in est.choices_]
    out["model_tests"] = [_test_json(c) for c in est.choices_]
    out["measured"] = list(est.measured_)
    return out


def _correlation(cov: Any) -> list[list[float | None]]:
    """The estimates' correlation matrix (order ``estimated``; None where a std is 0)."""
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    # a std of 0 (a parameter held) divides to inf or nan, and inf + -inf below too
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
        corr = (corr + corr.T) / 2  # symmetric and 1 on the diagonal to the last digit
    np.fill_diagonal(corr, np.where(std > 0, 1.0, np.nan))
    return [[_num(x) for x in row] for row in corr]


def _given(args: argparse.Namespace, **names: str) -> dict[str, Any]:
    """The library keywords of ``names`` (keyword -> attribute of ``args``) that the
    user set: the others keep the library's defaults."""
    return {k: getattr(args, a) for k, a in names.items() if getattr(args, a) is not None}


def _fit_two_step(args: argparse.Namespace, prior: Any, records: list[Record],
                  finals: list[Record] | None) -> tuple[Any, dict[str, Any]]:
    options = _given(args, n_theta="n_theta", cutoff_motor="cutoff_motor",
                     cutoff_load="cutoff_load", onset="onset", friction="friction")
    est = TwoStepIdentifier(prior, allow_far_from_prior=args.allow_far_from_prior,
                            **options).fit(records, final_records=finals)
    rows = zip(records, est.commutations_, est.theta_ini_per_record_,
               est.held_speed_gains_[: len(records)], strict=True)
    per_record = [{"file": rec.name, "t_s": com.t_s, "t_c": com.t_c, "t_b": com.t_b,
                   "theta_ini": ini, "held_speed_gain": gain}
                  for rec, com, ini, gain in rows]
    return est, {"theta_ini": est.theta_ini_, "per_record": per_record,
                 "bounds": list(est.bounds_),
                 "extra": {"onset": est.onset, **_friction_json(est)}}


def _fit_regression(args: argparse.Namespace, prior: Any, records: list[Record],
                    finals: list[Record] | None) -> tuple[Any, dict[str, Any]]:
    est = RegressionIdentifier(prior, allow_far_from_prior=args.allow_far_from_prior,
                               **_given(args, friction="friction")).fit(records)
    per_record = [{"file": rec.name, "t_s": t_s, "t_c": None, "t_b": None, "theta_ini": None,
                   "held_speed_gain": gain}
                  for rec, t_s, gain in zip(records, est.t_s_, est.held_speed_gains_,
                                            strict=True)]
    return est, {"theta_ini": None, "per_record": per_record,
                 "bounds": [0.0, float(est.theta_max)], "extra": _friction_json(est)}


def _friction_json(est: Any) -> dict[str, Any]:
    """The friction model of paper A's methods (no standard errors: they have none)."""
    return {"friction": est.friction_, "fc_M": est.fc_M_, "fc_L": est.fc_L_}


def _notes(args: argparse.Namespace, est: Any, caught: list[warnings.WarningMessage],
           flags: dict[str, Any]) -> list[str]:
    """What the reader of the result must know, in the words of the command line (printed
    after theta, and the ``notes`` of ``--json``)."""
    out = []
    if getattr(est, "std_", None) is None:  # two-step, regression: a bounded search
        return (_noted(caught, flags, (SearchEdgeWarning,)) + _unread_table(args)
                + _unused_torques(est))
    if est.ci95_[0] == 0.0:
        out.append("the 95% interval of theta reaches 0: these records are consistent with a "
                   "drive without backlash (its upper end is the largest backlash they allow)")
    for end, bounded in zip(("lower", "upper"), est.ci95_bounded_, strict=True):
        if not bounded:
            out.append(f"the likelihood does not rise to the 95% level on the {end} side "
                       "within the search range: the records hardly bound theta there "
                       "(longer or less noisy records help)")
    if all(t_c is None for (_, t_c, _) in est.commutations_):
        out.append("in the identified model the shaft leaves its flank after no step-down: "
                   "these records hardly show the backlash (theta rests on the model alone; "
                   "a step-down to 0 that the speeds follow shows it)")
    out += _held_notes(est) + _dropped_prior(est)
    out += _noted(caught, flags, (PriorMismatchWarning,))
    out += _noted(caught, flags, (CorrelatedResidualsWarning,))
    out += _noted(caught, flags, (QuantisedSpeedsWarning,))
    rivals = (f"the 95% interval spans the profiles of the {est.rival_basins_} other "
              "minimum(s) within 3.84 of the best in -2 log L")
    if est.ambiguous_:
        out.append("the search ended in distinct minima of nearly equal cost (the likelihood "
                   "is multimodal on these records); "
                   + (rivals if est.rival_basins_ else "the interval describes the best one only")
                   + ": try --bootstrap N or longer records")
    elif est.rival_basins_:
        out.append(f"the likelihood has other minima near the best: {rivals}, so it is wider "
                   "than theta -+ 1.96 std (longer or less noisy records narrow it)")
    return out


def _unread_table(args: argparse.Namespace) -> list[str]:
    """Paper A's methods hold the prior's linear parameters: a table of their
    uncertainty is not read, which the reader must know."""
    if not read_uncertainty_toml(args.drive):
        return []
    return [f"the [uncertainty] table of {args.drive} is read by --method joint only: "
            f"--method {args.method} holds the linear parameters at the prior's values "
            "(paper A's method)"]


def _unused_torques(est: Any) -> list[str]:
    """Paper A's viscous model leaves out the Coulomb torques a drive file gives."""
    if est.friction_ != "viscous" or not (est.prior.fc_M or est.prior.fc_L):
        return []
    return ["the Coulomb torques fc_M, fc_L of the [drive] table are not in paper A's "
            "viscous model (--friction coulomb or auto fits them from there)"]


def _dropped_prior(est: Any) -> list[str]:
    """A prior on the Coulomb torques leaves with the friction the test dropped."""
    rel = est.prior_rel_std
    given = [n for n in ("fc_M", "fc_L") if isinstance(rel, dict) and n in rel]
    if not given or est.friction_ != "viscous" or est.friction == "viscous":
        return []
    return [f"the prior on {', '.join(given)} ([uncertainty]) was dropped with the Coulomb "
            "friction: the data do not call for it (its likelihood-ratio test); --friction "
            "coulomb keeps it"]


def _held_notes(est: Any) -> list[str]:
    """Which linear parameters the [uncertainty] table held at the prior's values."""
    rel = est.prior_rel_std
    held = [n for n in LINEAR_PARAMS if n not in est.estimated_]
    if not isinstance(rel, dict) or not held:
        return []
    out = []
    absent = [n for n in held if n not in rel]
    if absent:
        out.append(f"{', '.join(absent)} held at the prior's values: [uncertainty] "
                   f"lists {', '.join(sorted(rel)) or 'none'} only (list the others with "
                   "their relative std to estimate them, or remove the table to estimate "
                   "all)")
    exact = [n for n in held if n in rel]
    if exact:
        out.append(f"{', '.join(exact)} held at the prior's values: [uncertainty] gives "
                   f"{'it' if len(exact) == 1 else 'them'} a relative std of 0 (known "
                   "exactly)")
    return out
