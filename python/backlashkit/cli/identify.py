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
import json
import math
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..identify.record import Record
from ..identify.report import add_report_option, check_report_directory, maybe_write_report
from ..identify.step import find_step_down, held_speed_gain, is_far
from ..identify.two_step import RegressionIdentifier, TwoStepIdentifier
from ..io import read_drive_toml, read_uncertainty_toml
from .files import add_file_options, file_options, reader_errors
from .main import flag_names

__all__ = ["add_parser", "run"]

METHODS = ("two-step", "regression", "joint")
#: Method used without ``--method``: ``joint`` is the most accurate and the only one
#: with an uncertainty.
DEFAULT_METHOD = "joint"

_DESCRIPTION = """\
Identify the backlash half-width theta (rad) of a two-mass drive from torque
step-down experiments (paper A, Ravanbod-Shirazi & Besancon-Voda 2002).

two-step: commutation instants t_c, t_b by eq. 9, pre-estimate eq. 6 from
FIR-filtered speeds, then least squares on w_motor over [t_s, t_s + dt4] with theta
in theta_ini (1 +- n_theta). regression: the same least squares over [0, 15 deg]
without the pre-estimate (paper A's Table 2 baseline). joint (default): maximum likelihood over
theta AND the linear parameters, on every record and both speeds (each weighted by its
own noise level, estimated from the data), the prior entering as a Gaussian penalty
with the relative std of the [uncertainty] table of PRIOR.toml (or --prior-rel-std);
without either, the linear parameters are refined from the data alone. It reports the
standard error std (Fisher information) and a 95% interval ci95 of theta (profile
likelihood; --interval fisher: theta +- 1.96 std), and says when the residuals are
correlated from sample to sample (filtered speeds: --noise ar models the noise as
autoregressive instead of white); its t_c, t_b are the contact changes of the
identified model (located between samples), theta_ini is the eq. 6 pre-estimate it
also starts from.

Each EXP.csv holds columns t,torque,w_motor,w_load (SI) with one step-down of the
torque from a positive level (other names, separators, decimal commas, rpm, a sample
time instead of a time column, .mat and .npz files: see the reading options).
Paper A's protocol uses a small step (a_1) for the pre-estimate and a larger one
(a_2) for the least squares: give the latter with --final (the positional files are
then used for the pre-estimate only; the joint method fits all files together).
"""

