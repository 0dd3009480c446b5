"""Scaling of ``backlashkit reproduce ravanbod2002`` over worker processes (issue 23).

The command is run as a user runs it, in a fresh process, with ``--jobs 1`` and then
``--jobs 2`` (interleaved ``--repeats`` times); the wall time of each run includes the
interpreter's start and the serial parts (the tables, the two-step and regression
columns). The scaling efficiency of 2 workers over 1 is ``T1 / (2 T2)`` on the medians
(issue 23's bar: >= 0.85). Both runs must give the same results (``--json-out`` less
the timings and the worker count; checked). The
machine's load average is printed before and after.

``--against CHECKOUT`` measures a change instead (issue 24): the same reproduction
with ``--jobs 2``, by this checkout's package and by an older one's (``CHECKOUT/python``
first on ``PYTHONPATH``, its compiled extension built there), interleaved
``--repeats`` times; the ratio of their median wall times, and how far the estimates
moved (``compare_reproduce.in_std``: per ``Err_p`` and method, in standard deviations
and standard errors of the old runs). ``--keep DIR`` keeps both JSON documents.

Run: ``python benchmarks/bench_reproduce.py [--runs 3] [--seed 2002] [--repeats 1]
[--against CHECKOUT [--keep DIR]]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: What the JSON of a reproduction holds besides its results: how long it took and on
#: how many workers.
NOT_RESULTS = ("seconds", "seconds_per_run", "jobs")


def results(node):
    """The JSON ``node`` less :data:`NOT_RESULTS`."""
    if isinstance(node, dict):
        return {k: results(v) for k, v in node.items() if k not in NOT_RESULTS}
    if isinstance(node, list):
        return [results(v) for v in node]
    return node


def run(runs: int, seed: int, jobs: int, package: Path | None = None,
        keep: Path | None = None) -> tuple[float, str]:
    """Wall time of one reproduction and its results (as JSON text); ``package``: the
    folder holding the ``backlashkit`` to run (None: the installed one); ``keep``: where
    to copy the JSON document."""
    env = dict(os.environ)
    if package is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(package), env.get("PYTHONPATH", "")])
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "out.json"
        cmd = [sys.executable, "-m", "backlashkit", "reproduce", "ravanbod2002", "--runs",
               str(runs), "--seed", str(seed), "--jobs", str(jobs), "--quiet",
               "--json-out", str(out)]
        start = time.perf_counter()
        subprocess.run(cmd, capture_output=True, text=True, check=True, env=env)
        sec = time.perf_counter() - start
        if keep is not None:
            keep.write_text(out.read_text())
        return sec, json.dumps(results(json.loads(out.read_text())), sort_keys=True)


def against(args) -> None:
    """This package against an older checkout's, interleaved (issue 24's measure)."""
    from compare_reproduce import in_std

    old_pkg = Path(args.against) / "python"
    if not (old_pkg / "backlashkit").is_dir():
        raise SystemExit(f"--against {args.against}: no python/backlashkit in it; give "
                         "the root of a checkout whose extension is built")
    keep = Path(args.keep or tempfile.mkdtemp())
    keep.mkdir(parents=True, exist_ok=True)
    times: dict[str, list[float]] = {"old": [], "new": []}
    for _ in range(args.repeats):
        for name, pkg in (("old", old_pkg), ("new", None)):
            sec, _ = run(args.runs, args.seed, 2, pkg, keep / f"{name}.json")
            times[name].append(sec)
            print(f"{name}: {sec:.1f} s", flush=True)
    t_old, t_new = (statistics.median(times[k]) for k in ("old", "new"))
    print(f"reproduce ravanbod2002 --runs {args.runs} --jobs 2, median of {args.repeats}: "
          f"{args.against} {t_old:.1f} s, this checkout {t_new:.1f} s: "
          f"{t_old / t_new:.2f}x faster (issue 24's bar: 3x)")
    in_std(*(json.loads((keep / f"{k}.json").read_text()) for k in ("old", "new")))
    print(f"load average after: {os.getloadavg()}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=3, help="runs per noise level")
    ap.add_argument("--seed", type=int, default=2002)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--against", metavar="CHECKOUT",
                    help="an older checkout (its extension built) to time against")
    ap.add_argument("--keep", metavar="DIR", help="with --against: keep both JSON documents")
    args = ap.parse_args()
    print(f"load average before: {os.getloadavg()}")
    if args.against:
        against(args)
        return
    times: dict[int, list[float]] = {1: [], 2: []}
    outputs = set()
    for _ in range(args.repeats):
        for jobs in (1, 2):
            sec, text = run(args.runs, args.seed, jobs)
            times[jobs].append(sec)
            outputs.add(text)
            print(f"--jobs {jobs}: {sec:.1f} s", flush=True)
    t1, t2 = (statistics.median(times[j]) for j in (1, 2))
    print(f"reproduce ravanbod2002 --runs {args.runs}, median of {args.repeats}: "
          f"1 worker {t1:.1f} s, 2 workers {t2:.1f} s")
    print(f"scaling efficiency of 2 workers over 1: {t1 / (2 * t2):.3f} (bar >= 0.85)")
    print(f"same results with 1 and 2 workers: {len(outputs) == 1}")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
