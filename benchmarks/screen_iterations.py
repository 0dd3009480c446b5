"""Benchmark: how the joint fit's screened refits decide, trial by trial (issue 24).

Two stages of the joint fit refit a point from another start for a few iterations
and go on only where it is below its reference by then:

* the search's restarts (``_search.restart``): ``RESTART_SCREEN_ITER`` iterations on
  the longest short window, against the best solution refined there;
* the profile's rechecks of its ends from the prior's point
  (``intervals._HeldTheta.recheck``): ``RECHECK_SCREEN_ITER`` iterations on the
  final data with ``theta`` held, against the refit continued from the estimate. A
  recheck whose start costs more than ``RECHECK_FAR`` times the estimate's cost above
  it is not run (``--no-far`` runs it anyway).

For each kind it prints how many were screened, how many ended the screen below
their reference, at which iteration those first went below (a histogram: what a
shorter screen would have lost), and how many lowered the fit; for the restarts also
how many rival basins the search handed the interval (``_search.rivals_of``: other
minima within 3.84 above the best on the whole records). For the rechecks it
also prints where they started: their start's cost above the estimate's, over the
estimate's cost, for those that ended below and for the rest.

Scenarios: one of ``benchmarks/real_drive.py`` (``--drive``, ``--effect``, ``--snr``,
its trials ``--trials A:B`` drawn from the same seeds as its rows, the prior at the
truth, or drawn about it with ``--prior-rel-std`` as there), or paper A's protocol
(``--protocol N``: seeds ``0`` to ``N - 1`` at ``Err_p = 0.3``).

Run: ``python benchmarks/screen_iterations.py --drive other --effect coulomb --snr 30
--trials 0:100 [--prior-rel-std S] [--jobs 2] [--no-far]``, or
``python benchmarks/screen_iterations.py --protocol 10 [--no-far]``.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from collections import Counter
from functools import partial

import numpy as np
import real_drive as rd

import backlashkit as bk
import backlashkit.identify._lm as lm_mod
import backlashkit.identify._search as search_mod
import backlashkit.identify.intervals as intervals_mod
from backlashkit.papers.ravanbod2002 import protocol_records
from backlashkit.parallel import ProgressBar, map_tasks

#: Paper A's prior error in the protocol's records.
ERR_P = 0.3
#: A refit "lowered the fit" where it ended below its reference by more than this
#: (chi-square units): below it, it reached the same point from another side.
LOWERED = 0.05


class Watch:
    """Every screened refit of one fit: its cost above its reference after each
    iteration."""

    def __init__(self) -> None:
        self.restarts: dict[int, tuple[object, list[float]]] = {}  # by id of its state
        self.rechecks: list[dict] = []
        self.restart_gain = 0.0
        self.rivals = 0

    def step(self, real, state, fun, *args):
        """``_lm._step``, noting the iterations of the screened refits."""
        ok = real(state, fun, *args)
        f = sys._getframe(1)
        while f.f_code.co_name in ("lm", "refine"):
            f = f.f_back
        loc = f.f_locals
        if f.f_code.co_name == "restart" and "ref" in loc and len(state.r) == len(loc["ref"].r):
            # the state is kept with its costs, so that its id is not reused
            self.restarts.setdefault(id(state), (state, []))[1].append(
                state.cost - loc["ref"].cost)
        elif f.f_code.co_name == "recheck":
            held = loc["self"]
            self.rechecks[-1]["costs"].append(
                state.cost - held.fit.cost - held._rises[loc["sign"], loc["d"]])
        return ok

    def restart(self, real, pb, best, *args, **kw):
        """``_search.restart``, noting how much it lowered the fit and the rival basins
        it returned."""
        out, rivals = real(pb, best, *args, **kw)
        self.restart_gain += best.cost - out.cost
        self.rivals += len(rivals)
        return out, rivals

    def recheck(self, real, held, sign, memo, d):
        """``_HeldTheta.recheck``, noting its start and how much it lowered the end."""
        before = held.rise(sign, memo, d)
        r0 = held._residual(held.fit.z[0] + sign * d, held.fit.anchor)
        note = {"start": (float(r0 @ r0) - held.fit.cost) / held.fit.cost, "costs": []}
        self.rechecks.append(note)
        after = real(held, sign, memo, d)
        note["gain"] = before - after
        return after


def watched_fit(recs, prior, no_far: bool, **kw) -> dict:
    """One default fit (``kw``: its other options), its screens watched."""
    w = Watch()
    saved = (lm_mod._step, search_mod.restart, intervals_mod._HeldTheta.recheck,
             intervals_mod.RECHECK_FAR)
    lm_mod._step = partial(w.step, saved[0])
    search_mod.restart = partial(w.restart, saved[1])
    intervals_mod._HeldTheta.recheck = lambda held, *a: w.recheck(saved[2], held, *a)
    if no_far:
        intervals_mod.RECHECK_FAR = math.inf
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bk.JointIdentifier(prior, workers=1, **kw).fit(recs)
    finally:
        (lm_mod._step, search_mod.restart, intervals_mod._HeldTheta.recheck,
         intervals_mod.RECHECK_FAR) = saved
    return {"restarts": [costs for _, costs in w.restarts.values()],
            "restart_gain": w.restart_gain, "rechecks": w.rechecks, "rivals": w.rivals}


def protocol_trial(no_far, seed):
    """Paper A's protocol records of one seed."""
    rec1, rec2, prior = protocol_records(ERR_P, seed)
    return watched_fit([rec1, rec2], prior, no_far)


