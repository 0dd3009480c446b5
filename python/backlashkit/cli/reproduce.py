"""``backlashkit reproduce PAPER``: rerun a source paper's protocol and compare.

The reproductions are library code (:mod:`backlashkit.papers`); this module parses each
target's options, checks its output paths before the run, calls it and prints its
tables and bars.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from ..errors import InputError
from ..parallel import ProgressBar
from .main import flag_names, missing_directory

__all__ = ["add_parser", "check_reproduce_outputs"]

#: target name -> one-line description
TARGETS = {
    "ravanbod2002": "Ravanbod-Shirazi & Besancon-Voda 2002, Section 5: Tables 1 and 2 and "
                    "the joint estimator",
    "tao1995": "Tao & Kokotovic 1995, Section IV: adaptive backlash inverse, Figs. 5 and 6",
}


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``reproduce`` and one sub-subcommand per target.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The top-level subparsers of :func:`backlashkit.cli.main.build_parser`.

    Returns
    -------
    argparse.ArgumentParser
        The ``reproduce`` parser.
    """
    p = subparsers.add_parser(
        "reproduce",
        help="rerun a source paper's experiment and compare with its reported results",
        description="Rerun a source paper's protocol and print its numbers beside ours.",
    )
    targets = p.add_subparsers(dest="paper", metavar="PAPER", parser_class=type(p))
    targets.required = True
    adders = {"ravanbod2002": _ravanbod2002_arguments, "tao1995": _tao1995_arguments}
    runners = {"ravanbod2002": run_ravanbod2002, "tao1995": run_tao1995}
    for name, summary in TARGETS.items():
        tp = targets.add_parser(name, help=summary, description=summary)
        adders[name](tp)
        tp.set_defaults(func=runners[name])
    return p


def _output_arguments(parser: argparse.ArgumentParser, *, what: str,
                      report_help: str) -> None:
    parser.add_argument("--json", action="store_true",
                        help=f"print {what} as JSON on stdout (the tables then go to stderr)")
    parser.add_argument("--json-out", metavar="FILE",
                        help=f"write {what} as JSON to FILE")
    parser.add_argument("--report", metavar="DIR", help=report_help)
    parser.add_argument("--force", action="store_true", help="overwrite existing outputs")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress bar on stderr (there is none when stderr is not "
                             "a terminal)")


def check_reproduce_outputs(json_out: str | None, report: str | None,
                            force: bool) -> Path | None:
    """Refuse, before any run, the ``--json-out FILE`` and ``--report DIR`` of a
    ``reproduce`` target that exist (without ``--force``), sit in a missing directory or
    cannot be written; return the report directory.

    A ``--json-out`` that exists but is no regular file (``/dev/null``, a pipe) is
    written to without ``--force``: nothing of the user's is overwritten.

    Parameters
    ----------
    json_out : str or None
        ``--json-out``.
    report : str or None
        ``--report``.
    force : bool
        ``--force``.

    Returns
    -------
    pathlib.Path or None
        The report directory.
    """
    from ..io import check_writable

    if json_out is not None:
        path = Path(json_out)
        if path.is_dir():
            raise InputError(f"--json-out {json_out} is a directory; give a file name in it "
                             f"(e.g. {path / 'results.json'})")
        if path.is_file() and not force:
            raise InputError(f"--json-out {json_out} already exists; pass --force to "
                             "overwrite it")
        if not path.exists() and not path.parent.is_dir():
            raise InputError(missing_directory("--json-out", path))
        check_writable(json_out, "--json-out")
    if report is None:
        return None
    rep = Path(report)
    if rep.exists() and not rep.is_dir():
        raise InputError(f"--report {rep} exists and is not a directory")
    if rep.exists() and any(rep.iterdir()) and not force:
        raise InputError(f"--report {rep} is not empty; pass --force to overwrite its files")
    check_writable(rep, "--report", directory=True)
    return rep


def _write_json(args: argparse.Namespace, body: str) -> None:
    """``--json`` on stdout, ``--json-out`` to its file (announced on stderr)."""
    if args.json:
        sys.stdout.write(body)
    if args.json_out is not None:
        with open(args.json_out, "w", encoding="utf-8") as fh:
            fh.write(body)
        print(f"backlashkit: wrote {args.json_out}", file=sys.stderr)


def _bar_lines(bars) -> str:
    return "\n".join(f"{'MET ' if m else 'MISS'}  {b}: {v}" for b, v, m in bars)


# --- ravanbod2002 ------------------------------------------------------------------


