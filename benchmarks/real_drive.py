"""Benchmark: the joint estimator on drives as they are (issue 20).

1. Coverage study (default): records made by the independent scipy reference
   (:func:`backlashkit.verify.reference_simulate`), 8 s at 1 ms, paper A's two torque
   levels held from the steady state and stepped down to 0 at 2 s, the true linear
   parameters as prior. The speeds get 40 dB of white noise, or, in the encoder
   scenarios, are the differenced counts of 16 384-count encoders reading the
   reference's exact angles (:func:`backlashkit.verify.reference_angles`) from a
   random start within a count. Per scenario (drive x what it has: nothing, Coulomb
   friction, a current loop, both, encoders, all three) the clean reference is
   simulated once and every trial adds its own noise or encoder offsets (a
   ``SeedSequence`` child per trial, so results do not depend on ``--jobs``). Printed
   per scenario: fits answered, median and largest |theta error| in %, how often the
   95 % interval covers the truth with its 2-binomial-standard-deviation band, how
   often ``friction="auto"`` and ``actuator="auto"`` kept each term, and the median
   rise of ``-2 log L`` and shift of ``theta`` (in its standard errors) without the
   current loop (``TermChoice``). The Cramér-Rao bound of theta for the model with the
   scenario's terms (``CRB %``, analogue speeds only) and the number of fits beyond
   max(5 %, 3 CRB) (``beyond``). Below the row: its trial of largest error, and the
   standard deviation of ``theta`` over the trials beside the median ``std_`` the fits
   report. ``--effects extended`` runs the extended scenarios:
   half and three times the Coulomb torques, loops of 0.5 and 2 ms, encoders of 4 096
   and 65 536 counts.
2. ``--offsets``: one record pair of encoder angles read from ``--trials`` random
   offsets, fitted with ``friction="viscous"`` and no loop: the spread of ``theta``
   against the standard error of the quantisation (``std_``) and of white noise.
3. ``--speed``: paper A's two 80 s records (its protocol at Err_p 0.3, one seed) fitted
   with ``friction="viscous"``, ``"coulomb"`` and the default ``"auto"`` (the last two
   against the first, as ratios of medians), one worker thread, in one process; in
   wall time and in the process's CPU time (which other jobs on a busy machine do not
   lengthen). With ``--trial K``, the default fit of trial ``K`` of each scenario of
   ``--drives`` and ``--effects`` instead, ``--repeats`` times.

Run: ``python benchmarks/real_drive.py [--trials 200] [--jobs 2] [--drives paper,other]
[--effects "ideal,coulomb,loop 1 ms,coulomb + loop,encoder,all three" | extended]
[--speed --repeats 3] [--crb] [--offsets] [--trial K]``; ``--trial K`` reruns trial
``K`` alone (the study prints its trial of largest error; ``--trial A:B`` each of trials
``A`` to ``B - 1`` in turn) and prints its fitted parameters against the truth, each
term test's reason, the profile's refits (``theta`` and the rise of the cost at each)
and (analogue speeds) ``-2 log L`` of the true drive against the estimate's, and that of
the minimum nearest the truth (:func:`truth_basin_line`: another basin, or one the
search missed); ``--trial K,L,M`` reruns the trials listed (a row prints those beyond
its error limit so); on analogue records of a drive with a current loop it also refits
them with the loop's lag held at its true value, a check of the profile interval
(:func:`held_loop_check`), and with ``--free-loop`` from each of the lag's starts with
the lag next to free (:func:`free_loop_lines`). ``--profile-grid N`` adds the profile's
rise at ``N`` held ``theta`` each side of the estimate, against the parabola of its
standard error (:class:`GridProfile`). ``--snr DB`` sets the analogue speeds' noise
(default 40 dB). ``--kernel-records`` makes the analogue records with the compiled
kernel the estimator fits with instead of the scipy reference (a diagnostic: where a row
is the same either way, what it shows is the estimator's statistics, not the two
simulators' differences). ``--prior-rel-std S`` gives each fit a prior of the linear
parameters with relative std ``S`` instead of the truth without one: each trial's prior
values drawn about the truth with that std (:func:`trial_prior`), as a prior that says
what it knows.

A row too long for one run is measured in slices, each of one scenario (one
``--drives`` and one ``--effects``): ``--slice A:B --save FILE`` runs trials ``A`` to
``B - 1`` of ``--trials`` with the seeds the whole row gives them and writes their
results with the git objects of the code they ran (``python/``, ``crates/`` and this
script; it refuses uncommitted changes there); ``--merge FILE ...`` prints the row
from slices that tile the trials with one seed, SNR and code; ``--against OTHER`` adds
the trials whose interval holds the truth in one of the two rows only (another saved
row of the same drive and trials, e.g. with another prior or code).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import norm

import backlashkit as bk
from backlashkit.identify.crb import LINEAR_PARAMS, cramer_rao_bound
from backlashkit.identify.intervals import ProfileLikelihood, _HeldTheta
from backlashkit.identify.terms import TAU_START_SAMPLES
from backlashkit.papers.ravanbod2002 import A1, A2, P_TRUE, THETA, protocol_records
from backlashkit.parallel import ProgressBar, map_tasks, task_seeds
from backlashkit.verify import reference_angles, reference_simulate

#: Records' length, step-down time, sample time (s); the speeds' default SNR (dB,
#: ``--snr``: issue 20 asks for 30-40 dB).
T_END, T_STEP, TS, SNR = 8.0, 2.0, 1e-3, 40.0
#: A second drive: stiffer, a lighter load, a smaller backlash.
OTHER = ({"J_M": 2.0e-3, "J_L": 2.5e-2, "k_sh": 150.0, "f_M": 3e-3, "f_L": 4e-3,
          "f_sh": 1.0e-2}, 0.02)
#: What the drives have: Coulomb torques (N m, about 1 and 2 % of the larger torque),
#: the current loop's time constant (s), and the encoders' counts per revolution
#: (0: analogue speeds with 40 dB of white noise).
EFFECTS = {"ideal": ((0.0, 0.0), 0.0, 0), "coulomb": ((0.01, 0.02), 0.0, 0),
           "loop 1 ms": ((0.0, 0.0), 1e-3, 0), "coulomb + loop": ((0.01, 0.02), 1e-3, 0),
           "encoder": ((0.0, 0.0), 0.0, 16384),
           "all three": ((0.01, 0.02), 1e-3, 16384)}
#: The extended scenarios: half and three times the Coulomb torques, a faster and a
#: slower loop, a coarser and a finer encoder (``--effects extended``).
EXTENDED = {"coulomb x0.5": ((0.005, 0.01), 0.0, 0), "coulomb x3": ((0.03, 0.06), 0.0, 0),
            "loop 0.5 ms": ((0.0, 0.0), 5e-4, 0), "loop 2 ms": ((0.0, 0.0), 2e-3, 0),
            "encoder 4096": ((0.0, 0.0), 0.0, 4096),
            "encoder 65536": ((0.0, 0.0), 0.0, 65536)}
#: Errors are judged against max(ERR_FLOOR, CRB_FACTOR x the Cramér-Rao bound of the
#: model with the scenario's terms (issue 20's bar).
ERR_FLOOR, CRB_FACTOR = 0.05, 3.0
#: The median of |z| for a standard normal z (its 75 % point): what the median of
#: ``|theta - truth| / std_`` is where the standard errors are right.
NORMAL_MEDIAN_ABS = 0.674
#: Last word of the spawn key of a trial's prior draw (``--prior-rel-std``): past the
#: children its records spawn, so they are the same with a prior or without.
PRIOR_STREAM = 1 << 20
#: A drawn prior value stays within this many of its relative std of the truth (a
#: positive value at every std the option takes, up to 0.3).
PRIOR_CLIP = 3.0
#: Largest ``--prior-rel-std``: PRIOR_CLIP of it stays below 1.
MAX_PRIOR_REL_STD = 0.3
#: Entropy word of the extended scenarios' seeds.
EXTENDED_STREAM = 1
#: The drives of the study: paper A's and the second one, with their backlash (rad).
DRIVES = {"paper": (P_TRUE, THETA), "other": OTHER}


def crb_theta(linear, theta, fc, tau_i, snr=SNR) -> float:
    """Cramér-Rao bound (rad) of theta from both records at ``snr`` dB, for the
    model with the scenario's terms estimated: theta, the six linear parameters, the
    Coulomb torques where the drive has them and the loop's lag where it has one."""
    drive = bk.TwoMassDrive(**linear, theta=theta, fc_M=fc[0], fc_L=fc[1])
    names = ["theta", *LINEAR_PARAMS] + (["fc_M", "fc_L"] if fc[0] else []) + (
        ["tau_i"] if tau_i else [])
    t = bk.signals.time_grid(T_END, TS)
    bounds = [cramer_rao_bound(drive, t, bk.signals.step_down(t, a, t_s=T_STEP), snr_db=snr,
                               estimate=names, initial_state="steady", tau_i=tau_i)
              for a in (A1, A2)]
    return (bounds[0] + bounds[1]).theta_std
