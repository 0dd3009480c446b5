"""Does the wear report's trend interval cover each drive's true growth rate? (issue 23)

A fleet from :func:`backlashkit.fleet.generate_fleet` (default 20 drives x 10 weekly
tests; paper A's drive with its linear parameters spread +-10 %, the initial half-width
+-20 % around 3.49e-2 rad, growth rates uniform on [0, 0.02] rad per year; each test
paper A's two step-down records at its SNRs, the torque held ``--hold`` s) is identified
with ``backlashkit.fleet.identify_fleet`` (the default joint estimator), and every
drive's Theil-Sen trend (``backlashkit.fleet.wear_trends``) is checked against its true
rate. Printed: how many of the drives' 95 % intervals cover the truth, the range a
95 % interval would give in 95 % of such studies (binomial), and, for comparison, the
same count for weighted least squares with the fits' own standard errors (the
alternative ``backlashkit.fleet.wear`` argues against) and the median width of both.

Run: ``python benchmarks/fleet_trend_coverage.py [--drives 20] [--weeks 10] [--seed 23]
[--hold 10] [--jobs 2 | --dask-local 2] [--data DIR] [--report DIR]``. ``--data`` keeps
the generated files and results there (a rerun completes an interrupted study);
``--report`` writes the wear report of the study.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np
from scipy import stats

from backlashkit.fleet import generate_fleet, identify_fleet, wear_trends, write_wear_report
from backlashkit.fleet.generate import DAYS_PER_YEAR
from backlashkit.parallel import dask_client


def wls(rows: list[dict], dates: list) -> tuple[float, float, float]:
    """Slope and 95 % interval of weighted least squares with the fits' std (rad/yr)."""
    x = np.array([(np.datetime64(r["date"]) - np.datetime64(dates[0].isoformat()))
                  .astype(float) / DAYS_PER_YEAR for r in rows])
    y = np.array([r["theta"] for r in rows])
    w = 1.0 / np.array([r["std"] for r in rows]) ** 2
    a = np.column_stack([np.ones_like(x), x])
    cov = np.linalg.inv(a.T @ (w[:, None] * a))
    beta = cov @ (a.T @ (w * y))
    half = 1.959963984540054 * math.sqrt(cov[1, 1])
    return float(beta[1]), float(beta[1] - half), float(beta[1] + half)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--drives", type=int, default=20)
    ap.add_argument("--weeks", type=int, default=10)
    ap.add_argument("--seed", type=int, default=23)
    ap.add_argument("--hold", type=float, default=10.0)
    ap.add_argument("--jobs", type=int)
    ap.add_argument("--dask-local", type=int)
    ap.add_argument("--data", type=Path)
    ap.add_argument("--report", type=Path)
    args = ap.parse_args()
    tmp = tempfile.TemporaryDirectory() if args.data is None else nullcontext(str(args.data))
    with tmp as folder:
        root = Path(folder) / "fleet"
        manifest = root / "MANIFEST.csv"
        truth = generate_fleet(args.drives, args.weeks, seed=args.seed, out=root,
                               hold=args.hold, force=True)
        start = time.perf_counter()
        client = (dask_client(n_workers=args.dask_local) if args.dask_local
                  else nullcontext())
        with client as executor:
            rows = identify_fleet(manifest, out=root / "RESULTS.csv", executor=executor,
                                  jobs=args.jobs)
        seconds = time.perf_counter() - start
        if args.report is not None:
            write_wear_report(rows, args.report)
    trends = {t.drive: t for t in wear_trends(rows)}
    refused = sum(r["status"] != "ok" for r in rows)
    cover_ts = cover_wls = 0
    widths_ts, widths_wls = [], []
    for d, rate in zip(truth.drives, truth.rate, strict=True):
        t = trends[d]
        cover_ts += bool(t.ci95_low <= rate <= t.ci95_high)
        widths_ts.append(t.ci95_high - t.ci95_low)
        mine = [r for r in rows if r["drive"] == d and r["status"] == "ok"]
        _, lo, hi = wls(mine, truth.dates)
        cover_wls += bool(lo <= rate <= hi)
        widths_wls.append(hi - lo)
    n = len(truth.drives)
    lo95, hi95 = (int(q) for q in stats.binom.ppf([0.025, 0.975], n, 0.95))
    print(f"{n} drives x {args.weeks} weeks, hold {args.hold:g} s, seed {args.seed}: "
          f"{len(rows)} tests, {refused} refused, {seconds:.0f} s")
    print(f"Theil-Sen (Sen's 95 % interval): {cover_ts}/{n} drives cover the true rate; "
          f"a 95 % interval gives {lo95}-{hi95} of {n} in 95 % of studies; median width "
          f"{np.median(widths_ts) * 1e3:.2f} mrad/yr")
    print(f"weighted least squares (fits' std): {cover_wls}/{n}; median width "
          f"{np.median(widths_wls) * 1e3:.2f} mrad/yr")
    print(f"true rates: {truth.rate.min() * 1e3:.2f} to {truth.rate.max() * 1e3:.2f} mrad/yr")


if __name__ == "__main__":
    main()
