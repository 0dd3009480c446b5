"""``backlashkit reproduce PAPER``: rerun a source paper's protocol and compare.

Each target is a module exposing ``add_arguments(parser)`` and ``run_cli(args)``;
targets are listed in :data:`TARGETS` and imported only when chosen.
"""

from __future__ import annotations

import argparse
import importlib

#: target name -> (module, one-line description)
TARGETS = {
    "ravanbod2002": (
        "backlashkit.papers.ravanbod2002",
        "Ravanbod-Shirazi & Besancon-Voda 2002, Section 5: Tables 1 and 2 and the joint "
        "estimator",
    ),
    "tao1995": (
        "backlashkit.papers.tao1995",
        "Tao & Kokotovic 1995, Section IV: adaptive backlash inverse, Figs. 5 and 6",
    ),
}


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``reproduce`` and one sub-subcommand per target.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The top-level subparsers of :func:`backlashkit.cli.build_parser`.

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
    for name, (module, summary) in TARGETS.items():
        tp = targets.add_parser(name, help=summary, description=summary)
        importlib.import_module(module).add_arguments(tp)
        tp.set_defaults(func=_runner(module))
    return p


def _runner(module: str):
    def run(args: argparse.Namespace) -> int:
        return int(importlib.import_module(module).run_cli(args))

    return run
