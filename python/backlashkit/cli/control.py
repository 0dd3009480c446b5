"""``backlashkit control SCENARIO.toml``: adaptive backlash-inverse control (paper B)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..errors import InputError
from ..io import check_plot_suffix, check_writable
from .main import missing_directory

__all__ = ["add_parser", "run"]

INVERSES = ("exact", "smooth-filter", "smooth-ramp", "none", "gain-only")


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``control`` subcommand.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The top-level subparsers.

    Returns
    -------
    argparse.ArgumentParser
        The subcommand's parser.
    """
    p = subparsers.add_parser(
        "control",
        help="simulate adaptive backlash-inverse control of a known plant (Tao & Kokotovic 1995)",
        description="Simulate the closed loop of a scenario file: known LTI plant, unknown "
        "input backlash, model-reference controller and adaptive backlash inverse.",
    )
    p.add_argument("scenario", metavar="SCENARIO.toml", help="scenario file")
    p.add_argument(
        "--inverse",
        choices=INVERSES,
        default=None,
        help="inverse to use (default: the file's [inverse] kind, else exact)",
    )
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("--trace", metavar="OUT.csv", help="write the trace (one row per ts)")
    p.add_argument("--plot", metavar="FILE",
                   help="save a figure (format from the extension: .png, .svg, .pdf, .jpg)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.set_defaults(func=run)
    return p


def _check_out(path: str | None, force: bool, flag: str, scenario: str) -> Path | None:
    if path is None:
        return None
    out = Path(path)
    if out.is_dir():
        raise InputError(f"{flag} {out} is a directory; give a file name")
    if out.exists() and not force:
        raise InputError(f"{flag} {out} already exists; pass --force to overwrite it")
    if out.exists() and out.resolve() == Path(scenario).resolve():
        raise InputError(f"{flag} {out} is the scenario file; choose another name")
    if not out.parent.is_dir():
        raise InputError(missing_directory(flag, out))
    check_writable(out, flag)
    return out


def run(args: argparse.Namespace) -> int:
    """Run ``backlashkit control``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments.

    Returns
    -------
    int
        Exit status (0).
    """
    from ..control.closed_loop import write_trace
    from ..control.scenario import load_scenario

    trace = _check_out(args.trace, args.force, "--trace", args.scenario)
    plot = _check_out(args.plot, args.force, "--plot", args.scenario)
    if plot is not None:
        check_plot_suffix("--plot", plot)
    if trace is not None and plot is not None and trace.resolve() == plot.resolve():
        raise InputError("--plot and --trace must be different files")
    sc = load_scenario(args.scenario)
    resp = sc.run(inverse=sc.make_inverse(args.inverse))
    if trace is not None:
        write_trace(trace, resp)
        print(f"backlashkit: wrote {trace}", file=sys.stderr)
    if plot is not None:
        resp.plot().savefig(plot)
        print(f"backlashkit: wrote {plot}", file=sys.stderr)
    summary = resp.summary()
    from ..delay.loops import mrc_delay_margin  # the linear loop, delay at the plant input

    summary["delay_margin"] = mrc_delay_margin(resp.design).as_dict()
    if args.json:
        json.dump(summary, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        c = summary["controller"]
        print(f"inverse: {summary['inverse']}")
        print(
            f"controller: theta_1 = {_vector(c['theta_1'])}, "
            f"theta_2 = {_vector(c['theta_2'])}, theta_3 = {c['theta_3']:g}"
        )
        print(
            "theta_b final (mc_r, m, mc_l): "
            + ", ".join(f"{x:.6g}" for x in summary["theta_b_final"])
            + (" (the initial values: without an inverse nothing adapts)"
               if summary["inverse"] == "none" else "")
        )
        print(f"RMS tracking error over the last third: {summary['rms_error_last']:.3e}")
        print(f"max |e| over the last third: {summary['max_abs_error_last']:.3e}")
        h_max = summary["delay_margin"]["h_max"]
        print("delay margin of the linear loop (delay at the plant input): "
              + ("none, unstable without delay" if h_max == 0 else
                 "stable for every delay" if h_max is None else f"{h_max:.6g} s"))
    return 0


def _vector(values) -> str:
    """A gain vector to 6 significant digits (``-5.5``, not its rounding error; ``0``,
    not ``-0``)."""
    return "[" + ", ".join(f"{x + 0.0:.6g}" for x in values) + "]"
