"""The joint ML estimate beside its linearisation at the truth (issue 3, coverage).

For trials of :mod:`robustness_joint` (same drives, records, priors and seeding), the
estimate linearised at the true parameters, ``theta* exp([(J^T J)^-1 J^T e]_theta)``
(``J`` the central-difference Jacobian of the weighted speeds in the log-parameters at
the truth, ``e`` the weighted noise actually drawn), is exactly normal with the
Cramér-Rao standard deviation. Where the fitted estimate stays within a small fraction
of a standard error of it, the estimator is efficient and its Fisher interval
calibrated, and misses are chance; where it does not, the likelihood is not regular
at the scale of a standard error (a rattling shaft), or the search failed.

Printed per scenario: std of ``(theta_hat - theta) / std_`` and of its linearised
counterpart, std of their difference in standard errors, the range of the fit's
Fisher std over the truth's, and the Fisher intervals covering the truth.

Run: ``python benchmarks/ml_vs_linearised.py [--scenarios 19,14,26] [--trials 100]
[--seed 21] [--jobs 2]`` (scenario rows as in ``robustness_joint.py``).
"""

from __future__ import annotations

import argparse
import math
import warnings

import numpy as np
import robustness_joint as rj

import backlashkit as bk
from backlashkit.errors import SensitivityWarning
from backlashkit.identify.joint import JointIdentifier
from backlashkit.parallel import ProgressBar, map_tasks

NAMES = ("theta", "J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh")
FD_STEP = 1e-5


def _speeds(drive, recs) -> np.ndarray:
    return np.concatenate([np.r_[r.w_motor, r.w_load]
                           for r in (drive.simulate(rec.t, rec.torque) for rec in recs)])


def trial(task):
    """(theta, estimate, Fisher std, linearised estimate, truth's std) of one trial."""
    drive, snr, seed = task
    warnings.simplefilter("ignore", SensitivityWarning)
    s_rec, s_prior = seed.spawn(2)
    recs = rj.records(drive, snr, s_rec)
    x = np.random.default_rng(s_prior).uniform(-1, 1, 6)
    prior = bk.TwoMassDrive(**{n: getattr(drive, n) * (1 - 0.4 * xi)
                               for n, xi in zip(NAMES[1:], x, strict=True)})
    fit = JointIdentifier(prior, workers=1, interval=bk.FisherInterval()).fit(recs)
    clean = _speeds(drive, recs)
    sig = []  # add_noise's std per record and channel
    pos = 0
    for rec in recs:
        for _ in range(2):  # w_M, then w_L
            c = clean[pos : pos + rec.t.size]
            sig.append(np.full(c.size, math.sqrt(np.mean(c**2)) / 10 ** (snr / 20)))
            pos += c.size
    sig = np.concatenate(sig)
    e = (np.concatenate([np.r_[r.w_motor, r.w_load] for r in recs]) - clean) / sig
    values = {n: getattr(drive, n) for n in NAMES}
    cols = []
    for n in NAMES:
        up, dn = (_speeds(bk.TwoMassDrive(**{**values, n: values[n] * math.exp(s)}), recs)
                  for s in (FD_STEP, -FD_STEP))
        cols.append((up - dn) / (2 * FD_STEP) / sig)
    jac = np.array(cols).T
    cov = np.linalg.inv(jac.T @ jac)
    dz = cov @ (jac.T @ e)
    return (drive.theta, fit.theta_, fit.std_, drive.theta * math.exp(dz[0]),
            drive.theta * math.sqrt(cov[0, 0]))


def main() -> None:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="19,14,26")
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    rows = [int(k) for k in args.scenarios.split(",")]
    scen = {k: (d, snr) for k, d, snr, _ in rj.scenarios(0.4)}
    tasks = [(*scen[k], s) for k in rows
             for s in np.random.SeedSequence([args.seed, k]).spawn(args.trials)]
    with ProgressBar("ML vs linearised", unit="fit") as bar:
        out = np.array(map_tasks(trial, tasks, jobs=args.jobs, progress=bar))
    print(f"seed {args.seed}, {args.trials} trials per scenario, Err_p = 40 %, Fisher intervals")
    print(f"{'row':>3} {'drive':<11} {'theta':>6} {'SNR':>4} | {'z std':>5} {'lin std':>7} "
          f"{'(est-lin)/sd':>12} {'std_/sd':>11} {'cover95':>7}")
    for j, k in enumerate(rows):
        th, est, std, lin, sd = out[j * args.trials : (j + 1) * args.trials].T
        d, snr = scen[k]
        z = (est - th) / std
        cover = int(np.sum(np.abs(z) <= 1.96))
        print(f"{k:3d} {rj.INERTIAS[d.J_L]:<11} {math.degrees(d.theta):5.1f}d {snr:4.0f} | "
              f"{np.std(z):5.2f} {np.std((lin - th) / sd):7.2f} {np.std((est - lin) / sd):12.2f} "
              f"{np.min(std / sd):5.3f}-{np.max(std / sd):5.3f} {cover:3d}/{args.trials}")


if __name__ == "__main__":
    main()
