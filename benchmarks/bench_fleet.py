"""Speed of fleet identification on the executors of ``backlashkit.parallel`` (issue 23).

One fleet from :func:`backlashkit.fleet.generate_fleet` (default 20 drives x 5 weekly
tests = 100 tests, the torque held ``--hold`` s) is identified by
``backlashkit.fleet.identify_fleet`` into a fresh results file on:

* a local process pool of 1 worker and of 2 workers (``process_pool``): the scaling
  efficiency of 2 workers over 1 is ``T1 / (2 T2)`` (issue 23's bar: >= 0.85);
* a local Dask cluster of 2 single-threaded worker processes (``dask_client``): Dask's
  overhead against the pool is ``T_dask / T2 - 1`` (bar: <= 10 %). The cluster's start
  is timed apart (paid once per session, not per fleet).

Every run must give the same table (checked). ``--overhead`` measures instead, for
``docs/design/fleet.md``: the cost per task of each executor on ``--tasks`` empty tasks,
the size of a task as sent to a worker, and the size and reading time of one record of
paper A's length (80 s at 1 ms) as CSV and as ``.npz``. ``--malloc`` times one fit
and its minor page faults (median of 3 processes, each the mean of 3 fits after a
first) with and without the
``MALLOC_TRIM_THRESHOLD_=65536`` that Dask's nanny sets in its workers (unset by
``backlashkit.parallel.dask_client``). Times are wall clock of
``identify_fleet`` alone, median of ``--repeats`` runs in this process; the machine's
load average is printed before and after (on a shared machine other people's work
slows the 2-worker runs more than the 1-worker one).

Run: ``python benchmarks/bench_fleet.py [--drives 20] [--weeks 5] [--hold 5] [--seed 7]
[--repeats 1] [--skip-serial]``, or ``python benchmarks/bench_fleet.py --overhead
[--tasks 2000]``, or ``python benchmarks/bench_fleet.py --malloc``.
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from backlashkit import read_records
from backlashkit.fleet import generate_fleet, identify_fleet, read_manifest
from backlashkit.parallel import dask_client, map_tasks, process_pool


def _noop(task):
    return task


def overhead(n_tasks: int) -> None:
    """Per-task cost of the executors; task and record sizes."""
    for name, make in (("pool-2", lambda: process_pool(2)),
                       ("dask-2", lambda: dask_client(n_workers=2))):
        with make() as executor:
            map_tasks(_noop, list(range(20)), executor=executor)  # workers up and warm
            start = time.perf_counter()
            map_tasks(_noop, list(range(n_tasks)), executor=executor)
            sec = time.perf_counter() - start
        print(f"{name}: {sec / n_tasks * 1e3:.2f} ms per empty task ({n_tasks} tasks)")
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder) / "fleet"
        truth = generate_fleet(1, 1, seed=1, out=root, hold=40.0)
        test = read_manifest(truth.manifest).tests[0]
        records, prior = test.paths(root)
        task = (test.drive, test.date.isoformat(), records, prior)
        print(f"task sent to a worker: {len(pickle.dumps(task))} bytes")
        csv = Path(records[0])
        rec = read_records(csv)[0]
        npz = csv.with_suffix(".npz")
        np.savez(npz, t=rec.t, torque=rec.torque, w_motor=rec.w_motor, w_load=rec.w_load)
        for path in (csv, npz):
            reads = []
            for _ in range(5):
                start = time.perf_counter()
                read_records(path)
                reads.append(time.perf_counter() - start)
            print(f"one 80 s record as {path.suffix}: {path.stat().st_size / 1e6:.2f} MB, "
                  f"read in {statistics.median(reads) * 1e3:.0f} ms (median of 5)")


def timed(manifest: Path, out: Path, executor) -> tuple[float, list]:
    start = time.perf_counter()
    rows = identify_fleet(manifest, out=out, executor=executor, force=True)
    return time.perf_counter() - start, rows


_ONE_FIT = """
import resource, sys, time
from backlashkit.fleet import identify_test, read_manifest
m = read_manifest(sys.argv[1]); t = m.tests[0]
task = (t.drive, t.date.isoformat(), *t.paths(m.path.parent))
identify_test(task)
faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
start = time.perf_counter()
for _ in range(3):
    identify_test(task)