def clean_records(linear, theta, fc, tau_i, counts=0, kernel=False):
    """The noise-free reference records of one scenario: ``(t, u, w_M, w_L)``, or with
    encoders ``(t, u, phi_M, phi_L)``, the exact angles. ``kernel``: the speeds made
    by the compiled kernel the estimator fits with instead (``--kernel-records``)."""
    drive = bk.TwoMassDrive(**linear, theta=theta, fc_M=fc[0], fc_L=fc[1])
    loop = bk.CurrentLoop(tau_i=tau_i) if tau_i else None
    t = bk.signals.time_grid(T_END, TS)
    out = []
    for a in (A1, A2):
        u = bk.signals.step_down(t, a, t_s=T_STEP)
        kw = {"actuator": loop, "initial_state": drive.steady_state(a)}
        if counts:
            out.append((t, u, *reference_angles(drive, t, u, **kw)))
        else:
            ref = (drive.simulate if kernel else partial(reference_simulate, drive))(t, u, **kw)
            out.append((t, u, ref.w_motor, ref.w_load))
    return out


class Task(NamedTuple):
    """What every trial of one scenario shares: the truth (linear parameters in SI,
    ``theta`` in rad), its clean records (:func:`clean_records`), the encoders' counts
    per revolution (0: analogue speeds), the speeds' SNR in dB and the prior's
    relative std (``--prior-rel-std``)."""

    linear: dict
    theta: float
    clean: list
    counts: int
    snr: float
    prior_rel_std: float


def one_trial(task: Task, seed):
    """One trial of a scenario: the fit's theta, interval and choices (with
    ``--prior-rel-std``, about its drawn prior)."""
    prior, kw = trial_prior(task.linear, task.prior_rel_std, seed)
    return _summary(_fit(prior, trial_records(task, seed), **kw))


def trial_prior(linear, rel, seed) -> tuple[dict, dict]:
    """The prior's linear parameters of one trial and the fit's options for it: the
    truth with no prior std (``rel`` 0), else each value drawn about the truth with
    relative std ``rel`` (clipped at :data:`PRIOR_CLIP` of them), from a stream of the
    trial's seed that its records do not use, and given as ``prior_rel_std``."""
    if not rel:
        return linear, {}
    rng = np.random.default_rng(np.random.SeedSequence(seed.entropy,
                                                       spawn_key=(*seed.spawn_key, PRIOR_STREAM)))
    eps = np.clip(rng.standard_normal(len(linear)), -PRIOR_CLIP, PRIOR_CLIP)
    drawn = {n: x * (1.0 + rel * e) for (n, x), e in zip(linear.items(), eps, strict=True)}
    return drawn, {"prior_rel_std": rel}


