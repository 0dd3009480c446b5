"""Benchmark: the joint estimator on drives with no backlash or very little.

Does the 95 % interval of ``theta`` answer "is there backlash at all?" ``theta`` is
fitted as a logarithm, which only approaches 0; where its Fisher interval reaches 0 the
profile is followed in rad of ``theta`` down to 0 (``ProfileLikelihood``,
docs/design/real-drives.md, "A drive without backlash"). Records as in
``benchmarks/real_drive.py``: the independent scipy reference
(:func:`backlashkit.verify.reference_simulate`), 8 s at 1 ms, paper A's two torque
levels held from the steady state and stepped down to 0 at 2 s, 40 dB of white noise
(``--snr``), the true linear parameters as the prior, every option at its default.
Each ``theta`` of ``--thetas`` (rad) is one row; trial ``k`` of every row draws its
noise from child ``k`` of ``--seed``'s ``SeedSequence`` (so the rows differ only in
``theta``, and results do not depend on ``--jobs``).

Printed per row: fits answered (refusals apart), how many warned that a linear
parameter moved far from the prior (:class:`~backlashkit.errors.PriorMismatchWarning`),
the share of intervals whose lower end is 0 ("consistent with no backlash"), the share
that cover the true ``theta`` with the 2-binomial-standard-deviation band about 95 %,
the share of intervals with both ends bounded, how many fits' intervals span the
profiles of other minima (``rival_basins_`` above 0, which the command line notes as
"other minima near the best"), and the medians of ``theta_``, ``std_`` and the
interval's upper end, in rad.

Run: ``python benchmarks/small_backlash.py [--trials 100] [--jobs 2] [--drive paper|other]
[--thetas 0,1e-5,3e-5,1e-4] [--snr 40] [--seed 7]``; ``--trial K`` reruns trial ``K`` of
each row alone and prints its interval, the profile's rise at ``theta = 0``, the
parameter that moved most and the truth's ``-2 log L`` against the estimate's.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
import warnings

from real_drive import DRIVES, Task, clean_records, trial_records, truth_line

import backlashkit as bk
from backlashkit.errors import PriorMismatchWarning
from backlashkit.parallel import ProgressBar, map_tasks, task_seeds

#: Backlash half-widths of the default rows (rad): none, then about 1, 3 and 10 times the
#: standard error of theta near 0 on paper A's drive at 40 dB (about 1e-5 rad).
THETAS = (0.0, 1e-5, 3e-5, 1e-4)


def one_trial(pair) -> dict:
    """The fit of one trial's records: its interval, or its refusal's message."""
    task, seed = pair
    recs = trial_records(task, seed)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            fit = bk.JointIdentifier(bk.TwoMassDrive(**task.linear), workers=1).fit(recs)
        except bk.InputError as exc:
            return {"error": str(exc)}
    far = any(issubclass(w.category, PriorMismatchWarning) for w in caught)
    return {"theta": fit.theta_, "std": fit.std_, "ci95": list(fit.ci95_),
            "bounded": list(fit.ci95_bounded_), "far": far, "rivals": fit.rival_basins_}


def trial_alone(args, linear, theta: float, k: int) -> None:
    """Rerun trial ``k`` of one ``theta``'s row: its interval, the profile's rise at
    ``theta = 0``, the linear parameter that moved most with its standard error and the
    prior's point's rise (what decides a note of a fit far from the prior,
    ``identify.step.FAR_RISE``, ``FAR_Z``), and the truth's -2 log L against the
    estimate's (``real_drive.truth_line``)."""
    clean = clean_records(linear, theta, (0.0, 0.0), 0.0)
    task = Task(linear, theta, clean, 0, args.snr, 0.0)
    recs = trial_records(task, task_seeds(args.seed, k + 1)[k])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = bk.JointIdentifier(bk.TwoMassDrive(**linear), workers=1).fit(recs)
    at_0 = [r for t, r in fit.profile_ if t == 0.0]
    moved = max(linear, key=lambda n: abs(math.log(fit.params_[n] / linear[n])))
    print(f"theta {theta:g} rad, trial {k}: theta_ {fit.theta_:.3g}, std_ {fit.std_:.3g}, "
          f"ci95_ [{fit.ci95_[0]:.3g}, {fit.ci95_[1]:.3g}], the profile's rise at 0 "
          f"{min(at_0) if at_0 else math.nan:.3g}; {moved} moved most, x"
          f"{fit.params_[moved] / linear[moved]:.3g} (standard error x"
          f"{math.exp(fit.param_std_[moved] / fit.params_[moved]):.3g}), the prior's point "
          f"{fit._prior_rise:.3g} above the estimate; rival basins {fit.rival_basins_}",
          flush=True)
    print(truth_line(linear, theta, (0.0, 0.0), 0.0, recs, fit), flush=True)


