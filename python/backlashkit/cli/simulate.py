"""``backlashkit simulate``: simulate a two-mass drive from the command line.

Two modes, exactly one of which is chosen:

* ``--torque TORQUE.csv``: simulate under a recorded motor torque (columns
  ``t,torque``) and write ``t,w_motor,w_load,phi_d`` on the same grid;
* ``--experiment KIND``: generate a synthetic experiment (``step-down``, paper A's,
  or ``step``, ``sine``, ``prbs``), simulate it from rest and write
  ``t,torque,w_motor,w_load`` -- the format ``backlashkit identify`` reads -- with
  optional white Gaussian noise on the speeds (``--snr-motor`` / ``--snr-load``,
  SNR defined as in :mod:`backlashkit.signals`).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import secrets
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from .. import signals
from .. import validate as v
from ..encoder import Encoder, measure_encoders
from ..errors import InputError, SensitivityWarning
from ..io import (
    check_plot_suffix,
    check_writable,
    read_actuator_toml,
    read_drive_toml,
    write_csv,
)
from ..laws import ShaftLaw
from .files import add_file_options, file_options, reader_errors
from .main import missing_directory

__all__ = ["add_parser", "run"]

EXPERIMENTS = ("step-down", "step", "sine", "prbs")
ALL = frozenset(EXPERIMENTS)

#: Experiment options: argparse dest -> (flag, experiments it applies to).
_OPTIONS: dict[str, tuple[str, frozenset[str]]] = {
    "amplitude": ("--amplitude", ALL),
    "hold": ("--hold", frozenset({"step-down"})),
    "level_after": ("--level-after", frozenset({"step-down"})),
    "step_time": ("--step-time", frozenset({"step"})),
    "frequency": ("--frequency", frozenset({"sine"})),
    "phase": ("--phase", frozenset({"sine"})),
    "bit_time": ("--bit-time", frozenset({"prbs"})),
    "ts": ("--ts", ALL),
    "duration": ("--duration", ALL),
    "snr_motor": ("--snr-motor", ALL),
    "snr_load": ("--snr-load", ALL),
    "seed": ("--seed", ALL),
}
_REQUIRED = {
    "step-down": ("amplitude", "hold"),
    "step": ("amplitude",),
    "sine": ("amplitude", "frequency"),
    "prbs": ("amplitude", "bit_time"),
}
DEFAULT_TS = 1e-3

_DESCRIPTION = """\
Simulate a two-mass drive with backlash, from rest: motor and load joined by an elastic
shaft with a dead zone (the model of paper A, Ravanbod-Shirazi & Besancon-Voda 2002).

With --torque, simulate under a recorded motor torque (columns t,torque) and write
t,w_motor,w_load,phi_d on the same grid. With --experiment, generate a synthetic
experiment and write t,torque,w_motor,w_load (the format identification reads), with
optional white Gaussian noise on the speeds; SNR = 10 log10(mean(w**2) / noise
variance) over the whole record. Units are SI (s, N m, rad, rad/s).
"""

_EPILOG = """\
examples:
  # paper A's step-down (0.157 N m for 40 s from rest, then 0), noisy speeds
  backlashkit simulate examples/paper_drive.toml --experiment step-down \\
      --amplitude 0.157 --hold 40 --snr-motor 30 --snr-load 30 --seed 1 --out exp.csv
  # a recorded torque
  backlashkit simulate examples/paper_drive.toml --torque examples/torque_example.csv \\
      --out response.csv --json
