"""``backlashkit delay-margin SYSTEM.toml``: the largest delay interval of a linear delay
system (Chen, IEEE TAC 1995)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..errors import InputError
from ..io import check_plot_suffix, check_writable
from .main import flag_names, missing_directory

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``delay-margin`` subcommand.

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
        "delay-margin",
        help="largest delay interval [0, h_max) of a linear delay system (Chen 1995)",
        description="Delay margin of x' - sum B_k x'(t - k h) = A0 x + sum A_k x(t - k h), "
        "from the [delay_system] table of SYSTEM.toml (A0 = [[...]], A = [[[...]], ...], "
        "optional B). Delays in s, frequencies in rad/s.",
    )
    p.add_argument("system", metavar="SYSTEM.toml", help="file with a [delay_system] table")
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("--h-range", metavar="LO,HI", default=None,
                   help="delays (s) over which to list the stability windows "
                        "(default 0,10*h_max, or 0,100 when h_max is 0 or infinite)")
    p.add_argument("--method", choices=("sweep", "kronecker"), default="sweep",
                   help="Chen's frequency sweep (default) or the Kronecker-sum pencil")
    p.add_argument("--plot", metavar="FILE",
                   help="save a figure (format from the extension: .png, .svg, .pdf, .jpg)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --plot file")
    p.set_defaults(func=run)
    return p


def _h_range(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        return float(parts[0]), float(parts[1])
    except ValueError:
        raise InputError(f"--h-range must be two numbers LO,HI in s; got {text!r}") from None


def _plot_path(path: str | None, force: bool) -> Path | None:
    if path is None:
        return None
    out = Path(path)
    check_plot_suffix("--plot", out)
    if out.is_dir():
        raise InputError(f"--plot {out} is a directory; give a file name")
    if out.exists() and not force:
        raise InputError(f"--plot {out} already exists; pass --force to overwrite it")
    if not out.parent.is_dir():
        raise InputError(missing_directory("--plot", out))
    check_writable(out, "--plot")
    return out


def _words(result, summary: dict) -> list[str]:
    lines = []
    if not summary["stable_at_zero"]:
        lines.append("unstable at h = 0: h_max = 0")
    elif result.difference_radius > 1.0:
        lines.append(f"the neutral difference operator is unstable (spectral radius "
                     f"{result.difference_radius:.6g} > 1): unstable for every h > 0")
    elif summary["h_max"] is None:
        lines.append("stable for every delay (delay-independent): h_max = inf")
    else:
        lines.append(f"h_max = {summary['h_max']:.10g} s (root on the imaginary axis at "
                     f"omega = {summary['omega']:.10g} rad/s)")
    ver = result.verification
    if ver:
        lines.append(f"check: rightmost root {ver['rightmost_below']:.3g} 1/s just below, "
                     f"{ver['rightmost_above']:.3g} 1/s just above h_max "
                     f"({'confirmed' if ver['passed'] else 'NOT confirmed'})")
    windows = summary["windows"]
    lines.append("stable for h in: " + (", ".join(f"[{a:.6g}, {b:.6g})" for a, b in windows)
                                        if windows else "none of the range"))
    return lines


def run(args: argparse.Namespace) -> int:
    """Run ``backlashkit delay-margin``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments.

    Returns
    -------
    int
        Exit status (0).
    """
    from ..delay import margin_of_system, read_delay_system

    h_range = _h_range(args.h_range)
    plot = _plot_path(args.plot, args.force)
    system = read_delay_system(args.system)
    try:
        result = margin_of_system(system, method=args.method)
    except InputError as exc:  # e.g. a marginal neutral operator: say which file
        raise InputError(f"{args.system}: {exc}") from None
    with flag_names({"h_range": "--h-range"}):
        summary = result.as_dict(h_range)
    if plot is not None:
        span = h_range or result.default_range()
        result.plot(h_range=span).savefig(plot)
        print(f"backlashkit: wrote {plot}", file=sys.stderr)
    if args.json:
        json.dump(summary, sys.stdout, indent=2, allow_nan=False)
        sys.stdout.write("\n")
    else:
        print("\n".join(_words(result, summary)))
    return 0