_EPILOG = """\
examples:
  backlashkit simulate examples/paper_drive.toml --experiment step-down \\
      --amplitude 0.157 --hold 40 --snr-motor 30 --snr-load 30 --seed 1 --out exp.csv
  backlashkit identify exp.csv --drive examples/paper_drive.toml --json
  backlashkit identify exp.csv --drive examples/paper_drive.toml --method joint
"""


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
        help="prior linear parameters: [drive] with J_M, J_L, k_sh, f_M, f_L, f_sh (SI); "
        "theta, if present, is ignored",
    )
    p.add_argument("--method", choices=METHODS, default=DEFAULT_METHOD,
                   help=f"default {DEFAULT_METHOD}")
    p.add_argument(
        "--final",
        metavar="EXP.csv",
        action="append",
        help="two-step: experiment(s) for the final least squares (paper A's step 2, "
        "a_2 = 0.6 a_max); default the positional files; joint: fitted with the positional "
        "files. May be repeated",
    )
    p.add_argument(
        "--n-theta", type=float, default=None, help="two-step: relative search half-width "
        "around theta_ini (default 0.1)"
    )
    p.add_argument(
        "--cutoff-motor", type=float, default=None, help="two-step: FIR cut-off for w_motor in "
        "rad/s (default 50)"
    )
    p.add_argument(
        "--cutoff-load", type=float, default=None, help="two-step: FIR cut-off for w_load in "
        "rad/s (default 20)"
    )
    p.add_argument(
        "--onset", choices=("constant", "unloading"), default=None,
        help="two-step: load speed before t_c in eq. 9: constant (paper, default) or the "
        "unloading shaft's cubic fall (exact t_c on noise-free data; no better with noise)"
    )
    p.add_argument(
        "--allow-far-from-prior", action="store_true",
        help="answer even when a linear parameter ends more than 5 times off the prior "
        "(joint), or the speeds under the torque held before the step-down are more than 5 "
        "times the prior's (two-step, regression) (default: refused, a unit or column "
        "mistake being likelier)"
    )
    p.add_argument(
        "--prior-rel-std", type=float, default=None, metavar="REL",
        help="joint: relative std of every linear parameter of the prior (overrides the "
        "[uncertainty] table; 0 = known exactly)"
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
                   help="joint --bootstrap: seed of the resamples' noise (default 0)")
    p.add_argument(
        "--noise", choices=("auto", "white", "ar"), default=None,
        help="joint: measurement noise model, white, autoregressive (for filtered "
        "speeds, whose noise is correlated from sample to sample: the residuals are "
        "whitened, the interval widened accordingly) or auto (default: autoregressive "
        "where the speeds' noise on the level held before the step-down is correlated)"
    )
    p.add_argument("--noise-order", type=int, default=None, metavar="P",
                   help="joint --noise ar or auto: order of the autoregressive model "
                   "(default 2)")
    p.add_argument(
        "--final-horizon", type=float, default=None, metavar="S",
        help="joint: final fit and interval on S seconds after the start and every torque "
        "jump of each record instead of the whole record (where the shaft rattles: "
        "better calibrated intervals, larger std)"
    )
    g = p.add_argument_group("reading the experiment files (all files alike)")
    add_file_options(g, columns_help="the file's names of our columns t, torque, w_motor, "
                     "w_load, e.g. 't=time,w_motor=n_mot,w_load=n_load' (unmapped ones keep "
                     "our names)")
    g.add_argument("--speed-unit", choices=("rad/s", "rpm"), default="rad/s",
                   help="unit of the speeds in the files; rpm are converted (default rad/s)")
    g.add_argument("--torque-levels", action="store_true",
                   help="replace a noisy measured torque by its piecewise-constant levels "
                   "(the model takes the torque as its exact input; default: a noisy torque "
                   "is an error)")
    p.add_argument("--json", action="store_true", help="print only a JSON object on stdout")
    add_report_option(p)
    p.set_defaults(func=run)
    return p


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
    from ..errors import InputError
    from ..identify.readers import read_records

    options = file_options(args)
    out: list[Record] = []
    for path in paths:
        if path == "-":
            raise InputError("'-': identify reads files, not the standard input; give a "
                             "file name (or /dev/stdin)")
        with reader_errors():
            out += read_records(path, speed_unit=args.speed_unit, **options)
    return out


#: More separate step-downs (each beyond a tenth of the largest) than this in one record
#: are no step-down experiment (a PRBS was fitted to 70 % with a standard error 1e-8).
MAX_STEP_DOWNS = 3


def _check_step_down_experiment(rec: Record, prior: Any) -> int:
    """The contract: a held torque stepped down, and at least two periods of the prior's
    ringing recorded after the step-down (the passage through the backlash takes about
    one; a record that ends at the step-down shows none). Returns the number of separate
    step-downs."""
    from ..errors import InputError
    from ..identify.torque import JUMP_THRESHOLD, torque_noise_std

    i_s, t_s, _, _ = find_step_down(rec)
    period = 2.0 * math.pi / math.sqrt(prior.k_sh * (1.0 / prior.J_M + 1.0 / prior.J_L))
    need = max(2.0 * period, 10 * rec.ts)
    if rec.t[-1] - t_s < need:
        raise InputError(
            f"{rec.name}: the record ends {rec.t[-1] - t_s:.3g} s after the step-down at "
            f"t = {t_s:.6g} s: record at least {need:.3g} s after it (two periods of the "
            "prior's ringing), so that the passage through the backlash is seen"
        )
    # a step-down drops from a held level (perhaps along a short ramp): a sine or a
    # random input also has a largest drop, but no level the shaft rests on before it
    n = int(round(need / rec.ts))
    u = rec.torque
    noise = torque_noise_std(u)
    before = u[max(0, i_s - 2 * n) : i_s]
    if before.size > n:  # some n samples within the 2n before the drop must be a level
        drop = float(u[max(0, i_s - n)] - u[min(u.size - 1, i_s + n)])
        windows = np.lib.stride_tricks.sliding_window_view(before, n)
        wobble = float(np.min(np.ptp(windows, axis=1)))
        if wobble > 0.05 * abs(drop) + JUMP_THRESHOLD * noise:
            raise InputError(
                f"{rec.name}: the torque is not held before its largest drop at "
                f"t = {t_s:.6g} s (over any {need:.3g} s of the {2 * need:.3g} s before it, it "
                f"varies by {wobble:.3g} N m or more): the identification needs paper A's "
                "experiment, a held torque stepped down"
            )
    downs = np.diff(u)  # separate drops beyond a tenth of the largest and the noise
    jump = JUMP_THRESHOLD * math.sqrt(2.0) * noise  # as find_step_down counts a drop
    big = np.flatnonzero(downs < min(0.1 * downs.min(), -jump))
    count = 1 + int(np.sum(np.diff(big) > 1)) if big.size else 0  # separate jumps
    if count > MAX_STEP_DOWNS:
        raise InputError(
            f"{rec.name}: the torque steps down {count} times (a random or periodic input?): "
            "the identification needs paper A's experiment, one step-down per record; split "
            "the record"
        )
    return count