print((time.perf_counter() - start) / 3,
      (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults) / 3)
"""


def malloc(hold: float) -> None:
    """One fit's time with and without Dask's MALLOC_TRIM_THRESHOLD_, interleaved."""
    with tempfile.TemporaryDirectory() as folder:
        truth = generate_fleet(1, 1, seed=1, out=Path(folder) / "fleet", hold=hold)
        times: dict[str, list[float]] = {"glibc default": [], "MALLOC_TRIM_THRESHOLD_=65536": []}
        faults: dict[str, list[float]] = {name: [] for name in times}
        for _ in range(3):
            for name in times:
                env = {k: v for k, v in os.environ.items() if k != "MALLOC_TRIM_THRESHOLD_"}
                if name != "glibc default":
                    env["MALLOC_TRIM_THRESHOLD_"] = "65536"
                out = subprocess.run([sys.executable, "-c", _ONE_FIT, str(truth.manifest)],
                                     env=env, capture_output=True, text=True, check=True)
                sec, flt = (float(x) for x in out.stdout.split())
                times[name].append(sec)
                faults[name].append(flt)
        for name, values in times.items():
            print(f"{name}: {statistics.median(values):.2f} s per fit (median of 3; "
                  + ", ".join(f"{x:.2f}" for x in values) + f"), "
                  f"{statistics.median(faults[name]):.0f} minor page faults per fit, "
                  f"hold {hold:g} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--drives", type=int, default=20)
    ap.add_argument("--weeks", type=int, default=5)
    ap.add_argument("--hold", type=float, default=5.0)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--skip-serial", action="store_true", help="no 1-worker run")
    ap.add_argument("--overhead", action="store_true", help="per-task costs and sizes only")
    ap.add_argument("--tasks", type=int, default=2000)
    ap.add_argument("--malloc", action="store_true", help="one fit with and without Dask's "
                    "MALLOC_TRIM_THRESHOLD_")
    args = ap.parse_args()
    if args.overhead:
        overhead(args.tasks)
        return
    if args.malloc:
        malloc(args.hold)
        return
    print(f"load average before: {os.getloadavg()}")
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        truth = generate_fleet(args.drives, args.weeks, seed=args.seed, out=root / "fleet",
                               hold=args.hold)
        n = args.drives * args.weeks
        times: dict[str, list[float]] = {"pool-1": [], "pool-2": [], "dask-2": []}
        tables = []
        for _ in range(args.repeats):
            for name, workers in (("pool-1", 1), ("pool-2", 2)):
                if name == "pool-1" and args.skip_serial:
                    continue
                with process_pool(workers) as pool:
                    sec, rows = timed(truth.manifest, root / f"{name}.csv", pool)
                times[name].append(sec)
                tables.append(rows)
                print(f"{name}: {sec:.1f} s ({sec / n:.2f} s per test)", flush=True)
            t0 = time.perf_counter()
            with dask_client(n_workers=2) as client:
                started = time.perf_counter() - t0
                sec, rows = timed(truth.manifest, root / "dask-2.csv", client)
            times["dask-2"].append(sec)
            tables.append(rows)
            print(f"dask-2: {sec:.1f} s ({sec / n:.2f} s per test); cluster start "
                  f"{started:.1f} s", flush=True)
    same = all(t == tables[0] for t in tables)
    med = {k: statistics.median(v) for k, v in times.items() if v}
    print(f"{n} tests, hold {args.hold:g} s; median of {args.repeats}: "
          + ", ".join(f"{k} {v:.1f} s" for k, v in med.items()))
    if "pool-1" in med:
        print(f"scaling efficiency of 2 workers over 1: {med['pool-1'] / (2 * med['pool-2']):.3f}"
              " (bar >= 0.85)")
    print(f"Dask overhead against the process pool: {med['dask-2'] / med['pool-2'] - 1:+.1%}"
          " (bar <= 10 %)")
    print(f"identical tables on every executor: {same}")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
