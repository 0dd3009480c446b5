"""Robustness of the joint ML identifier away from paper A's drive (issue 3).

Scenarios: backlash half-widths 0.5, 2 and 5 deg; load/motor inertia ratios about 2,
14 (paper A) and 50; SNR 20, 30 and 40 dB on both speeds of both records; prior
errors ``Err_p`` up to 40 % (``P_hat = P* (1 - Err_p X)``, ``X ~ U[-1, 1]`` per linear
parameter). Each trial simulates paper A's two experiments on the drive (80 s
records from rest, torque ``0.1 a_max`` then ``0.6 a_max`` held 40 s, then 0; Ts =
1 ms; white noise at the SNR over the whole record, :func:`signals.add_noise`) and
fits :class:`~backlashkit.identify.joint.JointIdentifier` with its defaults (the
linear parameters refined from the data, no penalty).

Reported per scenario: the Cramér-Rao bound of theta relative to theta (all seven
parameters estimated, both records), mean relative error, worst relative error,
std/CRB, coverage of ``ci95_``; overall, coverage per drive and where the CRB is at
most 2.5 % of theta, how many trials off by more than 5 %, and how
many whose interval misses the truth, have a lower cost at the true parameters than at
the estimate (the optimiser's fault); how many trials beyond 5 % where the CRB is at
most 2.5 % of theta, beside the number an efficient unbiased estimator would give
(``sum 2 Phi(-5 % / CRB)`` over those trials); and, unless the interval is Fisher's,
on how many trials the two intervals disagree and where the ends lie in Fisher
half-widths; the largest residual lag-1 autocorrelation per fit (median, 99th
percentile, max), how many fits ran the second search of ``misfit_restart`` and kept it,
and how many ended with a linear parameter more than 3 times off the prior
(``far_from_prior_``).
``--corr C`` passes the speeds' noise through ``e_t = C e_(t-1) + w_t`` (scaled to the
same SNR; the CRB printed is then that noise's), ``--noise ar`` fits ``ARNoise(2)``
(``white``: ``WhiteNoise()``; default the identifier's ``AutoNoise()``), and
``--torque-noise R`` measures the torque with white noise of std R times the step and
levels it with :func:`backlashkit.torque_levels` before the fit (a speed observer's
coloured noise and a current sensor's torque, as on a real drive).
Issue 3 asks: within 5 % everywhere, about 95 % coverage. Where the CRB itself is above
2.5 % of theta (0.5 deg at 20 dB: 4.6-7.2 %), no unbiased estimator stays within 5 %
in 95 % of the trials, so the summary also gives the worst error over the other
scenarios and the count of trials beyond ``max(5 %, 3 CRB)``.

Run: ``python benchmarks/robustness_joint.py [--trials 20] [--seed 5] [--jobs 2]
[--stiffness-grid 9] [--split-shifts 0.5] [--stiffness-restarts 0.15,0.4,0.8]
[--friction-restarts 1.0] [--no-misfit-restart] [--search-factor 3]
[--final-horizon H]
[--fine-horizons 0.25,0.6,1.6] [--ambiguity-starts 4] [--interval profile|fisher]
[--bootstrap N] [--scenarios 0,1,...] [--corr 0.8 --noise ar --torque-noise 0.01]
[--dump FILE]``. ``--interval`` chooses the
interval (default the profile likelihood, the identifier's default); ``--bootstrap N``
gives every fit ``ParametricBootstrap(N, seed=trial index)`` (N + 1 fits per trial).
Unless the interval is Fisher's, the coverage of the Fisher interval of the same fits
is reported beside it;
``--scenarios`` runs only the listed rows (0-8: J_L/J_M = 2, 9-17: 14, 18-26: 51).
Trial ``i`` of a scenario uses ``SeedSequence([seed, scenario index]).spawn(trials)[i]``,
so results do not depend on ``--jobs``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
import warnings
from pathlib import Path

import numpy as np

import backlashkit as bk
from backlashkit import signals
from backlashkit.errors import PriorMismatchWarning, SensitivityWarning
from backlashkit.identify import Record
from backlashkit.identify.crb import cramer_rao_bound
from backlashkit.identify.intervals import FisherInterval, ParametricBootstrap, ProfileLikelihood
from backlashkit.identify.joint import JointIdentifier
from backlashkit.identify.search import Continuation, FirstHorizon, JointSearch, Restarts, ThetaGrid
from backlashkit.parallel import ProgressBar, map_tasks

BASE = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
#: load inertia -> label (ratio J_L / J_M about 2, 14, 50)
INERTIAS = {1.0e-2: "J_L/J_M=2", 6.8e-2: "J_L/J_M=14", 0.25: "J_L/J_M=51"}
THETAS_DEG = (0.5, 2.0, 5.0)
SNRS = (20.0, 30.0, 40.0)
T_S, TS, A_MAX = 40.0, 1e-3, 1.57


def scenarios(err_p: float):
    """(index, drive, snr, err_p) for every combination."""
    combos = itertools.product(INERTIAS, THETAS_DEG, SNRS)
    for k, (j_l, th, snr) in enumerate(combos):
        yield k, bk.TwoMassDrive(**{**BASE, "J_L": j_l}, theta=math.radians(th)), snr, err_p


def records(drive, snr, seed, corr: float = 0.0, torque_noise: float = 0.0):
    """Paper A's two experiments on ``drive``: white noise at ``snr`` dB on both speeds
    (``corr`` > 0: through ``e_t = corr e_(t-1) + w_t``, scaled to the same SNR), and
    ``torque_noise`` > 0: the torque measured with white noise of that std relative to
    the step, then levelled by :func:`backlashkit.torque_levels` as a user would."""
    from colored_noise import colored

    t = signals.time_grid(2 * T_S, TS)
    out = []
    for a, ss in zip((0.1 * A_MAX, 0.6 * A_MAX), seed.spawn(2), strict=True):
        with warnings.catch_warnings():  # grazing bounces late in the coast-down: far
            warnings.simplefilter("ignore", SensitivityWarning)  # below the noise
            r = drive.simulate(t, signals.step_down(t, a, t_s=T_S))
        sm, sl, st = ss.spawn(3)  # the first two as spawn(2) gave them: white unchanged
        if corr:
            w_m, w_l = (colored(w, snr, corr, np.random.default_rng(s_))
                        for w, s_ in ((r.w_motor, sm), (r.w_load, sl)))
        else:
            w_m, w_l = (signals.add_noise(r.w_motor, snr, rng=sm),
                        signals.add_noise(r.w_load, snr, rng=sl))
        torque = r.torque
        if torque_noise:
            torque = torque + torque_noise * a * np.random.default_rng(st).standard_normal(
                t.size)
        rec = Record(t, torque, w_m, w_l)
        out.append(bk.torque_levels(rec) if torque_noise else rec)
    return out


def trial(task):
    drive, snr, err_p, seed, options, corr, torque_noise = task
    s_rec, s_prior = seed.spawn(2)
    recs = records(drive, snr, s_rec, corr, torque_noise)
    names = ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh")
    x = np.random.default_rng(s_prior).uniform(-1, 1, len(names))
    prior = bk.TwoMassDrive(**{n: getattr(drive, n) * (1 - err_p * xi)
                               for n, xi in zip(names, x, strict=True)})
    with warnings.catch_warnings():  # far_from_prior_ is counted instead
        warnings.simplefilter("ignore", SensitivityWarning)
        warnings.simplefilter("ignore", PriorMismatchWarning)
        # the study measures the estimator: a fit far from the prior is counted, where
        # a user's fit would be refused
        fit = JointIdentifier(prior, workers=1, allow_far_from_prior=True, **options).fit(recs)
        # diagnosis: weighted cost (the fit's noise model) at the truth and at the fit;
        # truth lower = the optimiser missed the global minimum, not a limit of the data
        costs = [sum(_cost(fit, k, (rec.w_motor, rec.w_load), (r.w_motor, r.w_load))
                     for k, (rec, r) in enumerate(zip(
                         recs, (d.simulate(rec.t, rec.torque) for rec in recs), strict=True)))
                 for d in (drive, fit.drive_)]
    fisher = fit.param_std_["theta"]
    # -2 log L with white noise of unknown level per channel, less its constant: where
    # two codes end a trial apart, the lower is the better fit of the same records
    from real_drive import concentrated_m2ll

    m2ll = concentrated_m2ll(fit)
    return (fit.theta_, fit.std_, fit.ci95_, costs[0] < costs[1], fisher, fit.ambiguous_,
            fit.ci95_bounded_, float(np.max(np.abs(fit.residual_lag1_))),
            fit.misfit_restarted_, fit.misfit_restart_won_, bool(fit.far_from_prior_), m2ll)


def _cost(fit, k: int, measured, simulated) -> float:
    """The fit's cost of record ``k``'s speeds against ``simulated``: residuals whitened
    by its ``ARNoise`` polynomial (if any) over its innovation std."""
    from scipy.signal import lfilter

    total = 0.0
    for c, (y, x) in enumerate(zip(measured, simulated, strict=True)):
        e = y - x
        if fit.noise_ar_ is not None:
            a = fit.noise_ar_[k, c]
            e = lfilter(np.r_[1.0, a], [1.0], e)[a.size :]
        total += float(np.sum((e / fit.noise_innovation_std_[k, c]) ** 2))
    return total


def crb(drive, snr, corr: float = 0.0):
    """CRB of theta, all parameters estimated, for the two experiments (first-order
    noise of lag-1 correlation ``corr``; white for 0)."""
    t = signals.time_grid(2 * T_S, TS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SensitivityWarning)
        b1, b2 = (cramer_rao_bound(drive, t, signals.step_down(t, a, t_s=T_S), snr_db=snr,
                                   estimate="all", noise_ar=[-corr] if corr else None)
                  for a in (0.1 * A_MAX, 0.6 * A_MAX))
    return (b1 + b2).theta_std


def main() -> None:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--err-p", type=float, default=0.4)
    ap.add_argument("--stiffness-grid", type=int, default=1,
                    help="ThetaGrid(stiffness_points=...) (default 1, its default)")
    ap.add_argument("--split-shifts", default="0.5",
                    help="FirstHorizon(split_shifts=...), comma-separated ('' for none)")
    ap.add_argument("--stiffness-restarts", default="0.15,0.4,0.8",
                    help="Restarts(stiffness=...), log-shifts of k_sh, "
                    "comma-separated ('' for none)")
    ap.add_argument("--friction-restarts", default="1.0",
                    help="Restarts(friction=...), log-shifts of f_M / f_L, "
                    "comma-separated ('' for none, the code before them)")
    ap.add_argument("--no-misfit-restart", action="store_true",
                    help="Restarts(misfit=False) (the code before it)")
    ap.add_argument("--search-factor", default="3",
                    help="FirstHorizon(search_factor=...) ('none' for unbounded)")
    ap.add_argument("--final-horizon", type=float, default=None,
                    help="JointSearch(final_horizon=...) in s (default: whole record)")
    ap.add_argument("--fine-horizons", default="0.25,0.6,1.6",
                    help="Continuation(fine_horizons=...), comma-separated ('' for one "
                    "continuation path, the code before it)")
    ap.add_argument("--ambiguity-starts", type=int, default=4,
                    help="Continuation(ambiguity_starts=...) (default 4, its default; 0: "
                    "off, the code before it)")
    ap.add_argument("--interval", choices=("profile", "fisher"), default="profile",
                    help="JointIdentifier(interval=...) (default profile, its default)")
    ap.add_argument("--bootstrap", type=int, default=0,
                    help="ParametricBootstrap(n_resamples) per fit (default 0: Fisher)")
    ap.add_argument("--scenarios", default="",
                    help="comma-separated scenario rows to run (default all 27)")
    ap.add_argument("--corr", type=float, default=0.0,
                    help="lag-1 correlation of the speeds' first-order noise (default 0: "
                    "white)")
    ap.add_argument("--noise", choices=("auto", "white", "ar"), default="auto",
                    help="JointIdentifier(noise_model=...): AutoNoise() (its default), "
                    "WhiteNoise() or ARNoise(2)")
    ap.add_argument("--torque-noise", type=float, default=0.0,
                    help="torque measured with white noise of this std relative to the "
                    "step, levelled by torque_levels before the fit (default 0: exact)")
    ap.add_argument("--dump", metavar="FILE", default=None,
                    help="also write every trial (scenario, estimate, std, ci95) as JSON")
    args = ap.parse_args()
    def floats(text: str) -> tuple[float, ...]:
        return tuple(float(x) for x in text.split(",") if x.strip())

    search = JointSearch(
        grid=ThetaGrid(stiffness_points=args.stiffness_grid),
        first=FirstHorizon(
            split_shifts=floats(args.split_shifts),
            search_factor=None if args.search_factor == "none" else float(args.search_factor)),
        continuation=Continuation(fine_horizons=floats(args.fine_horizons),
                                  ambiguity_starts=args.ambiguity_starts),
        restarts=Restarts(stiffness=floats(args.stiffness_restarts),
                          friction=floats(args.friction_restarts),
                          misfit=not args.no_misfit_restart),
        final_horizon=args.final_horizon,
    )
    options = {
        "search": search,
        "interval": ProfileLikelihood() if args.interval == "profile" else FisherInterval(),
    }
    if args.noise != "auto":
        options["noise_model"] = bk.ARNoise(2) if args.noise == "ar" else bk.WhiteNoise()
    start = time.perf_counter()
    scen = list(scenarios(args.err_p))
    if args.scenarios:
        rows = {int(x) for x in args.scenarios.split(",")}
        scen = [sc for sc in scen if sc[0] in rows]
    tasks = []
    for k, d, snr, e in scen:
        for i, s in enumerate(np.random.SeedSequence([args.seed, k]).spawn(args.trials)):
            opts = dict(options)
            if args.bootstrap:
                opts["interval"] = ParametricBootstrap(args.bootstrap, seed=i)
            tasks.append((d, snr, e, s, opts, args.corr, args.torque_noise))
    with ProgressBar("robustness", unit="fit") as bar:
        results = map_tasks(trial, tasks, jobs=args.jobs, progress=bar)
    if args.dump:
        rows = [{"scenario": k, "trial": i, "drive": INERTIAS[d.J_L], "theta": d.theta,
                 "theta_deg": math.degrees(d.theta), "snr_db": snr,
                 "estimate": r[0], "std": r[1], "ci95": list(r[2]), "truth_cost_lower": bool(r[3]),
                 "std_fisher": r[4], "ambiguous": bool(r[5]), "ci95_bounded": list(r[6]),
                 "max_abs_lag1": r[7], "misfit_restarted": bool(r[8]),
                 "misfit_restart_won": bool(r[9]), "far_from_prior": r[10], "m2ll": r[11]}
                for (k, d, snr, _), chunk_start in zip(scen, range(0, len(results), args.trials),
                                                       strict=True)
                for i, r in enumerate(results[chunk_start : chunk_start + args.trials])]
        Path(args.dump).write_text(json.dumps(rows, indent=1) + "\n")
    fisher_too = args.bootstrap or args.interval != "fisher"
    print(f"joint ML, Err_p = {args.err_p:.0%}, {args.trials} trials per scenario, "
          f"seed {args.seed}, options {options}, bootstrap {args.bootstrap}, speed noise "
          + (f"first-order, lag-1 {args.corr:g}" if args.corr else "white")
          + (f", torque noise {args.torque_noise:g} of the step, levelled"
             if args.torque_noise else "") + "; "
          "err = (theta_hat - theta) / theta")
    print(f"{'drive':<11} {'theta':>6} {'SNR':>4} | {'CRB%':>5} {'mean err%':>9} "
          f"{'max |err|%':>10} {'std/CRB':>7} {'cover95':>7}"
          + (f" {'Fisher':>7}" if fisher_too else ""))
    n_cover = n_cover_fisher = n_all = n_fail = n_truth_better = n_gross = 0
    n_uncovered = n_uncovered_truth_better = 0
    n_res = n_cover_res = n_fail_res = 0
    expected_fail_res = 0.0  # of an efficient unbiased estimator (error ~ N(0, CRB^2))
    by_ratio: dict[str, list[int]] = {}
    worst = worst_resolvable = 0.0
    thetas = [d.theta for _, d, _, _ in scen for _ in range(args.trials)]
    for i, (_, d, snr, _) in enumerate(scen):
        chunk = results[i * args.trials : (i + 1) * args.trials]
        est = np.array([r[0] for r in chunk])
        err = (est - d.theta) / d.theta
        bound = crb(d, snr, args.corr) / d.theta
        cover = sum(lo <= d.theta <= hi for _, _, (lo, hi), *_ in chunk)
        cover_fisher = sum(abs(r[0] - d.theta) <= 1.96 * r[4] for r in chunk)
        missed = [r[3] for r, e in zip(chunk, err, strict=True) if abs(e) > 0.05]
        uncovered = [r[3] for r in chunk if not r[2][0] <= d.theta <= r[2][1]]
        n_uncovered += len(uncovered)
        n_uncovered_truth_better += sum(uncovered)
        n_fail += len(missed)
        n_truth_better += sum(missed)
        n_gross += int(np.sum(np.abs(err) > max(0.05, 3 * bound)))
        n_cover += cover
        n_cover_fisher += cover_fisher
        n_all += len(chunk)
        worst = max(worst, float(np.max(np.abs(err))))
        if bound <= 0.025:
            worst_resolvable = max(worst_resolvable, float(np.max(np.abs(err))))
            n_res += len(chunk)
            n_cover_res += cover
            n_fail_res += len(missed)
            expected_fail_res += len(chunk) * math.erfc(0.05 / bound / math.sqrt(2.0))
        tally = by_ratio.setdefault(INERTIAS[d.J_L], [0, 0])
        tally[0] += cover
        tally[1] += len(chunk)
        print(f"{INERTIAS[d.J_L]:<11} {math.degrees(d.theta):5.1f}d {snr:4.0f} | "
              f"{100 * bound:5.2f} {100 * np.mean(err):9.2f} {100 * np.max(np.abs(err)):10.2f} "
              f"{np.std(est, ddof=1) / (bound * d.theta):7.2f} {cover:3d}/{len(chunk):<3d}"
              + (f" {cover_fisher:3d}/{len(chunk):<3d}" if fisher_too else ""))
    print(f"overall: worst |err| {100 * worst:.2f} % ({100 * worst_resolvable:.2f} % where "
          f"CRB <= 2.5 % of theta), coverage {n_cover}/{n_all} = "
          f"{100 * n_cover / n_all:.1f} %; {time.perf_counter() - start:.0f} s")
    print("coverage by drive: " + ", ".join(f"{k} {c}/{n}" for k, (c, n) in by_ratio.items())
          + f"; where CRB <= 2.5 % of theta: {n_cover_res}/{n_res} = "
          f"{100 * n_cover_res / max(n_res, 1):.1f} %")
    if fisher_too:
        print(f"coverage of the Fisher interval of the same fits: {n_cover_fisher}/{n_all} = "
              f"{100 * n_cover_fisher / n_all:.1f} %")
        fisher_ok = [abs(r[0] - t) <= 1.96 * r[4] for r, t in zip(results, thetas, strict=True)]
        own_ok = [r[2][0] <= t <= r[2][1] for r, t in zip(results, thetas, strict=True)]
        differ = [o for f, o in zip(fisher_ok, own_ok, strict=True) if f != o]
        print(f"the two intervals disagree on {len(differ)} trials, {sum(differ)} of them "
              "covered by this one")
        lower = [(r[0] - r[2][0]) / (1.96 * r[4]) for r in results]
        upper = [(r[2][1] - r[0]) / (1.96 * r[4]) for r in results]
        print("ends in Fisher half-widths, 5th-95th percentile: below "
              f"{np.percentile(lower, 5):.2f}-{np.percentile(lower, 95):.2f}, above "
              f"{np.percentile(upper, 5):.2f}-{np.percentile(upper, 95):.2f}")
    caveat = (" (over the whole records, which --final-horizon does not fit)"
              if args.final_horizon else "")
    print(f"trials beyond 5 % where CRB <= 2.5 % of theta: {n_fail_res} of {n_res} "
          f"(an efficient unbiased estimator: {expected_fail_res:.1f} expected)")
    print(f"trials beyond max(5 %, 3 CRB): {n_gross} of {n_all}")
    n_amb = sum(bool(r[5]) for r in results)
    print(f"ambiguous searches (JointIdentifier.ambiguous_): {n_amb} of {n_all}")
    lag1 = np.array([r[7] for r in results])
    print(f"largest |lag-1| of a residual per fit: median {np.median(lag1):.4f}, 99th "
          f"percentile {np.percentile(lag1, 99):.4f}, max {np.max(lag1):.3f}; misfit "
          f"restarts (JointIdentifier.misfit_restarted_): {sum(bool(r[8]) for r in results)}"
          f" of {n_all}, {sum(bool(r[9]) for r in results)} of them kept")
    print("fits with a linear parameter more than 3 times off the prior "
          f"(JointIdentifier.far_from_prior_): {sum(r[10] for r in results)} of {n_all}")
    n_open = sum(not all(r[6]) for r in results)
    print(f"intervals with an open end (JointIdentifier.ci95_bounded_): {n_open} of {n_all}")
    print(f"intervals missing the truth: {n_uncovered}; in {n_uncovered_truth_better} of them "
          f"the true parameters have a lower cost than the estimate{caveat}")
    print(f"trials off by more than 5 %: {n_fail}; in {n_truth_better} of them the true "
          f"parameters have a lower cost than the estimate (a missed global minimum){caveat}")


if __name__ == "__main__":
    main()