def _refuse_duplicates(records: list[Record]) -> None:
    """Refuse a record given twice: the joint fit would count its data twice and
    report a standard error too small by sqrt(2)."""
    from ..errors import InputError

    seen: dict[bytes, str] = {}
    for rec in records:
        key = b"".join(np.ascontiguousarray(x, float).tobytes()
                       for x in (rec.t, rec.torque, rec.w_motor, rec.w_load))
        if key in seen:
            raise InputError(
                f"{rec.name} holds the same data as {seen[key]}: give every record once "
                "(the joint fit would count it twice and understate the uncertainty)"
            )
        seen[key] = rec.name


#: An estimated linear parameter (or held speed) identify.FAR_FROM_PRIOR times off its
#: prior (either way) is noted; this many times off refuses the answer, unless
#: --allow-far-from-prior: a prior that far off is rarer than a unit or column mistake
#: (rpm read as rad/s moves J_M x0.1, swapped speeds J_M x6 and k_sh x6), whose theta
#: means nothing.
REFUSE_FROM_PRIOR = 5.0


#: A fit this close to 100 % (rms residual over the speed's spread) leaves no noise to
#: model: a measured speed has noise far above it (a 16-bit encoder: about 1e-5).
NOISE_FREE = 1e-7


def _far_from_prior(est, prior, factor: float) -> list[str]:
    """The estimated linear parameters more than ``factor`` times off the prior."""
    return [name for name in est.estimated_[1:]
            if is_far(est.params_[name] / getattr(prior, name), factor)]


_CHECK_UNITS = ("check the units of the speeds (rpm read as rad/s?) and of the time, the "
                "columns (w_motor and w_load swapped?) and PRIOR.toml")


def _check_held_speeds(records: list[Record], prior: Any, *, allow: bool) -> list[str]:
    """The two-step and regression methods simulate the prior from the speed held before
    the step-down; a record in other units, or a prior far off, makes that meaningless.
    A :func:`~backlashkit.identify.held_speed_gain` more than ``REFUSE_FROM_PRIOR``
    times off 1 (or negative) is refused unless ``allow``, one more than
    ``FAR_FROM_PRIOR`` times off is noted. Returns the notes."""
    from ..errors import InputError

    notes = []
    for rec in records:
        gain = held_speed_gain(rec, prior)
        if not math.isfinite(gain):  # too few samples before the step-down to tell
            continue
        what = (f"{rec.name}: under the torque held before the step-down at t = "
                f"{find_step_down(rec)[1]:.6g} s the speeds are {gain:.3g} times the prior's")
        if is_far(gain, REFUSE_FROM_PRIOR) and not allow:
            raise InputError(
                f"{what} (this method simulates the prior from them): {_CHECK_UNITS}; if "
                "the prior's frictions are that far off, use --method joint (it estimates "
                "them) or pass --allow-far-from-prior"
            )
        if is_far(gain):
            notes.append(f"{what}: {_CHECK_UNITS}")
    return notes


def _ratios(est, prior, names: list[str]) -> str:
    """``J_M x0.103, k_sh x6.4``: the estimates of ``names`` over the prior's values."""
    return ", ".join(f"{n} x{est.params_[n] / getattr(prior, n):.3g}" for n in names)