def drive_trial(task, no_far, seed):
    """One trial of a ``real_drive.py`` scenario, its records and prior drawn as there."""
    prior, kw = rd.trial_prior(task.linear, task.prior_rel_std, seed)
    return watched_fit(rd.trial_records(task, seed), bk.TwoMassDrive(**prior), no_far, **kw)


def first_below(costs: list[float], screen: int) -> int | None:
    """The iteration (from 1) at which a screen first went below its reference, or
    None where it did not within ``screen`` iterations."""
    return next((i + 1 for i, c in enumerate(costs[:screen]) if c < 0), None)


def report(res: list[dict], no_far: bool) -> None:
    """Print the screens' counts, histograms and starts."""
    screen = search_mod.RESTART_SCREEN_ITER
    restarts = [c for r in res for c in r["restarts"]]
    below = [first_below(c, screen) for c in restarts]
    hist = Counter(b for b in below if b is not None)
    print(f"restarts: {len(restarts)} screened, {sum(b is not None for b in below)} ended "
          f"the screen ({screen} iterations) below the reference, first below at "
          f"iteration {dict(sorted(hist.items()))}; they lowered the fit by more than "
          f"{LOWERED} in {sum(r['restart_gain'] > LOWERED for r in res)} of "
          f"{len(res)} fits")
    print(f"rival basins (other minima within 3.84 above the best on the whole records, "
          f"the stage's and the restarts'): {sum(r['rivals'] for r in res)} in "
          f"{sum(r['rivals'] > 0 for r in res)} of {len(res)} fits")
    screen = intervals_mod.RECHECK_SCREEN_ITER
    rechecks = [c for r in res for c in r["rechecks"]]
    far = sum(c["start"] > intervals_mod.RECHECK_FAR for c in rechecks)
    won = [c for c in rechecks if c["gain"] > LOWERED]
    hist = Counter(first_below(c["costs"], screen) for c in won)
    print(f"rechecks: {len(rechecks)}, {far} of them starting more than RECHECK_FAR = "
          f"{intervals_mod.RECHECK_FAR:g} times the estimate's cost above it "
          f"({'run' if no_far else 'not run'}); {len(won)} lowered an end by more than "
          f"{LOWERED}, first below at iteration {dict(sorted(hist.items(), key=str))}")
    for name, group in (("lowered an end", won),
                        ("did not", [c for c in rechecks if c not in won])):
        starts = [c["start"] for c in group]
        if starts:
            print(f"  start above the estimate's cost, over that cost, where it {name}: "
                  f"{min(starts):.3g} to {max(starts):.3g} (median "
                  f"{float(np.median(starts)):.3g}, {len(starts)} rechecks)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--protocol", type=int, default=0,
                    help="paper A's protocol, seeds 0 to N - 1, instead of a scenario")
    ap.add_argument("--drive", default="other", choices=sorted(rd.DRIVES))
    ap.add_argument("--effect", default="coulomb", choices=[*rd.EFFECTS, *rd.EXTENDED])
    ap.add_argument("--snr", type=float, default=rd.SNR)
    ap.add_argument("--trials", default="0:20", help="A:B, the scenario's trials A to B - 1")
    ap.add_argument("--seed", type=int, default=2020, help="real_drive.py's --seed")
    ap.add_argument("--prior-rel-std", type=float, default=0.0,
                    help="real_drive.py's: a prior of the linear parameters drawn about "
                         "the truth with this relative std")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--no-far", action="store_true",
                    help="run the rechecks that start far above too (RECHECK_FAR = inf)")
    args = ap.parse_args(argv)
    if args.protocol:
        bar = ProgressBar("paper A's protocol", quiet=False)
        res = map_tasks(partial(protocol_trial, args.no_far),
                        [np.random.SeedSequence(k) for k in range(args.protocol)],
                        jobs=args.jobs, progress=bar)
        bar.close()
        print(f"paper A's protocol, Err_p {ERR_P}, seeds 0 to {args.protocol - 1}")
    else:
        first, stop = (int(x) for x in args.trials.split(":"))
        linear, theta = rd.DRIVES[args.drive]
        fc, tau, counts = {**rd.EFFECTS, **rd.EXTENDED}[args.effect]
        task = rd.Task(linear, theta, rd.clean_records(linear, theta, fc, tau, counts),
                       counts, args.snr, args.prior_rel_std)
        seeds = rd.task_seeds(rd.scenario_seeds(args.seed)[args.drive, args.effect], stop)
        bar = ProgressBar(f"{args.drive}, {args.effect}", quiet=False)
        res = map_tasks(partial(drive_trial, task, args.no_far), seeds[first:],
                        jobs=args.jobs, progress=bar)
        bar.close()
        print(f"{args.drive}, {args.effect}, {args.snr:g} dB, trials {first} to {stop - 1}"
              + (f", prior rel. std {args.prior_rel_std:g}" if args.prior_rel_std else ""))
    report(res, args.no_far)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