def row(args, linear, theta: float) -> None:
    """Run and print one ``theta``'s row."""
    t0 = time.perf_counter()
    clean = clean_records(linear, theta, (0.0, 0.0), 0.0)
    task = Task(linear, theta, clean, 0, args.snr, 0.0)
    with ProgressBar(f"theta {theta:g} rad", quiet=False) as bar:
        res = map_tasks(one_trial, [(task, s) for s in task_seeds(args.seed, args.trials)],
                        jobs=args.jobs, progress=bar)
    ok = [r for r in res if "theta" in r]
    n = max(len(ok), 1)
    band = 2.0 * math.sqrt(0.95 * 0.05 / n)
    zero = sum(r["ci95"][0] == 0.0 for r in ok) / n
    cover = sum(r["ci95"][0] <= theta <= r["ci95"][1] for r in ok) / n
    both = sum(all(r["bounded"]) for r in ok) / n

    def median(key):
        return statistics.median(r[key] for r in ok) if ok else math.nan

    upper = statistics.median(r["ci95"][1] for r in ok) if ok else math.nan
    print(f"{theta:>8.3g} {len(ok):>4}/{len(res):<4} {sum(r['far'] for r in ok):>4} "
          f"{zero:>7.1%} {cover:>7.1%} {f'{0.95 - band:.1%}-{0.95 + band:.1%}':>13} "
          f"{both:>7.1%} {sum(r['rivals'] > 0 for r in ok):>6} {median('theta'):>10.3g} "
          f"{median('std'):>9.3g} {upper:>9.3g} "
          f"{time.perf_counter() - t0:>6.0f}", flush=True)
    missed = [k for k, r in enumerate(res)
              if "theta" in r and not r["ci95"][0] <= theta <= r["ci95"][1]]
    if missed:  # to rerun alone
        print(f"  the interval leaves the truth out in trials {','.join(map(str, missed))}",
              flush=True)
    refused = [k for k, r in enumerate(res) if "error" in r]
    if refused:
        print(f"  refused in trials {','.join(map(str, refused))}, the first: "
              f"{res[refused[0]]['error']}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=None)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--snr", type=float, default=40.0, help="the speeds' SNR in dB")
    ap.add_argument("--drive", choices=sorted(DRIVES), default="paper")
    ap.add_argument("--thetas", default=",".join(f"{x:g}" for x in THETAS),
                    help="comma-separated backlash half-widths in rad, one row each")
    ap.add_argument("--trial", type=int, default=None,
                    help="rerun trial K of each row alone and print its profile at 0")
    args = ap.parse_args()
    linear = DRIVES[args.drive][0]
    if args.trial is not None:
        for theta in (float(x) for x in args.thetas.split(",")):
            trial_alone(args, linear, theta, args.trial)
        return
    print(f"{args.drive} drive, {args.snr:g} dB, {args.trials} trials a row (seed {args.seed})")
    print(f"{'theta':>8} {'answered':>9} {'far':>4} {'from 0':>7} {'cover':>7} "
          f"{'2-sigma band':>13} {'bounded':>7} {'rivals':>6} {'theta_':>10} {'std_':>9} "
          f"{'upper':>9} {'s':>6}")
    for theta in (float(x) for x in args.thetas.split(",")):
        row(args, linear, theta)


if __name__ == "__main__":
    main()
