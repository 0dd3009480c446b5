"""``--report DIR`` of ``backlashkit identify``: the HTML identification report
(:func:`backlashkit.identify.report.write_identification_report`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..identify.report import write_identification_report
from ..plants import TwoMassDrive
from .main import Flag, flag_names, spell

__all__ = ["add_report_option", "maybe_write_report"]


def add_report_option(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add ``--report DIR`` and ``--force`` to the ``identify`` subcommand's parser.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The subcommand's parser.

    Returns
    -------
    argparse.ArgumentParser
        The same parser.
    """
    parser.add_argument(
        "--report",
        metavar="DIR",
        default=None,
        help="write an HTML report (index.html and PNG/SVG figures) into DIR",
    )
    parser.add_argument(
        "--force", action="store_true", help="write the report into DIR even if it is not "
        "empty (the report's files are overwritten)"
    )
    return parser


def maybe_write_report(
    args: argparse.Namespace,
    records: Any,
    result: Any,
    prior: TwoMassDrive,
    final_records: Any = None,
    notes: Sequence[str] = (),
    flags: Mapping[str, Flag] | None = None,
) -> Path | None:
    """Write the report if ``--report`` was given.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments with ``report`` and ``force`` (see :func:`add_report_option`).
    records : Record or sequence of Record
        Experiments given to the identifier.
    result : object
        The fitted identifier.
    prior : TwoMassDrive
        The prior drive.
    final_records : Record or sequence of Record, optional
        Experiments of the final least squares, when given separately.
    notes : sequence of str, optional
        The command's notes on the answer, listed in the report.
    flags : mapping of str to Flag, optional
        Library parameter -> the command's flag, for the advice the page words itself.

    Returns
    -------
    pathlib.Path or None
        Path of ``index.html``, or None when no report was asked for.
    """
    if args.report is None:
        return None
    with flag_names({"force": "--force"}):
        index = write_identification_report(
            args.report, records, result, prior=prior, force=bool(args.force),
            final_records=final_records, notes=notes,
            spell=lambda option: spell(option, flags or {}),
        )
    print(f"backlashkit: wrote {index}", file=sys.stderr)
    return index