def _ravanbod2002_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``backlashkit reproduce ravanbod2002``; without one, the library's
    default applies (said in the help)."""
    import inspect

    from ..papers.ravanbod2002 import run_ravanbod2002 as run

    default = {k: p.default for k, p in inspect.signature(run).parameters.items()}
    parser.add_argument("--runs", type=int, default=None,
                        help=f"runs per Err_p, >= 2 (a spread needs two; default "
                        f"{default['runs']})")
    parser.add_argument("--seed", type=int, default=None,
                        help=f"root seed (default {default['seed']})")
    parser.add_argument("--jobs", type=int, default=None,
                        help=f"worker processes (default {default['jobs']}); results do not "
                        "depend on it")
    parser.add_argument("--err-p", default=None, metavar="E1,E2,...",
                        help="prior errors to run (default "
                        f"{','.join(f'{e:g}' for e in default['err_p'])})")
    parser.add_argument("--snr-step1", default=None, metavar="SNR_M,SNR_L",
                        help="step-1 SNR of w_M,w_L in dB (default the paper's "
                        f"{','.join(f'{x:g}' for x in default['snr1'])})")
    _output_arguments(parser, what="the whole document", report_help="write an HTML "
                      "report (index.html), the JSON and a figure of the estimates (PNG, "
                      "SVG) into DIR")


def _numbers(option: str, text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(f"{option} must be numbers separated by commas, got {text!r}") from None


def run_ravanbod2002(args: argparse.Namespace) -> int:
    """Run ``backlashkit reproduce ravanbod2002``.

    Parameters
    ----------
    args : argparse.Namespace
        With ``runs``, ``seed``, ``jobs``, ``err_p``, ``snr_step1``, ``json``,
        ``json_out``, ``report``, ``force``, ``quiet``.

    Returns
    -------
    int
        0 when the joint estimator meets every bar, 1 otherwise.
    """
    from ..papers import ravanbod2002 as paper

    rep = check_reproduce_outputs(args.json_out, args.report, bool(args.force))
    options = {k: getattr(args, k) for k in ("runs", "seed", "jobs")
               if getattr(args, k) is not None}
    if args.snr_step1 is not None:
        snr1 = _numbers("--snr-step1", args.snr_step1)
        if len(snr1) != 2 or not all(math.isfinite(x) for x in snr1):
            raise InputError(f"--snr-step1 must be two finite numbers SNR_M,SNR_L in dB, got "
                             f"{args.snr_step1!r}")
        options["snr1"] = (snr1[0], snr1[1])
    if args.err_p is not None:
        err_p = _numbers("--err-p", args.err_p)
        if len(set(err_p)) != len(err_p):
            raise InputError(f"--err-p lists a value twice ({args.err_p!r}): each row is run "
                             "once")
        options["err_p"] = err_p
    flags = {"runs": "--runs", "seed": "--seed", "jobs": "--jobs", "err_p": "--err-p"}
    with flag_names(flags), ProgressBar("ravanbod2002", unit="run",
                                        quiet=args.quiet) as bar:
        doc = paper.run_ravanbod2002(**options, progress=bar)
    bars = paper.checks(doc)
    doc["checks"] = [{"bar": b, "value": v, "met": bool(m)} for b, v, m in bars]
    text = paper.format_tables(doc) + "\n\n" + _bar_lines(bars)
    print(text, file=sys.stderr if args.json else sys.stdout)
    _write_json(args, paper.to_json(doc))
    if rep is not None:
        index = paper.write_report(rep, doc, text=text)
        print(f"backlashkit: wrote {index}", file=sys.stderr)
    return 0 if all(m for _, _, m in bars) else 1


# --- tao1995 -----------------------------------------------------------------------


def _tao1995_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``backlashkit reproduce tao1995``."""
    _output_arguments(parser, what="the summary", report_help="write an HTML report "
                      "(index.html), its figures (PNG, SVG) and the traces (CSV) into DIR")


def run_tao1995(args: argparse.Namespace) -> int:
    """Run ``backlashkit reproduce tao1995``.

    Parameters
    ----------
    args : argparse.Namespace
        With ``json``, ``json_out``, ``report``, ``force``, ``quiet``.

    Returns
    -------
    int
        0 when every bar of the reproduction is met, 1 otherwise.
    """
    from ..papers import tao1995 as paper

    rep = check_reproduce_outputs(args.json_out, args.report, bool(args.force))
    with ProgressBar("tao1995", unit="controller", quiet=args.quiet) as bar:
        runs = paper.run_tao1995(progress=bar)
    doc = paper.summary(runs)
    bars = [(c["bar"], c["value"], c["met"]) for c in doc["checks"]]
    print(_bar_lines(bars), file=sys.stderr if args.json else sys.stdout)
    _write_json(args, json.dumps(doc, indent=2) + "\n")
    if rep is not None:
        index = paper.write_report(rep, runs)
        print(f"backlashkit: wrote {index}", file=sys.stderr)
    return 0 if all(m for _, _, m in bars) else 1