"""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``simulate`` subcommand.

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
        "simulate",
        help="simulate a two-mass drive with backlash (recorded torque or synthetic experiment)",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _add_input(p)
    _add_output(p)
    _add_model(p)
    _add_experiment_options(p)
    p.set_defaults(func=run)
    return p


def _add_input(p: argparse.ArgumentParser) -> None:
    """The drive file and the source of the torque (a file or an experiment)."""
    p.add_argument(
        "drive",
        metavar="DRIVE.toml",
        help="drive parameters: a [drive] table with J_M, J_L, k_sh, f_M, f_L, f_sh, theta "
        "(SI; theta is the backlash HALF-width in rad), optionally the Coulomb and breakaway "
        "torques fc_M, fc_L, fs_M, fs_L (N m), and an [actuator] table with the current "
        "loop's tau_i (s)",
    )
    src = p.add_argument_group("input (give exactly one)")
    src.add_argument(
        "--torque", metavar="TORQUE.csv", help="motor torque record, columns t (s), torque "
        "(N m): CSV (';', decimal commas), .mat or .npz, read as identify reads experiments"
    )
    add_file_options(p.add_argument_group("reading the torque file (with --torque)"),
                     columns_help="the file's names of our columns t, torque, e.g. "
                     "'t=time,torque=M'")
    src.add_argument(
        "--experiment",
        choices=EXPERIMENTS,
        help="generate a synthetic experiment from rest (step-down: a torque held, then "
        "dropped, what identify reads)",
    )


def _add_output(p: argparse.ArgumentParser) -> None:
    """Where the results go."""
    out = p.add_argument_group("output")
    out.add_argument(
        "--out",
        metavar="OUT.csv",
        required=True,
        help="output CSV: t,w_motor,w_load,phi_d (--torque) or t,torque,w_motor,w_load "
        "(--experiment)",
    )
    out.add_argument(
        "--plot",
        metavar="FILE",
        help="also save a plot of speeds, twist and shaft torque (format from the extension: "
        ".png, .svg, .pdf, .jpg)",
    )
    out.add_argument("--force", action="store_true", help="overwrite output files if they exist")
    out.add_argument(
        "--json", action="store_true", help="print a JSON summary on stdout (events, samples)"
    )


def _add_model(p: argparse.ArgumentParser) -> None:
    """The contact law and how the speeds are measured."""
    p.add_argument(
        "--law",
        choices=[law.value for law in ShaftLaw],
        default=ShaftLaw.PAPER.value,
        help="shaft contact law: paper (spring plus damper in contact, tau_c + tau_d: the "
        "damper may pull just before contact is lost; default), no-pull (the damper "
        "never pulls: max(tau_c + tau_d, 0), Modelica's ElastoBacklash2) or modelica "
        "(Modelica's ElastoBacklash: tau_c + min(tau_c, tau_d), 0 where tau_c + tau_d <= 0)",
    )
    enc = p.add_argument_group("measurement")
    enc.add_argument(
        "--encoder",
        type=float,
        metavar="N",
        help="measure the speeds as an encoder of N counts per revolution (>= 1) does: "
        "differences of counts over the sample time; adds columns count_motor, count_load",
    )
    enc.add_argument(
        "--speed-filter",
        type=float,
        metavar="TAU",
        help="with --encoder: first-order filter of the encoder speeds, time constant TAU "
        "in s (the drive's speed observer; default none; identify does not model it)",
    )


def _add_experiment_options(p: argparse.ArgumentParser) -> None:
    """The options of the synthetic experiments."""
    exp = p.add_argument_group("experiment options (with --experiment)")
    exp.add_argument("--amplitude", type=float, metavar="A", help="torque level in N m (all)")
    exp.add_argument(
        "--hold",
        type=float,
        metavar="T_S",
        help="step-down: time in s the level A is held before stepping down "
        "(paper A's small step: --amplitude 0.157 --hold 40)",
    )
    exp.add_argument(
        "--level-after",
        type=float,
        metavar="B",
        help="step-down: level after T_S in N m (default 0)",
    )
    exp.add_argument(
        "--step-time", type=float, metavar="T0", help="step: instant of the step in s (default 0)"
    )
    exp.add_argument("--frequency", type=float, metavar="W", help="sine: frequency in rad/s")
    exp.add_argument("--phase", type=float, metavar="P", help="sine: phase in rad (default 0)")
    exp.add_argument("--bit-time", type=float, metavar="TB", help="prbs: duration of a bit in s")
    exp.add_argument(
        "--ts", type=float, metavar="TS", help=f"sample time in s (default {DEFAULT_TS:g})"
    )
    exp.add_argument(
        "--duration",
        type=float,
        metavar="D",
        help="record length in s (default 2 * T_S for step-down, 2 * T0 for step; required "
        "for sine and prbs)",
    )
    exp.add_argument(
        "--snr-motor", type=float, metavar="DB", help="add white noise to w_motor at this SNR (dB)"
    )
    exp.add_argument(
        "--snr-load", type=float, metavar="DB", help="add white noise to w_load at this SNR (dB)"
    )
    exp.add_argument(
        "--seed",
        type=int,
        metavar="S",
        help="seed of the noise and the prbs bits (default: a fresh one, reported)",
    )


def _encoder(args: argparse.Namespace) -> Encoder | None:
    """The --encoder / --speed-filter options as an Encoder (refusals in the library)."""
    if args.encoder is None:
        if args.speed_filter is not None:
            raise InputError("--speed-filter only applies with --encoder N")
        return None
    if args.snr_motor is not None or args.snr_load is not None:
        raise InputError(
            "--snr-motor/--snr-load add white noise to exact speeds; with --encoder the "
            "speeds are measured by the encoder: give one or the other"
        )
    try:
        return Encoder(args.encoder, 0.0 if args.speed_filter is None else args.speed_filter)
    except InputError as exc:
        flag = "--speed-filter" if "tau_w" in str(exc) else "--encoder"
        raise InputError(f"{flag}: {exc}") from None


def _note(message: str) -> None:
    print(f"backlashkit: {message}", file=sys.stderr)


def _read_torque(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray]:
    """The --torque file, read as identify reads experiments (its advice as flags)."""
    from ..identify.readers import read_torque

    with reader_errors():
        return read_torque(args.torque, **file_options(args))


def _check_source(args: argparse.Namespace) -> None:
    if (args.torque is None) == (args.experiment is None):
        which = "both were given" if args.torque is not None else "neither was given"
        raise InputError(
            f"give exactly one of --torque TORQUE.csv or --experiment KIND ({which})"
        )
    readers = [flag for flag, dest in (("--columns", "columns"), ("--sample-time", "sample_time"),
                                       ("--delimiter", "delimiter"), ("--decimal", "decimal"),
                                       ("--resample", "resample"))
               if getattr(args, dest) is not None]
    if readers and args.torque is None:
        verb = "applies" if len(readers) == 1 else "apply"
        raise InputError(f"{', '.join(readers)} only {verb} with --torque (reading its file)")
    given = [dest for dest in _OPTIONS if getattr(args, dest) is not None]
    if args.torque is not None:
        if given:
            flags = ", ".join(_OPTIONS[d][0] for d in given)
            verb = "applies" if len(given) == 1 else "apply"
            raise InputError(f"{flags} only {verb} with --experiment, not with --torque")
        return
    for dest in given:
        flag, kinds = _OPTIONS[dest]
        if args.experiment not in kinds:
            raise InputError(
                f"{flag} does not apply to --experiment {args.experiment} "
                f"(it applies to: {', '.join(k for k in EXPERIMENTS if k in kinds)})"
            )
    missing = [_OPTIONS[d][0] for d in _REQUIRED[args.experiment] if getattr(args, d) is None]
    if missing:
        raise InputError(f"--experiment {args.experiment} needs {', '.join(missing)}")


def _check_output(args: argparse.Namespace) -> Path:
    out = Path(args.out)
    if out.is_dir():
        raise InputError(f"--out {out} is a directory; give a file name")
    if not out.parent.is_dir():
        raise InputError(missing_directory("--out", out))
    if out.exists():
        if not args.force:
            raise InputError(f"--out {out} already exists; pass --force to overwrite it")
        inputs = [Path(args.drive)] + ([Path(args.torque)] if args.torque else [])
        for path in inputs:
            if path.exists() and out.resolve() == path.resolve():
                raise InputError(f"--out {out} is also an input file; choose another name")
    if args.plot is not None:
        plot = Path(args.plot)
        check_plot_suffix("--plot", plot)
        if not plot.parent.is_dir():
            raise InputError(missing_directory("--plot", plot))
        if plot.exists() and not args.force:
            raise InputError(f"--plot {plot} already exists; pass --force to overwrite it")
        if plot.resolve() == out.resolve():
            raise InputError("--plot and --out must be different files")
        check_writable(plot, "--plot")
    check_writable(out, "--out")
    return out


def _experiment(args: argparse.Namespace, seeds: list[np.random.SeedSequence]):
    """Time grid, torque and a description of the experiment."""
    kind = args.experiment
    ts = v.positive("--ts", DEFAULT_TS if args.ts is None else args.ts)
    amplitude = v.finite_scalar("--amplitude", args.amplitude)
    info: dict[str, Any] = {"kind": kind, "amplitude": amplitude, "ts": ts}
    default_duration = None
    if kind == "step-down":
        hold = v.positive("--hold", args.hold)
        default_duration = 2.0 * hold
    elif kind == "step":
        t0 = v.nonnegative("--step-time", 0.0 if args.step_time is None else args.step_time)
        default_duration = 2.0 * t0 if t0 > 0 else None
    if args.duration is None:
        if default_duration is None:
            extra = " (or a --step-time > 0)" if kind == "step" else ""
            raise InputError(f"--experiment {kind} needs --duration{extra}")
        duration = default_duration
    else:
        duration = v.positive("--duration", args.duration)
    if duration < ts:
        raise InputError(f"--duration must be at least --ts ({ts!r} s), got {duration!r} s")
    try:
        t = signals.time_grid(duration, ts)
    except InputError as exc:
        raise InputError(f"--duration / --ts: {exc}") from None
    info["duration"] = float(t[-1] - t[0])
    if kind == "step-down":
        if hold >= t[-1]:
            raise InputError(
                f"--hold ({hold!r} s) must be shorter than --duration ({duration!r} s), "
                "or the step-down is not recorded"
            )
        b = 0.0 if args.level_after is None else v.finite_scalar("--level-after", args.level_after)
        if not amplitude > b:
            raise InputError(
                f"--experiment step-down steps down from --amplitude to --level-after: the "
                f"amplitude ({amplitude!r} N m) must be above the level after "
                f"({b!r} N m)"
            )
        torque = signals.step_down(t, amplitude, t_s=hold, b=b)
        info.update(hold=hold, level_after=b)
    elif kind == "step":
        if t0 >= t[-1]:
            raise InputError(
                f"--step-time ({t0!r} s) must be shorter than --duration ({duration!r} s), "
                "or the step is not recorded"
            )
        torque = signals.step(t, amplitude, t_step=t0)
        info.update(step_time=t0)
    elif kind == "sine":
        phase = 0.0 if args.phase is None else v.finite_scalar("--phase", args.phase)
        try:
            torque = signals.sine(t, amplitude, args.frequency, phase=phase)
        except InputError as exc:
            raise InputError(f"--frequency: {exc}") from None
        info.update(frequency_rad_s=float(args.frequency), phase=phase)
    else:
        try:
            torque = signals.prbs(t, amplitude, bit_time=args.bit_time, seed=seeds[0])
        except InputError as exc:
            raise InputError(f"--bit-time: {exc}") from None
        info.update(bit_time=float(args.bit_time))
    return t, torque, info


def _add_noise(
    clean: np.ndarray, snr: float, seed: np.random.SeedSequence, flag: str, name: str
) -> tuple[np.ndarray, float]:
    snr = v.finite_scalar(flag, snr)
    try:
        noisy = signals.add_noise(clean, snr, rng=seed)
    except InputError as exc:
        raise InputError(f"{flag}: cannot add noise to {name}: {exc}") from None
    return noisy, signals.measure_snr_db(clean, noisy)


def run(args: argparse.Namespace) -> int:
    """Run ``backlashkit simulate`` with parsed arguments; return the exit status.

    Parameters
    ----------
    args : argparse.Namespace
        Arguments parsed by the parser of :func:`add_parser`.

    Returns
    -------
    int
        0 on success. Bad input raises :class:`InputError`, which
        :func:`backlashkit.cli.main` reports on one line with status 2.
    """
    _check_source(args)
    encoder = _encoder(args)
    out = _check_output(args)
    drive = read_drive_toml(args.drive, require_theta=True)
    actuator = read_actuator_toml(args.drive)
    seed = _Seed.of(args)
    if args.torque is not None:
        t, torque = _read_torque(args)
        source: dict[str, Any] = {"torque_file": str(args.torque)}
    else:
        t, torque, source = _experiment(args, seed.children)
        source = {"experiment": source}
    if seed.fresh:  # after the options are checked: a refused run has no seed to repeat
        _note(f"note: no --seed given; using --seed {seed.value}")
    elif args.seed is not None and not seed.children:
        _note("note: --seed has no effect: nothing random is drawn without --snr-motor, "
              "--snr-load or --experiment prbs")

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SensitivityWarning)
        response = drive.simulate(t, torque, law=args.law, actuator=actuator,
                                  positions=encoder is not None)
    columns, noise = _columns(args, response, seed, encoder)
    write_csv(out, columns, force=args.force)
    if args.plot is not None:
        # the speeds as written, where noise or an encoder made them differ
        written = (columns["w_motor"], columns["w_load"])
        measured = written if noise is not None or encoder is not None else None
        response.plot(measured=measured).savefig(args.plot)
        _note(f"wrote {args.plot}")
    _note_sampling(drive, response)
    n = int(response.t.size)
    _note(f"wrote {out} ({n} samples, {len(response.events)} contact events, law {args.law})")
    if args.json:
        summary = {
            "command": "simulate",
            "drive": str(args.drive),
            "law": args.law,
            # what was simulated, friction, loop and encoder included, as read
            "model": {**dataclasses.asdict(drive),
                      **dict(zip(("fs_M", "fs_L"), drive.to_chain().fs, strict=True)),
                      "tau_i": None if actuator is None else actuator.tau_i},
            "encoder": None if encoder is None else {
                "counts_per_rev": encoder.counts_per_rev, "speed_filter": encoder.tau_w},
            **source,
            "output": str(out),
            "columns": list(columns),
            **_response_summary(response),
            "noise": noise,
        }
        print(json.dumps(summary, allow_nan=False, default=_json_default))
    return 0


@dataclasses.dataclass(frozen=True)
class _Seed:
    """The run's seed: given, or fresh (and then reported) when noise or prbs bits need
    one; its children seed the prbs bits, the motor noise and the load noise."""

    value: int | None
    fresh: bool
    noisy: bool
    children: list[np.random.SeedSequence]

    @classmethod
    def of(cls, args: argparse.Namespace) -> _Seed:
        noisy = args.experiment is not None and (
            args.snr_motor is not None or args.snr_load is not None
        )
        needs_seed = noisy or args.experiment == "prbs"
        for flag, value in (("--snr-motor", args.snr_motor), ("--snr-load", args.snr_load)):
            if value is not None:
                v.finite_scalar(flag, value)
        seed = args.seed
        if seed is not None and seed < 0:
            raise InputError(f"--seed must be >= 0, got {seed}")
        fresh_seed = needs_seed and seed is None
        if fresh_seed:
            seed = secrets.randbits(63)
        seeds = np.random.SeedSequence(seed).spawn(3) if needs_seed else []
        return cls(seed, fresh_seed, noisy, seeds)


def _columns(args: argparse.Namespace, response, seed: _Seed,
             encoder: Encoder | None) -> tuple[dict[str, np.ndarray], dict[str, Any] | None]:
    """The output's columns, and the noise added to the speeds (``None`` without)."""
    noise: dict[str, Any] | None = None
    if args.torque is not None:
        columns = {
            "t": response.t,
            "w_motor": response.w_motor,
            "w_load": response.w_load,
            "phi_d": response.phi_d,
        }
    else:
        w_motor, w_load = response.w_motor, response.w_load
        if seed.noisy:
            w_motor, w_load, noise = _noisy_speeds(args, w_motor, w_load, seed)
        columns = {"t": response.t, "torque": response.torque, "w_motor": w_motor,
                   "w_load": w_load}
    if encoder is not None:
        columns = measure_encoders(response, encoder)
        if args.torque is not None:
            del columns["torque"]  # the input file holds it
    return columns, noise