def _fit(linear, recs, **kw):
    """The joint fit of ``recs`` from the true linear parameters (default options
    unless ``kw``), or the refusal's message."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            return bk.JointIdentifier(bk.TwoMassDrive(**linear), workers=1, **kw).fit(recs)
        except bk.InputError as exc:
            return str(exc)


def _summary(fit) -> dict:
    """What the study keeps of a fit (or of its refusal's message)."""
    if isinstance(fit, str):
        return {"error": fit}
    return {"theta": fit.theta_, "ci95": fit.ci95_, "std": fit.std_,
            "kept": {c.term: c.kept for c in fit.choices_},
            "rise": {c.term: c.rise for c in fit.choices_},
            "shift": {c.term: c.shift for c in fit.choices_}}


def _fitted_line(fit, linear, fc, tau) -> str:
    """The fitted parameters against the truth: linear ones in % off, the rest in SI."""
    off = ", ".join(f"{n} {100 * (fit.params_[n] / x - 1):+.1f} %" for n, x in linear.items())
    return (f"  fitted: {off}; fc_M {fit.fc_M_:.4g} N m (true {fc[0]:g}), fc_L "
            f"{fit.fc_L_:.4g} N m (true {fc[1]:g}), tau_i {1e3 * fit.tau_i_:.3g} ms "
            f"(true {1e3 * tau:g})")


def concentrated_m2ll(fit) -> float:
    """``-2 log L`` (less its constant) of a fit with white noise of unknown level in
    every channel: ``sum n log(SSE / n)`` over its residuals."""
    return residuals_m2ll(e for pair in fit.residuals_ for e in pair)


def residuals_m2ll(residuals) -> float:
    """``sum n log(SSE / n)`` over residual arrays, one per channel."""
    return sum(e.size * math.log(float(np.mean(e ** 2))) for e in residuals)


def steady_errors(drive, recs, loop=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(w_M - sim, w_L - sim)`` per record of ``drive`` simulated by the compiled
    kernel from the records' steady start."""
    sims = [drive.simulate(r.t, r.torque, actuator=loop,
                           initial_state=drive.steady_state(r.torque[0])) for r in recs]
    return [(r.w_motor - sim.w_motor, r.w_load - sim.w_load)
            for r, sim in zip(recs, sims, strict=True)]


def truth_line(linear, theta, fc, tau_i, recs, fit) -> str:
    """``-2 log L`` of the true drive (the compiled kernel from the records' steady
    start) against the fit's: a truth below the estimate means the search stopped
    short of the maximum; above it, the noise favours the estimate."""
    drive = bk.TwoMassDrive(**linear, theta=theta, fc_M=fc[0], fc_L=fc[1])
    loop = bk.CurrentLoop(tau_i=tau_i) if tau_i else None
    rise = (residuals_m2ll(e for pair in steady_errors(drive, recs, loop) for e in pair)
            - concentrated_m2ll(fit))
    return (f"  the truth: -2 log L {rise:+.4g} from the estimate's (white noise of fitted "
            f"level; {'below: the search stopped short' if rise < 0 else 'above it'})")


def basin_params(fc, tau_i) -> tuple[str, ...]:
    """Names of the truth's-basin refit (:func:`truth_basin_line`), refitted in their
    logarithms: theta and the linear parameters, with the Coulomb torques and the
    loop's lag where the drive has them."""
    return ("theta", *LINEAR_PARAMS, *(("fc_M", "fc_L") if fc[0] else ()),
            *(("tau_i",) if tau_i else ()))


def _basin_errors(names, z, recs):
    """:func:`steady_errors` of the drive (and loop) whose ``names`` have logarithms
    ``z``."""
    values = dict(zip(names, np.exp(z), strict=True))
    tau_i = values.pop("tau_i", 0.0)
    drive = bk.TwoMassDrive(**values)
    return drive, steady_errors(drive, recs, bk.CurrentLoop(tau_i=tau_i) if tau_i else None)


def truth_basin_line(linear, theta, fc, tau_i, recs, fit) -> str:
    """The minimum of the likelihood nearest the truth: scipy's least squares from the
    true drive (the true model's terms, :func:`basin_params`), the speeds weighted by
    the fit's noise levels, against the estimate in ``-2 log L`` (as
    :func:`truth_line`). A minimum above the estimate means the records point to the
    estimate, and the profile interval spans the other basin if it reaches it
    (``rival_basins_``); one below, a basin the search missed."""
    sig = np.asarray(fit.noise_std_, float)
    names = basin_params(fc, tau_i)

    def residual(z):
        return np.concatenate([e / s_ for pair, s in zip(_basin_errors(names, z, recs)[1], sig,
                                                          strict=True)
                               for e, s_ in zip(pair, s, strict=True)])

    truth = {"theta": theta, **linear, "fc_M": fc[0], "fc_L": fc[1], "tau_i": tau_i}
    with warnings.catch_warnings():  # steps across grazing contacts
        warnings.simplefilter("ignore")
        z = least_squares(residual, np.log([truth[n] for n in names]), diff_step=1e-6,
                          xtol=1e-12, ftol=1e-12).x
    d, errors = _basin_errors(names, z, recs)
    rise = residuals_m2ll(e for pair in errors for e in pair) - concentrated_m2ll(fit)
    verdict = ("above the estimate: the records point to the estimate" if rise > 0
               else "below the estimate: the search missed it")
    return (f"  the truth's basin: its minimum at theta {100 * (d.theta / theta - 1):+.2f} %, "
            f"k_sh {100 * (d.k_sh / linear['k_sh'] - 1):+.1f} %, "
            f"J_M {100 * (d.J_M / linear['J_M'] - 1):+.1f} %, -2 log L {rise:+.4g} from "
            f"the estimate's, {verdict}; rival basins spanned by the interval: "
            f"{fit.rival_basins_}")


def held_loop_check(linear, theta, recs, fit, tau_i, prior=None, **kw) -> str:
    """The records refitted with Coulomb friction and the loop's lag held at its true
    value. The profile of ``theta`` at that fit's ``theta`` lies at most its rise of
    ``-2 log L`` above the estimate (it minimises over the lag too), so where the rise
    is below 3.84 and that ``theta`` is outside the interval, the profile's refits
    missed a lower valley. ``prior`` and ``kw``: the fit's prior (default the truth's
    linear parameters) and its prior options."""
    held = _fit(prior or linear, recs, friction="coulomb", actuator=bk.CurrentLoop(tau_i=tau_i),
                **kw)
    if isinstance(held, str) or isinstance(fit, str) or fit.noise_ar_ is not None:
        return "  (no check: a refusal or coloured noise)"
    rise = concentrated_m2ll(held) - concentrated_m2ll(fit)
    lo, hi = fit.ci95_
    return (f"  the loop's lag held at {1e3 * tau_i:g} ms: theta {held.theta_:.6g} rad "
            f"({100 * (held.theta_ / theta - 1):+.2f} %), -2 log L {rise:+.3g} from the "
            f"estimate's (white noise of fitted level), "
            f"{'inside' if lo <= held.theta_ <= hi else 'outside'} its 95 % interval")


#: Relative prior stds of :func:`free_loop_lines`: the linear parameters and the lag
#: fitted about the prior's values and a lag's start with stds of 1000 % and 500 %, so
#: that their penalty rows weigh next to nothing against the records (a lag a quarter
#: of its start adds 0.0225 to ``-2 log L``, a linear parameter 20 % off 0.0004).
FREE_LINEAR_STD, FREE_LAG_STD = 10.0, 5.0


def free_loop_lines(linear, theta, recs, fit, prior=None) -> str:
    """The records refitted with Coulomb friction and a current loop whose lag is next
    to free (:data:`FREE_LAG_STD`), once from each of the lag's starts
    (``terms.TAU_START_SAMPLES``, held through the search, then fitted): how far the
    model with a loop lets ``theta`` go at a cost near the estimate's, where the fit
    dropped the loop. ``prior``: the fit's prior values (default the truth's)."""
    rel = {**dict.fromkeys(LINEAR_PARAMS, FREE_LINEAR_STD), "tau_i": FREE_LAG_STD}
    out = ["  the loop next to free, from each start of its lag (theta, its std_, the "
           "lag, -2 log L from the estimate's):"]
    for k in TAU_START_SAMPLES:
        f = _fit(prior or linear, recs, friction="coulomb", prior_rel_std=rel,
                 actuator=bk.CurrentLoop(tau_i=k * recs[0].ts))
        out.append(f"    from {k * recs[0].ts * 1e3:g} ms: " + (
            f"refused ({f})" if isinstance(f, str) else
            f"{100 * (f.theta_ / theta - 1):+.2f} %, {100 * f.std_ / theta:.2f} %, "
            f"{1e3 * f.tau_i_:.3g} ms, {concentrated_m2ll(f) - concentrated_m2ll(fit):+.3g}"))
    return "\n".join(out)


def trial_records(task: Task, seed) -> list:
    """The records of one trial of a scenario: analogue speeds get their noise;
    encoders start at a uniformly random angle within a count."""
    counts, snr = task.counts, task.snr
    recs = []
    for (t, u, y_m, y_l), ss in zip(task.clean, seed.spawn(len(task.clean)), strict=True):
        s_m, s_l = ss.spawn(2)
        if counts:  # the drives log differenced counts as speeds, as issue 20's did
            enc = bk.Encoder(counts)
            w_m, w_l = (enc.measure(t, y + enc.resolution * np.random.default_rng(s_).uniform())
                        .speed for y, s_ in ((y_m, s_m), (y_l, s_l)))
        else:
            w_m, w_l = (bk.signals.add_noise(y_m, snr, rng=s_m),
                        bk.signals.add_noise(y_l, snr, rng=s_l))
        recs.append(bk.Record(t, u, w_m, w_l))
    return recs


def scenario_seeds(seed: int) -> dict[tuple[str, str], np.random.SeedSequence]:
    """Every scenario's ``SeedSequence`` by ``(drive, effect)``, from the study's
    ``--seed``; trial ``i`` draws from its child ``i`` (:func:`task_seeds`)."""
    out = {}
    root = np.random.SeedSequence(seed)
    for i, (dname, ss) in enumerate(zip(DRIVES, root.spawn(len(DRIVES)), strict=True)):
        # the extended scenarios draw from a stream of their own, so adding them left
        # the first six rows' seeds as they were
        extended = np.random.SeedSequence([seed, EXTENDED_STREAM, i])
        for table, seeds in ((EFFECTS, ss.spawn(len(EFFECTS))),
                             (EXTENDED, extended.spawn(len(EXTENDED)))):
            out.update({(dname, ename): ss2 for ename, ss2 in zip(table, seeds, strict=True)})
    return out


def coverage(args) -> None:
    if args.trial is None:  # one trial alone prints a line, not a table
        _print_header()
    seeds = scenario_seeds(args.seed)
    for dname, (linear, theta) in DRIVES.items():
        if dname not in args.drives:
            continue
        for ename, effect in {**EFFECTS, **EXTENDED}.items():
            if ename in args.effects:
                _scenario(args, dname, linear, theta, ename, effect, seeds[dname, ename])


def _print_header() -> None:
    print(f"{'drive':<7} {'has':<15} {'answered':>8} {'|err| med %':>11} {'max %':>7} "
          f"{'CRB %':>6} {'beyond':>6} {'cover':>6} {'2-sigma band':>14} {'fc kept':>8} "
          f"{'loop kept':>9} {'loop rise':>9} {'shift':>6} {'s':>6}")


def _scenario(args, dname, linear, theta, ename, effect, seed) -> None:
    """Run and print one scenario's row."""
    fc, tau, counts = effect
    t0 = time.perf_counter()
    clean = clean_records(linear, theta, fc, tau, counts, kernel=args.kernel_records)
    # quantised angles are not white Gaussian noise: no bound is printed for encoders
    crb = math.nan if counts else crb_theta(linear, theta, fc, tau, args.snr)
    task = Task(linear, theta, clean, counts, args.snr, args.prior_rel_std)
    if args.trial is not None:  # each trial's own seed, as in the whole study's, spawned
        seeds = task_seeds(seed, max(args.trial) + 1)  # once (it spawns anew each call)
        for k in args.trial:
            _trial_alone(args, k, (dname, ename), task, effect, seeds[k])
        return
    first, stop = args.slice or (0, args.trials)
    bar = ProgressBar(f"{dname}, {ename}", quiet=False)
    # trial i's seed is child i of the scenario's, whatever the slice
    res = map_tasks(seeded_trial, [(task, s) for s in task_seeds(seed, stop)[first:]],
                    jobs=args.jobs, progress=bar)
    bar.close()
    seconds = time.perf_counter() - t0
    if args.save:
        save_slice(args, {"drive": dname, "effect": ename, "first": first, "crb": crb,
                          "seconds": seconds, "results": res})
    _print_row(dname, ename, theta, res, crb, seconds, first)


def _trial_alone(args, k, names, task: Task, effect, seed) -> None:
    """Rerun trial ``k`` of a scenario from its ``seed``, as in the whole study, and
    print its fit, its term tests, its profile and the truth's likelihood."""
    linear, theta = task.linear, task.theta
    fc, tau, counts = effect
    recs = trial_records(task, seed)
    prior, kw = trial_prior(linear, task.prior_rel_std, seed)
    grid = GridProfile(n=args.profile_grid) if args.profile_grid else None
    fit = _fit(prior, recs, **kw, **({"interval": grid} if grid else {}))
    print(f"{names[0]}, {names[1]}, trial {k}: {_trial_line(_summary(fit), theta)}", flush=True)
    if grid is not None and not isinstance(fit, str):
        print(_grid_lines(grid, fit, theta), flush=True)
    if task.prior_rel_std:  # the drawn prior's values, off the truth
        print("  prior: " + ", ".join(f"{n} {100 * (prior[n] / x - 1):+.1f} %"
                                      for n, x in linear.items()), flush=True)
    if not isinstance(fit, str):
        print(_fitted_line(fit, linear, fc, tau), flush=True)
        for c in fit.choices_:
            print(f"  {c.reason()}", flush=True)
        if fit.profile_ is not None:
            print(_profile_line(fit.profile_, theta), flush=True)
        if not counts and fit.noise_ar_ is None:
            print(truth_line(linear, theta, fc, tau, recs, fit), flush=True)
            print(truth_basin_line(linear, theta, fc, tau, recs, fit), flush=True)
    if tau and not counts:
        print(held_loop_check(linear, theta, recs, fit, tau, prior, **kw), flush=True)
        if args.free_loop and not isinstance(fit, str):
            print(free_loop_lines(linear, theta, recs, fit, prior), flush=True)


def seeded_trial(pair):
    """:func:`one_trial` of a ``(task, seed)`` pair."""
    return one_trial(*pair)


#: What must agree between the slices of one row (``--merge``).
SLICE_KEYS = ("drive", "effect", "snr", "seed", "trials", "code", "prior_rel_std",
              "kernel_records")


#: What a slice ran, as paths of the repository: the package, the compiled core and
#: this script (its scenarios).
CODE = ("python", "crates", "benchmarks/real_drive.py")


def code_version() -> str:
    """The git objects of :data:`CODE` at ``HEAD``, or an error where any holds
    uncommitted changes: a slice must name the code it ran."""
    root = Path(__file__).resolve().parents[1]

    def git(*cmd: str) -> str:
        return subprocess.run(["git", *cmd], cwd=root, capture_output=True, text=True,
                              check=True).stdout

    if git("status", "--porcelain", *CODE).strip():
        raise SystemExit(f"real_drive.py: --save needs {', '.join(CODE)} committed (a "
                         "slice names the code it ran by their git objects)")
    ids = git("rev-parse", *(f"HEAD:{c}" for c in CODE)).split()
    return ", ".join(f"{c} {i[:12]}" for c, i in zip(CODE, ids, strict=True))


def save_slice(args, row: dict) -> None:
    """Write one scenario's slice of trials, with what its merge checks."""
    path = Path(args.save)
    if path.exists():
        raise SystemExit(f"real_drive.py: {path} exists: choose another --save file")
    doc = {"snr": args.snr, "seed": args.seed, "trials": args.trials,
           "prior_rel_std": args.prior_rel_std, "kernel_records": args.kernel_records,
           "code": code_version(), **row}
    # numpy scalars (a choice's kept flag) as Python values
    path.write_text(json.dumps(doc, indent=1, default=lambda x: x.item()) + "\n")
    print(f"wrote {path} (trials {row['first']} to {row['first'] + len(row['results']) - 1})",
          file=sys.stderr)


def merge(args) -> None:
    """One scenario's row from its saved slices (``--merge``): they must be of one
    scenario, seed and code, and tile its trials."""
    docs = sorted((json.loads(Path(f).read_text()) for f in args.merge),
                  key=lambda d: d["first"])
    for key in SLICE_KEYS:
        # slices saved before --prior-rel-std had no prior std: 0
        if len({str(d.get(key, 0.0)) for d in docs}) > 1:
            raise SystemExit(f"real_drive.py: the slices differ in {key}: "
                             f"{sorted({str(d.get(key, 0.0)) for d in docs})}")
    starts = [d["first"] for d in docs]
    ends = [d["first"] + len(d["results"]) for d in docs]
    # --partial: the first trials of a row not finished (said as such; a band for fewer)
    whole = ends[-1] == docs[0]["trials"] or args.partial
    if starts[0] != 0 or not whole or starts[1:] != ends[:-1]:
        raise SystemExit("real_drive.py: the slices do not tile the trials: "
                         f"{list(zip(starts, ends, strict=True))} of {docs[0]['trials']} "
                         "(--partial takes the first trials alone)")
    if ends[-1] != docs[0]["trials"]:
        print(f"trials 0 to {ends[-1] - 1} of {docs[0]['trials']} only (--partial)")
    theta = DRIVES[docs[0]["drive"]][1]
    res = [r for d in docs for r in d["results"]]
    rel = docs[0].get("prior_rel_std", 0.0)
    print(f"{docs[0]['drive']}, {docs[0]['effect']}: {len(docs)} slices, code "
          f"{docs[0]['code']}, SNR {docs[0]['snr']:g} dB, seed {docs[0]['seed']}"
          + (f", priors drawn with relative std {rel:g}" if rel else "")
          + (", records by the compiled kernel" if docs[0].get("kernel_records") else ""))
    _print_header()
    _print_row(docs[0]["drive"], docs[0]["effect"], theta, res, docs[0]["crb"],
               sum(d["seconds"] for d in docs))
    if args.against:
        _print_against(res, json.loads(Path(args.against).read_text()), docs[0]["drive"],
                       theta)


#: ``--against``: an estimate counts as moved where it differs by more than this
#: relative amount (far above rounding, far below any standard error of these rows).
MOVED = 1e-6


def _print_against(res: list, other: dict, dname: str, theta: float) -> None:
    """The trials covered in the merged row ``res`` (from trial 0) or in the saved row
    ``other`` alone, each with both rows' lines (a change of code or prior: which
    trials it won or lost), and the trials whose estimates moved (:data:`MOVED`)."""
    if other["drive"] != dname or other["first"] != 0 or len(other["results"]) != len(res):
        raise SystemExit("real_drive.py: --against needs a row of the same drive and "
                         "trials, from trial 0")

    def covers(r) -> bool:
        return "theta" in r and r["ci95"][0] <= theta <= r["ci95"][1]

    for name, a, b in (("this row only", res, other["results"]),
                       ("the other row only", other["results"], res)):
        ks = [i for i, (x, y) in enumerate(zip(a, b, strict=True)) if covers(x) and not covers(y)]
        print(f"  covered in {name}: {len(ks)} trials", flush=True)
        for i in ks:
            print(f"    trial {i}: {_trial_line(res[i], theta)}; the other: "
                  f"{_trial_line(other['results'][i], theta)}", flush=True)
    moved = [i for i, (x, y) in enumerate(zip(res, other["results"], strict=True))
             if "theta" in x and "theta" in y and abs(x["theta"] / y["theta"] - 1) > MOVED]
    print(f"  estimates moved by more than {MOVED:g} of theta: {len(moved)} trials"
          + (f" ({', '.join(map(str, moved))})" if moved else ""), flush=True)


def _print_row(dname, ename, theta, res, crb, seconds, first=0) -> None:
    """One scenario's row from its trials' results (trial ``first`` the first)."""
    ok = [r for r in res if "theta" in r]
    err = [abs(r["theta"] / theta - 1) * 100 for r in ok]
    n = len(ok)
    cover = sum(r["ci95"][0] <= theta <= r["ci95"][1] for r in ok) / max(n, 1)
    band = 2 * math.sqrt(0.95 * 0.05 / max(n, 1))
    kept = {term: sum(r["kept"].get(term, False) for r in ok) / max(n, 1)
            for term in ("friction", "actuator")}
    rises = [r["rise"]["actuator"] for r in ok if "actuator" in r["rise"]]
    rise = statistics.median(rises) if rises else math.nan
    shifts = [r["shift"]["actuator"] for r in ok if "actuator" in r["shift"]]
    # nan where the fit without the loop stopped before converging (TermChoice.shift):
    # the median of the others, the count of those below the row
    known = [x for x in shifts if math.isfinite(x)]
    shift = statistics.median(known) if known else math.nan
    floor = ERR_FLOOR if math.isnan(crb) else max(ERR_FLOOR, CRB_FACTOR * crb / theta)
    limit = 100 * floor
    beyond = [first + i for i, r in enumerate(res)
              if "theta" in r and abs(r["theta"] / theta - 1) * 100 > limit]
    print(f"{dname:<7} {ename:<15} {n:>4}/{len(res):<3} "
          f"{statistics.median(err) if err else math.nan:>11.2f} "
          f"{max(err) if err else math.nan:>7.2f} {100 * crb / theta:>6.2f} {len(beyond):>6d} "
          f"{cover:>6.1%} "
          f"{f'{0.95 - band:.1%}-{0.95 + band:.1%}':>14} {kept['friction']:>8.1%} "
          f"{kept['actuator']:>9.1%} {rise:>9.3g} {shift:>6.2f} {seconds:>6.0f}", flush=True)
    if len(known) < len(shifts):
        print(f"  the loop's shift of theta unknown in {len(shifts) - len(known)} fits (the "
              "fit without it stopped before converging); its median is the others'",
              flush=True)
    if err:  # the trial to rerun alone with --trial
        k = max(range(len(res)), key=lambda i: abs(res[i].get("theta", theta) / theta - 1))
        print(f"  largest error in trial {first + k}: {_trial_line(res[k], theta)}",
              flush=True)
        if beyond:  # rerun them with --trial to tell a search's miss from the records'
            print(f"  beyond the error limit of {limit:.3g} %: trials "
                  f"{','.join(map(str, beyond))}", flush=True)
        if n > 1:  # does the interval's width match the estimates' spread?
            spread = statistics.stdev(r['theta'] for r in ok)
            print(f"  theta's standard deviation over the trials {spread:.3g} rad, median "
                  f"std_ {statistics.median(r['std'] for r in ok):.3g} rad", flush=True)
            print(_expected_beyond(n, limit / 100 * theta, crb, spread), flush=True)
            # a bias, or errors wider than std_ says, for every trial or for a few
            z = [abs(r["theta"] - theta) / r["std"] for r in ok if r["std"] > 0]
            print(f"  mean error {statistics.fmean(r['theta'] / theta - 1 for r in ok):+.2%}, "
                  f"median |theta - truth| / std_ {statistics.median(z):.3g} (a normal's: "
                  f"{NORMAL_MEDIAN_ABS})", flush=True)
            _print_by_loop(ok, theta)
    for r in res:
        if "error" in r:
            print(f"  refused: {r['error']}", flush=True)
            break


def _expected_beyond(n: int, limit: float, crb: float, spread: float) -> str:
    """How many of ``n`` fits normal errors would put beyond the error limit (rad): of
    the bound's spread ``crb`` (what the limit assumes), and of the trials' ``spread``."""
    at = ", ".join(f"{2 * n * norm.sf(limit / s):.2g} {what}"
                   for s, what in ((crb, "at the bound"), (spread, "at the trials' spread"))
                   if math.isfinite(s) and s > 0)
    return f"  fits beyond the limit that normal errors would give: {at}"


def _print_by_loop(ok, theta) -> None:
    """Coverage and mean error of the fits that kept the loop and of those that
    dropped it, where the test chose either way (a wrong choice biases theta)."""
    split = {kept: [r for r in ok if r["kept"].get("actuator", False) == kept]
             for kept in (True, False)}
    if not all(split.values()):
        return
    parts = []
    for kept, rs in split.items():
        cover = sum(r["ci95"][0] <= theta <= r["ci95"][1] for r in rs) / len(rs)
        bias = statistics.fmean(r["theta"] / theta - 1 for r in rs)
        parts.append(f"{'kept' if kept else 'dropped'} the loop: {len(rs)}, covers "
                     f"{cover:.1%}, mean error {bias:+.2%}")
    print(f"  fits that {'; '.join(parts)}", flush=True)


#: ``--profile-grid``: the grid spans this many Fisher standard errors either side.
GRID_SPAN = 3.5


@dataclass(frozen=True)
class GridProfile(ProfileLikelihood):
    """The default profile interval, and besides it the profile's rise at ``n`` held
    ``theta`` on each side, evenly up to :data:`GRID_SPAN` Fisher standard errors of
    ``log theta`` (``--profile-grid N``): whether the profile is a parabola there or
    rougher than its curvature. ``points`` gets ``(theta, rise)`` pairs."""

    n: int = 0
    points: list = field(default_factory=list, compare=False)

    def _interval(self, fit):
        found = super()._interval(fit)
        s_z = math.sqrt(fit.cov_z[0, 0])
        for sign in (-1.0, 1.0):
            held, memo = _HeldTheta(fit, self.max_iter), {}
            for d in np.arange(1, self.n + 1) * GRID_SPAN * s_z / self.n:
                self.points.append((math.exp(fit.z[0] + sign * d), held.rise(sign, memo, d)))
        self.points.sort()
        return found


def _grid_lines(grid: GridProfile, fit, theta) -> str:
    """The grid's rises against the parabola of the Fisher standard error, and where
    the truth lies in those errors."""
    lines = [f"  the profile on a grid (z = (theta - estimate) / std_; a parabola rises z^2); "
             f"the truth at z = {(theta - fit.theta_) / fit.std_:+.2f}:"]
    worst = 0.0
    for th, rise in grid.points:
        z = (th - fit.theta_) / fit.std_
        worst = max(worst, abs(rise - z * z))
        lines.append(f"    theta {th:.6g} rad  z {z:+5.2f}  rise {rise:7.3f}  z^2 {z * z:7.3f}")
    lines.append(f"  largest |rise - z^2| on the grid: {worst:.3g}")
    return "\n".join(lines)


def _profile_line(profile, theta) -> str:
    """The profile's refits, by ``theta``: where each held ``theta`` lies from the truth,
    and the rise of the cost (chi-square units) there above the estimate's."""
    points = ", ".join(f"{100 * (th / theta - 1):+.2f} % {rise:.3g}" for th, rise in profile)
    return f"  profile (theta from the truth, rise): {points}"


def _trial_line(r, theta) -> str:
    """One trial's result in words."""
    if "error" in r:
        return f"refused: {r['error']}"
    lo, hi = r["ci95"]
    kept = ", ".join(term for term, k in r["kept"].items() if k) or "no term"
    return (f"theta {r['theta']:.6g} rad ({100 * (r['theta'] / theta - 1):+.2f} %), "
            f"95 % interval [{lo:.6g}, {hi:.6g}], kept {kept}")


def offsets(args) -> None:
    """One record pair of encoder angles read from ``--trials`` random offsets: the
    spread of the estimates against the standard errors the fits report (the
    quantisation's, ``std_``) and white noise's (``param_std_``)."""
    linear, theta = DRIVES["paper"]
    clean = clean_records(linear, theta, (0.0, 0.0), 0.0, EFFECTS["encoder"][2])
    res = map_tasks(offset_trial, [(linear, clean)] * args.trials, jobs=args.jobs,
                    seed=np.random.SeedSequence(args.seed))
    err = np.array([r[0] for r in res]) - theta
    print(f"{args.trials} offsets of one record pair (paper drive, 16 384 counts, "
          "friction='viscous', no loop): spread of theta "
          f"{np.std(err, ddof=1):.3g} rad, median std_ (quantisation) "
          f"{np.median([r[1] for r in res]):.3g} rad, median white-noise std "
          f"{np.median([r[2] for r in res]):.3g} rad; the 95 % interval covers in "
          f"{np.mean([r[3] <= theta <= r[4] for r in res]):.1%}")


def offset_trial(task, seed):
    """``(theta, std, white std, low, high)`` of one fit of the clean angles read by
    encoders from random offsets."""
    linear, clean = task
    enc = bk.Encoder(EFFECTS["encoder"][2])
    recs = []
    for (t, u, phi_m, phi_l), ss in zip(clean, seed.spawn(len(clean)), strict=True):
        off = np.random.default_rng(ss).uniform(size=2) * enc.resolution
        recs.append(bk.Record(t, u, *(enc.measure(t, p + o).speed
                                      for p, o in zip((phi_m, phi_l), off, strict=True))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = bk.JointIdentifier(bk.TwoMassDrive(**linear), workers=1, friction="viscous",
                                 actuator=None).fit(recs)
    return fit.theta_, fit.std_, fit.param_std_["theta"], *fit.ci95_


def speed(args) -> None:
    if args.trial is not None:
        return speed_trials(args)
    r1, r2, prior = protocol_records(0.3, np.random.SeedSequence(args.seed))
    wall: dict[str, list[float]] = {}
    cpu: dict[str, list[float]] = {}
    for _ in range(args.repeats):
        for name in ("viscous", "coulomb", "auto"):
            kw = {"friction": name}
            if name != "auto":
                kw["actuator"] = None
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0, c0 = time.perf_counter(), time.process_time()
                bk.JointIdentifier(prior, workers=1, **kw).fit([r1, r2])
                wall.setdefault(name, []).append(time.perf_counter() - t0)
                cpu.setdefault(name, []).append(time.process_time() - c0)
    base, base_cpu = statistics.median(wall["viscous"]), statistics.median(cpu["viscous"])
    for name, ts in wall.items():
        med, med_cpu = statistics.median(ts), statistics.median(cpu[name])
        print(f"friction={name!r:<10} median {med:6.2f} s over {len(ts)} "
              f"(x{med / base:.2f} the viscous fit); CPU {med_cpu:6.2f} s "
              f"(x{med_cpu / base_cpu:.2f})")


def speed_trials(args) -> None:
    """``--speed --trial K``: the default fit of trial ``K`` of each scenario, timed
    ``--repeats`` times on one thread (median wall and CPU time): the study's own
    records, which the protocol's comparison does not have (a current loop)."""
    seeds = scenario_seeds(args.seed)
    for dname, (linear, theta) in DRIVES.items():
        for ename, effect in {**EFFECTS, **EXTENDED}.items():
            if dname not in args.drives or ename not in args.effects:
                continue
            fc, tau, counts = effect
            task = Task(linear, theta, clean_records(linear, theta, fc, tau, counts), counts,
                        args.snr, args.prior_rel_std)
            trial_seeds = task_seeds(seeds[dname, ename], max(args.trial) + 1)
            for k in args.trial:
                prior, kw = trial_prior(linear, args.prior_rel_std, trial_seeds[k])
                recs = trial_records(task, trial_seeds[k])
                wall, cpu = [], []
                for _ in range(args.repeats):
                    t0, c0 = time.perf_counter(), time.process_time()
                    fit = _fit(prior, recs, **kw)
                    wall.append(time.perf_counter() - t0)
                    cpu.append(time.process_time() - c0)
                theta_ = fit if isinstance(fit, str) else (
                    f"theta {fit.theta_:.9g} rad, std {fit.std_:.3g} rad")
                print(f"{dname}, {ename}, trial {k}: median {statistics.median(wall):.2f} s "
                      f"over {args.repeats} (CPU {statistics.median(cpu):.2f} s); {theta_}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=int, default=200)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--seed", type=int, default=2020)
    p.add_argument("--snr", type=float, default=SNR,
                   help=f"the analogue speeds' SNR in dB (default {SNR:g})")
    p.add_argument("--drives", default="paper,other",
                   help="comma-separated drives of the coverage study (paper, other)")
    p.add_argument("--effects", default=",".join(EFFECTS),
                   help=f"comma-separated scenarios (default: {', '.join(EFFECTS)}; "
                        f"'extended': {', '.join(EXTENDED)})")
    p.add_argument("--trial", type=_trials, default=None, metavar="K, A:B or K,L,M",
                   help="run only trial K (from 0), trials A to B-1, or the trials listed, "
                        "of each scenario, each alone as in the study")
    p.add_argument("--profile-grid", type=int, default=0, metavar="N",
                   help="with --trial: the profile's rise at N held theta each side, up to "
                        f"{GRID_SPAN:g} standard errors")
    p.add_argument("--prior-rel-std", type=float, default=0.0, metavar="S",
                   help="give each fit a prior of the linear parameters with relative std "
                        "S, its values drawn about the truth with that std (default 0: the "
                        "truth as the prior, no prior std)")
    p.add_argument("--free-loop", action="store_true",
                   help="with --trial, on records of a drive with a loop: also refit them "
                        "with the loop's lag next to free from each of its starts")
    p.add_argument("--kernel-records", action="store_true",
                   help="analogue records made by the compiled kernel the estimator fits "
                        "with, not the scipy reference: a diagnostic that tells the two "
                        "simulators' differences from the estimator's statistics")
    p.add_argument("--speed", action="store_true")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--crb", action="store_true",
                   help="print only each scenario's Cramér-Rao bound and error limit")
    p.add_argument("--offsets", action="store_true",
                   help="the spread over --trials encoder offsets of one record pair")
    p.add_argument("--slice", type=_slice, default=None, metavar="A:B",
                   help="run only trials A to B-1 of --trials (with --save)")
    p.add_argument("--save", default=None, metavar="FILE",
                   help="write the trials' results to FILE (JSON), for --merge")
    p.add_argument("--merge", nargs="+", default=None, metavar="FILE",
                   help="print the row of one scenario from its saved slices")
    p.add_argument("--partial", action="store_true",
                   help="with --merge: slices that tile only the first trials of the row")
    p.add_argument("--against", default=None, metavar="FILE",
                   help="with --merge: also list the trials whose interval holds the truth "
                        "in one of the two rows only (FILE: another saved row of the same "
                        "trials), with both estimates")
    args = p.parse_args(argv)
    args.drives = args.drives.split(",")
    args.effects = [e for name in args.effects.split(",")
                    for e in (EXTENDED if name == "extended" else [name])]
    if args.free_loop and args.trial is None:
        p.error("--free-loop refits one trial's records: give --trial")
    if args.against and not args.merge:
        p.error("--against compares a merged row with another: give --merge")
    if args.save and len(args.drives) * len(args.effects) != 1:
        p.error("--save takes one scenario: one --drives and one --effects")
    if not 0.0 <= args.prior_rel_std <= MAX_PRIOR_REL_STD:
        p.error(f"--prior-rel-std must be in [0, {MAX_PRIOR_REL_STD:g}], got "
                f"{args.prior_rel_std:g}")
    if args.slice and args.slice[1] > args.trials:
        p.error(f"--slice ends at trial {args.slice[1] - 1}, beyond --trials {args.trials}")
    (merge if args.merge else speed if args.speed else bounds if args.crb
     else offsets if args.offsets else coverage)(args)
    return 0


def _trials(text: str) -> list[int]:
    """``K`` as ``[K]``, ``A:B`` as trials ``A`` to ``B - 1`` (:func:`_slice`), or
    ``K,L,M`` as those trials."""
    if ":" in text:
        return list(range(*_slice(text)))
    try:
        ks = [int(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected K, A:B or K,L,M (integers), got {text!r}") from None
    if min(ks) < 0:
        raise argparse.ArgumentTypeError(f"expected trials >= 0, got {text!r}")
    return ks


def _slice(text: str) -> tuple[int, int]:
    """``A:B`` as trials ``(A, B)``, ``0 <= A < B``."""
    try:
        first, stop = (int(x) for x in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B (two integers), got {text!r}") from None
    if not 0 <= first < stop:
        raise argparse.ArgumentTypeError(f"expected 0 <= A < B, got {text!r}")
    return first, stop


def bounds(args) -> None:
    """The Cramér-Rao bound of theta per analogue scenario, and the error limit
    max(5 %, 3 CRB) of issue 20's bar."""
    print(f"{'drive':<7} {'has':<15} {'CRB %':>6} {'limit %':>8}")
    for dname, (linear, theta) in DRIVES.items():
        for ename, (fc, tau, counts) in {**EFFECTS, **EXTENDED}.items():
            if dname in args.drives and ename in args.effects and not counts:
                crb = crb_theta(linear, theta, fc, tau, args.snr) / theta
                print(f"{dname:<7} {ename:<15} {100 * crb:6.2f} "
                      f"{100 * max(ERR_FLOOR, CRB_FACTOR * crb):8.2f}")


if __name__ == "__main__":
    sys.exit(main())
