"""``backlashkit fleet MANIFEST.csv --out RESULTS.csv``: identify a fleet's tests, report
its wear."""

from __future__ import annotations

import argparse
import sys
from contextlib import nullcontext
from pathlib import Path

from ..errors import InputError

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``fleet`` subcommand.

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
        "fleet",
        help="identify the backlash of every test of a fleet, track each drive's wear",
        description="Identify every test of MANIFEST.csv (columns drive,date,records,prior; "
        "files relative to its folder) with the default method, appending one row per test "
        "to RESULTS.csv as it finishes. Rerunning the same command completes an "
        "interrupted run without refitting what is there.",
    )
    p.add_argument("manifest", metavar="MANIFEST.csv", help="one row per test")
    p.add_argument("--out", required=True, metavar="RESULTS.csv",
                   help="results, one row per test (completed if it exists)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=int, metavar="N", help="N local worker processes")
    where.add_argument("--dask-local", type=int, metavar="N",
                       help="a local Dask cluster of N worker processes (needs backlashkit[dask])")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="a running Dask scheduler, e.g. tcp://host:8786; the workers read "
                       "the files at the same paths")
    p.add_argument("--report", metavar="DIR", help="write the wear report (index.html) here "
                   "(an earlier wear report in DIR is replaced)")
    p.add_argument("--growth-threshold", type=float, metavar="RAD",
                   help="flag a drive whose half-width grew more than this over its tests "
                   "(default 3.5e-3 rad)")
    p.add_argument("--rate-threshold", type=float, default=0.0, metavar="RAD_PER_YEAR",
                   help="flag a drive whose wear rate's 95 %% interval lies above this "
                   "(default 0: any significant growth)")
    p.add_argument("--force", action="store_true",
                   help="start RESULTS.csv afresh; overwrite the report's files")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)
    return p


def run(args: argparse.Namespace) -> int:
    """Run ``backlashkit fleet``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        Exit status (0).
    """
    from ..fleet import identify_fleet, read_manifest, wear_trends, write_wear_report
    from ..fleet.report import check_report_dir
    from ..parallel import ProgressBar, dask_client
    from .main import flag_names

    manifest = read_manifest(args.manifest)
    report = None if args.report is None else check_report_dir(args.report, force=args.force)
    thresholds = {"rate_threshold": args.rate_threshold}
    if args.growth_threshold is not None:
        thresholds["growth_threshold"] = args.growth_threshold
    with flag_names({"rate_threshold": "--rate-threshold",
                     "growth_threshold": "--growth-threshold"}):
        wear_trends([], **thresholds)  # the thresholds checked before any fit
    if args.jobs is not None and args.jobs < 1:
        raise InputError(f"--jobs must be a positive integer, got {args.jobs}")
    if args.dask_local is not None and args.dask_local < 1:
        raise InputError(f"--dask-local must be a positive integer, got {args.dask_local}")
    if Path(args.out).resolve() == manifest.path.resolve():
        raise InputError("--out must not be the manifest itself")
    bar = ProgressBar("fleet", unit="test", quiet=args.quiet)
    client = (dask_client(n_workers=args.dask_local) if args.dask_local is not None
              else dask_client(address=args.scheduler) if args.scheduler is not None
              else nullcontext())
    kept: list[int] = []  # the tests already in --out: the first call's count

    def progress(done: int, total: int) -> None:
        if not kept:
            kept.append(done)
        bar(done, total)

    try:
        with client as executor:
            rows = identify_fleet(manifest, out=args.out, executor=executor, jobs=args.jobs,
                                  force=args.force, progress=progress)
    finally:
        bar.close()
    refused = [r for r in rows if r["status"] != "ok"]
    reused = f" ({kept[0]} kept from {args.out}, {len(rows) - kept[0]} run now)" \
        if kept and kept[0] else ""
    print(f"{len(rows)} tests{reused}: {len(rows) - len(refused)} identified, "
          f"{len(refused)} refused; results in {args.out}")
    if report is not None:
        print(f"backlashkit: wrote {write_wear_report(rows, report, **thresholds)}",
              file=sys.stderr)
    return 0