def _notes(args: argparse.Namespace, est: Any, prior: Any, bounds: list[float],
           rel: Any) -> list[str]:
    """What the reader of the result must know, in the words of the command line (printed
    after theta, and the ``notes`` of ``--json``)."""
    out = []
    if getattr(est, "std_", None) is None:  # two-step, regression: a bounded search
        for end, edge in zip(("lower", "upper"), bounds, strict=True):
            if abs(est.theta_ - edge) <= 1e-6 * max(bounds[1], 1e-300):
                hint = " (widen --n-theta)" if args.method == "two-step" else ""
                out.append(f"theta is at the {end} end of the search interval: the cost's "
                           f"minimum may lie beyond it{hint}")
        return out
    for end, bounded in zip(("lower", "upper"), est.ci95_bounded_, strict=True):
        if not bounded:
            out.append(f"the likelihood does not rise to the 95% level on the {end} side "
                       "within the search range: the records hardly bound theta there "
                       "(longer or less noisy records help)")
    if all(t_c is None for (_, t_c, _) in est.commutations_):
        out.append("in the identified model the shaft leaves its flank after no step-down: "
                   "these records hardly show the backlash (theta rests on the model alone; "
                   "a step-down to 0 that the speeds follow shows it)")
    held = [n for n in est.params_ if n not in est.estimated_]
    if isinstance(rel, dict) and held:
        absent = [n for n in held if n not in rel]
        if absent:
            out.append(f"{', '.join(absent)} held at the prior's values: [uncertainty] "
                       f"lists {', '.join(sorted(rel)) or 'none'} only (list the others with "
                       "their relative std to estimate them, or remove the table to estimate "
                       "all)")
        exact = [n for n in held if n in rel]
        if exact:
            out.append(f"{', '.join(exact)} held at the prior's values: [uncertainty] gives "
                       "them a relative std of 0 (known exactly)")
    far = est.far_from_prior_  # FAR_FROM_PRIOR times off
    if far:
        out.append(f"{_ratios(est, prior, far)} of the prior: {_CHECK_UNITS}")
    message = est.correlation_message()
    misfit = 1.0 - float(np.min(est.fit_percent_)) / 100.0  # rms residual / spread
    if misfit < NOISE_FREE:  # a residual this small is no noise, white or coloured
        out.append(f"the model reproduces every speed to {max(misfit, 1e-16):.1g} of its "
                   "spread (noise-free, simulated records?): the residual is numerical "
                   "error, so std and interval only say that theta is determined to that "
                   "precision")
        message = None
    if message is not None:
        message = message.replace("fit with noise_model=ARNoise()", "try --noise ar")
        message = message.replace("ARNoise would hide", "--noise ar would hide")
        out.append(message.replace("raise the order", "raise --noise-order"))
    if est.ambiguous_:
        out.append("the search ended in distinct minima of nearly equal cost (the likelihood "
                   "is multimodal on these records); the interval describes the best one "
                   "only: try --bootstrap N or longer records")
    return out


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


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
    flags = dict(_FLAGS)
    if args.prior_rel_std is not None:  # else the [uncertainty] table gave the values
        flags["prior_rel_std"] = "--prior-rel-std"
    from ..errors import PriorMismatchWarning

    with flag_names(flags), warnings.catch_warnings():
        # the command notes or refuses a prior mismatch itself, with its flags
        warnings.simplefilter("ignore", PriorMismatchWarning)
        return _run(args)


#: Library parameters set from a flag of ``identify`` -> the flag.
_FLAGS = {
    "n_theta": "--n-theta", "cutoff_motor": "--cutoff-motor", "cutoff_load": "--cutoff-load",
    "n_resamples": "--bootstrap", "seed": "--seed", "final_horizon": "--final-horizon",
    "sample_time": "--sample-time", "order": "--noise-order",
}