def _noisy_speeds(args: argparse.Namespace, w_motor: np.ndarray, w_load: np.ndarray,
                  seed: _Seed) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """The speeds with the noise of --snr-motor / --snr-load, and its account."""
    # every key in every document, null for a speed left clean
    noise: dict[str, Any] = {"seed": seed.value, "snr_motor_db": None,
                             "measured_snr_motor_db": None, "snr_load_db": None,
                             "measured_snr_load_db": None}
    if args.snr_motor is not None:
        w_motor, measured = _add_noise(w_motor, args.snr_motor, seed.children[1], "--snr-motor",
                                       "w_motor")
        noise.update(snr_motor_db=float(args.snr_motor), measured_snr_motor_db=measured)
    if args.snr_load is not None:
        w_load, measured = _add_noise(w_load, args.snr_load, seed.children[2], "--snr-load",
                                      "w_load")
        noise.update(snr_load_db=float(args.snr_load), measured_snr_load_db=measured)
    return w_motor, w_load, noise


def _note_sampling(drive, response) -> None:
    """Notes on what the samples cannot show: ringing faster than the sample rate and
    near-grazing contacts."""
    omega = drive.ringing_frequency
    ts_out = float(response.t[1] - response.t[0])
    if ts_out * omega > math.pi:  # exact at the samples, but no sample shows it
        _note(
            f"note: the sample time {ts_out:.6g} s cannot resolve the drive's ringing at "
            f"{omega:.4g} rad/s (period {2 * math.pi / omega:.3g} s): identify refuses such "
            "records (a time column in ms reads as s)"
        )
    grazes = response.near_grazing
    if grazes:
        first = grazes[0]
        _note(
            f"note: {len(grazes)} near-grazing contact(s), first at t = {first.time:.6g} s "
            f"(margin {abs(first.margin):.3g}): the trajectory after it is sensitive to tiny "
            "changes of the inputs and parameters"
        )


def _response_summary(response) -> dict[str, Any]:
    """The --json keys that describe the simulated response."""
    n = int(response.t.size)
    grazes = response.near_grazing
    return {
        "n_samples": n,
        "ts": float((response.t[-1] - response.t[0]) / (n - 1)),
        "t_start": float(response.t[0]),
        "t_end": float(response.t[-1]),
        "n_events": len(response.events),
        "events": [dataclasses.asdict(e) for e in response.events],
        "near_grazing": len(grazes),
        "near_grazing_events": [
            {"time": g.time, "shaft": g.shaft, "margin": g.margin} for g in grazes
        ],
    }


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")

