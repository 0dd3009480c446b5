"""Benchmark: the current loop's score test against the fit it spares (issue 24).

The joint estimator tests a current loop (``actuator="auto"``) by fitting the model with
it from four starts, which costs about half a default fit on paper A's records. A
score test at the fit without it (``backlashkit.identify._score``) predicts what that
fit finds, and where the predicted fall of ``-2 log L`` is below
``terms.SCREEN_DROP`` the loop is dropped unfitted. This benchmark runs every fit
with the screen off, so the loop is always fitted, and puts each trial's prediction
beside what the fit found:

* ``screened``: trials the screen would have dropped unfitted;
* ``of them kept`` / ``widened``: those among them that the fitted test kept, or
  where it widened the interval to the other model's (the screen changes the
  answer only there: both must be 0 for the screen to change no choice);
* ``fitted kept``: trials the test kept, and the smallest predicted fall among them;
* ``fall / rise``: median ratio of the predicted fall to the fitted rise where both
  exceed 1 (the linearisation's accuracy).

Scenarios: paper A's two 80 s records (its protocol at Err_p 0.3), and the 8 s records
of ``benchmarks/real_drive.py`` made by the independent scipy reference (nothing,
Coulomb friction, a 1 ms loop, both; both drives; 40 dB), one ``SeedSequence`` child
per trial.

Run: ``python benchmarks/score_screen.py [--trials 20] [--jobs 2]``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import warnings

import numpy as np
import real_drive as rd

import backlashkit as bk
import backlashkit.identify._score as score_mod
import backlashkit.identify._search as search_mod
from backlashkit.identify.terms import SCREEN_DROP, TermChoice
from backlashkit.papers.ravanbod2002 import protocol_records
from backlashkit.parallel import ProgressBar, map_tasks

#: Scenarios of ``real_drive.py`` checked beside paper A's protocol.
EFFECTS = ("ideal", "coulomb", "loop 1 ms", "coulomb + loop")
#: Paper A's prior error in the protocol's records.
ERR_P = 0.3


def fit_both_ways(recs, prior) -> dict:
    """Fit with the screen off; the score test's prediction and the fitted test's
    choice of the loop."""
    seen: dict = {}
    real_test, real_decide = search_mod.score_test, TermChoice.decide.__func__

    def test(*args, **kw):
        seen["score"] = real_test(*args, **kw)
        return seen["score"]

    def decide(cls, term, *args, **kw):
        choice = real_decide(cls, term, *args, **kw)
        if term == "actuator" and "score" in seen and "choice" not in seen:
            seen["choice"] = choice
        return choice

    score_mod.SCREEN_DROP, search_mod.score_test = -math.inf, test
    TermChoice.decide = classmethod(decide)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bk.JointIdentifier(prior, workers=1).fit(recs)
    except bk.InputError:
        return {}
    finally:
        score_mod.SCREEN_DROP, search_mod.score_test = SCREEN_DROP, real_test
        TermChoice.decide = classmethod(real_decide)
    if "choice" not in seen:
        return {}
    c = seen["choice"]
    return {"drop": seen["score"].drop, "rise": c.rise, "kept": c.kept,
            "widened": c.other_ci95 is not None}


def protocol_trial(task, seed):
    """Paper A's protocol records of one seed."""
    rec1, rec2, prior = protocol_records(ERR_P, seed)
    return fit_both_ways([rec1, rec2], prior)


def drive_trial(task, seed):
    """One trial of a ``real_drive.py`` scenario (its records drawn the same way)."""
    return fit_both_ways(rd.trial_records(task, seed), bk.TwoMassDrive(**task.linear))


def row(name: str, res: list[dict]) -> None:
    """Print one scenario's comparison."""
    ok = [r for r in res if r]
    screened = [r for r in ok if r["drop"] < SCREEN_DROP]
    kept = [r for r in ok if r["kept"]]
    both = [r["drop"] / r["rise"] for r in ok if r["drop"] > 1 and r["rise"] > 1]
    print(f"{name:<22} {len(ok):>3}/{len(res):<3} {len(screened):>8} "
          f"{sum(r['kept'] for r in screened):>12} {sum(r['widened'] for r in screened):>7} "
          f"{len(kept):>11} "
          f"{min((r['drop'] for r in kept), default=math.nan):>15.3g} "
          f"{statistics.median(both) if both else math.nan:>11.2f}", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=24)
    args = ap.parse_args(argv)
    print(f"screen: predicted fall of -2 log L < {SCREEN_DROP}")
    print(f"{'scenario':<22} {'fits':>7} {'screened':>8} {'of them kept':>12} "
          f"{'widened':>7} {'fitted kept':>11} {'least fall kept':>15} {'fall / rise':>11}")
    root = np.random.SeedSequence(args.seed)
    seeds = root.spawn(1 + len(rd.DRIVES) * len(EFFECTS))
    bar = ProgressBar("paper A's protocol", quiet=False)
    res = map_tasks(protocol_trial, [None] * args.trials, jobs=args.jobs, seed=seeds[0],
                    progress=bar)
    bar.close()
    row("paper A, 80 s", res)
    k = 1
    for dname, (linear, theta) in rd.DRIVES.items():
        for ename in EFFECTS:
            fc, tau, _ = rd.EFFECTS[ename]
            clean = rd.clean_records(linear, theta, fc, tau)
            bar = ProgressBar(f"{dname}, {ename}", quiet=False)
            task = rd.Task(linear, theta, clean, 0, rd.SNR, 0.0)
            res = map_tasks(drive_trial, [task] * args.trials, jobs=args.jobs, seed=seeds[k],
                            progress=bar)
            bar.close()
            row(f"{dname}, {ename}", res)
            k += 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