def _run(args: argparse.Namespace) -> int:
    from ..errors import InputError

    if args.report is not None:  # before the fit, not after it
        if not args.report.strip():
            raise InputError("--report needs a directory name, got an empty one")
        check_report_directory(Path(args.report), force=bool(args.force))
    prior = read_drive_toml(args.drive, require_theta=False)
    prior = prior.with_theta(None) if prior.theta is not None else prior
    records = read_experiments(args, args.records)
    finals = None if not args.final else read_experiments(args, args.final)
    read_notes: list[str] = []
    if args.torque_levels:
        from ..identify.torque import torque_levels

        for group in (records, finals or []):
            for k, rec in enumerate(group):
                try:
                    group[k] = torque_levels(rec)
                except InputError as exc:  # a ramp: the library's name -> the flag
                    raise InputError(str(exc).replace("torque_levels", "--torque-levels", 1)
                                     ) from None
                if group[k] is rec:
                    read_notes.append(f"{rec.name}: the torque is piecewise constant already; "
                                      "--torque-levels left it as it is")
                    continue
                levels = np.unique(group[k].torque).size
                if levels == 1:
                    raise InputError(
                        f"{rec.name}: --torque-levels found one level only: the torque never "
                        "changes by more than 8 noise std from one sample to the next (a slow "
                        "ramp?); give the torque command (the set-point) instead")
                removed = float(np.sqrt(np.mean((rec.torque - group[k].torque) ** 2)))
                read_notes.append(
                    f"{rec.name}: torque replaced by its {levels} piecewise-constant levels "
                    f"(the removed noise has an rms of {removed:.3g} N m)")
    for rec in records + (finals or []):  # the identifiers check the rest
        if _check_step_down_experiment(rec, prior) > 1:  # the contract: one per record
            t_s = find_step_down(rec)[1]
            read_notes.append(
                f"{rec.name}: the torque steps down more than once; t_s, t_c, t_b and the "
                f"pre-estimate (eq. 6) use the largest step-down, at t = {t_s:.6g} s (the "
                "contract is one step-down per record: split the record to use the others)")
    per_record: list[dict[str, Any]] = []
    std: float | None = None
    ci95: list[float] | None = None
    extra: dict[str, Any] = {}
    for option, value in (("--bootstrap", args.bootstrap), ("--interval", args.interval),
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
    if args.method != "joint":  # the joint fit estimates the frictions: checked after it
        from ..identify.record import as_records

        as_records(records + (finals or []), prior=prior)  # the identifiers' checks first
        read_notes += _check_held_speeds(records + (finals or []), prior,
                                         allow=args.allow_far_from_prior)
    if args.method == "joint":
        from ..identify.joint import JointIdentifier

        if args.prior_rel_std is not None:
            rel: Any = args.prior_rel_std
        else:
            rel = read_uncertainty_toml(args.drive) or None
        everything = records + (finals or [])
        _refuse_duplicates(everything)
        from ..errors import CorrelatedResidualsWarning
        from ..identify.intervals import FisherInterval, ParametricBootstrap, ProfileLikelihood
        from ..identify.noise import ARNoise, AutoNoise, WhiteNoise

        seed = 0 if args.seed is None else args.seed
        if seed < 0:  # the library's message would offer a SeedSequence
            raise InputError(f"--seed must be >= 0, got {seed}")
        if args.bootstrap is not None and args.interval is not None:
            raise InputError("give --interval or --bootstrap, not both")
        interval: Any = FisherInterval() if args.interval == "fisher" else ProfileLikelihood()
        if args.bootstrap is not None:
            interval = ParametricBootstrap(args.bootstrap, seed=seed)
        if args.noise_order is not None and args.noise == "white":
            raise InputError("--noise-order only applies with --noise ar or auto")
        order = 2 if args.noise_order is None else args.noise_order
        noise_model: Any = WhiteNoise()
        if args.noise == "ar":
            noise_model = ARNoise(order)
        elif args.noise in (None, "auto"):
            noise_model = AutoNoise(order)
        est = JointIdentifier(prior, prior_rel_std=rel, interval=interval,
                              noise_model=noise_model, final_horizon=args.final_horizon)
        with warnings.catch_warnings():  # said below, as a note, or in the JSON
            warnings.simplefilter("ignore", CorrelatedResidualsWarning)
            est.fit(everything)
        very_far = _far_from_prior(est, prior, REFUSE_FROM_PRIOR)
        if very_far and not args.allow_far_from_prior:
            raise InputError(
                f"the fit moved {_ratios(est, prior, very_far)} from the prior: "
                f"{_CHECK_UNITS}; if the prior is that far off, pass --allow-far-from-prior"
            )
        theta_ini = est.theta_ini_
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
        bounds = [float(est.theta_max / est.n_grid), float(est.theta_max)]
        std = est.std_
        ci95 = [float(x) for x in est.ci95_]
        extra = {
            "interval": est.interval_,
            "ci95_bounded": list(est.ci95_bounded_),
            "ambiguous": est.ambiguous_,
            "misfit_restarted": est.misfit_restarted_,
            "misfit_restart_won": est.misfit_restart_won_,
            "noise_model": ("white" if est.noise_ar_ is None
                            else f"ar({est.noise_ar_.shape[-1]})"),
            "residuals_correlated": est.correlation_message() is not None,
            "final_horizon": est.final_horizon,
            "std_fisher": est.param_std_["theta"],
            "params": est.params_,
            "estimated": list(est.estimated_),
            "param_std": est.param_std_,
            "prior_rel_std": rel,
            "far_from_prior": est.far_from_prior_,
        }
    elif args.method == "two-step":
        est = TwoStepIdentifier(
            prior,
            n_theta=0.1 if args.n_theta is None else args.n_theta,
            cutoff_motor=50.0 if args.cutoff_motor is None else args.cutoff_motor,
            cutoff_load=20.0 if args.cutoff_load is None else args.cutoff_load,
            onset="constant" if args.onset is None else args.onset,
        ).fit(records, final_records=finals)
        theta_ini: float | None = est.theta_ini_
        rows = zip(records, est.commutations_, est.theta_ini_per_record_,
                   est.held_speed_gains_[: len(records)], strict=True)
        for rec, com, ini, gain in rows:
            per_record.append(
                {"file": rec.name, "t_s": com.t_s, "t_c": com.t_c, "t_b": com.t_b,
                 "theta_ini": ini, "held_speed_gain": gain}
            )
        bounds = list(est.bounds_)
        extra["onset"] = est.onset
    else:
        if args.final:
            raise InputError("--final only applies with --method two-step")
        est = RegressionIdentifier(prior).fit(records)
        theta_ini = None
        for rec, t_s, gain in zip(records, est.t_s_, est.held_speed_gains_, strict=True):
            per_record.append(
                {"file": rec.name, "t_s": t_s, "t_c": None, "t_b": None, "theta_ini": None,
                 "held_speed_gain": gain}
            )
        bounds = [0.0, float(RegressionIdentifier(prior).theta_max)]
    report = maybe_write_report(args, records, est, prior, final_records=finals)
    notes = read_notes + _notes(args, est, prior, bounds, rel if args.method == "joint" else None)
    result = {
        "command": "identify",
        "method": args.method,
        "drive": str(args.drive),
        "theta": _num(est.theta_),
        "theta_deg": _num(math.degrees(est.theta_)),
        "theta_ini": _num(theta_ini),
        "std": _num(std),
        "ci95": ci95,
        "search_interval": bounds,
        "cost": _num(est.cost_),
        "records": per_record,
        "final_records": [r.name for r in finals] if finals else None,
        "report": str(report) if report else None,
        **extra,
        "notes": notes,
    }
    if args.json:
        print(json.dumps(result, allow_nan=False))
        return 0
    out = sys.stdout
    print(f"method {args.method}; theta is the backlash HALF-width", file=out)
    print(f"{'file':<30} {'t_s (s)':>10} {'t_c (s)':>10} {'t_b (s)':>10} {'theta_ini (rad)':>16}",
          file=out)
    for row in per_record:
        cells = [f"{row[k]:10.4f}" if row[k] is not None else f"{'-':>10}"
                 for k in ("t_s", "t_c", "t_b")]
        ini = f"{row['theta_ini']:16.5g}" if row["theta_ini"] is not None else f"{'-':>16}"
        print(f"{row['file'][-30:]:<30} {' '.join(cells)} {ini}", file=out)
    if theta_ini is not None:
        print(f"theta_ini = {theta_ini:.5g} rad ({math.degrees(theta_ini):.4g} deg)", file=out)
    if std is None:
        print(f"theta     = {est.theta_:.5g} rad ({math.degrees(est.theta_):.4g} deg), "
              f"searched in [{bounds[0]:.4g}, {bounds[1]:.4g}] rad; no uncertainty for this "
              "method", file=out)
        for note in notes:
            print(f"note: {note}", file=out)
    else:
        how = {"fisher": " (Fisher)", "profile": " (profile likelihood)"}.get(est.interval_, "")
        if est.interval_ == "bootstrap":
            how = f" (parametric bootstrap, {est.bootstrap_thetas_.size} refits)"
        if est.final_horizon is not None:
            how += f" (fitted on {est.final_horizon:g} s after each torque jump)"
        print(f"theta     = {est.theta_:.5g} rad ({math.degrees(est.theta_):.4g} deg), "
              f"std {std:.3g} rad, 95% interval [{ci95[0]:.5g}, {ci95[1]:.5g}] rad{how}",
              file=out)
        for note in notes:
            print(f"note: {note}", file=out)
        for name in est.estimated_[1:]:
            print(f"{name:<9} = {est.params_[name]:.5g} (std {est.param_std_[name]:.3g})",
                  file=out)
        for rec, (a, b), (sm, sl) in zip(records + (finals or []), est.fit_percent_,
                                          est.noise_std_, strict=True):
            print(f"{rec.name[-30:]:<30} fit % (w_M, w_L) = ({a:.1f}, {b:.1f}); noise std = "
                  f"({sm:.3g}, {sl:.3g}) rad/s", file=out)
    return 0
