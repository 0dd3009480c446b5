"""Benchmark: identification speed (issue 3's targets), medians of several runs.

1. ``backlashkit identify e1.csv e2.csv --drive PRIOR.toml --json`` (joint, the default
   method) on paper A's two 80 s records, as a fresh process pinned to one core
   (``taskset -c 0`` where available, else ``RAYON_NUM_THREADS=1``): the whole
   command, interpreter start and file reading included. Target: < 2 s.
2. The same fit in-process (``JointIdentifier(workers=1).fit``), beside the faithful
   two-step method and the regression baseline, for the split of the time; and the
   share of its profile-likelihood interval (the fit's time minus that of the same fit
   with ``interval=FisherInterval()``), the same fit with the stiffness restarts of
   earlier versions, ``stiffness_restarts=(0.15,)`` (the cost of the wider default),
   without the restarts of the friction split, ``friction_restarts=()``, with no
   restart at all (every field of ``Restarts`` off), and with
   ``noise_model=ARNoise(2)``, left out of the default for its cost.
3. With ``--reproduce``: ``backlashkit reproduce ravanbod2002 --runs 10 --jobs 2``
   wall time (target < 60 s on 2 cores), once.
4. Accuracy of eq. 9 (both onsets) on noise-free records of both steps: ``t_c`` and
   ``t_b`` against the simulator's contact events, in samples (issue 3 asks for 2), and
   on 40 noisy step-1 records (60 dB) with the eq. 6 spread; and of the joint
   estimator's model instants (``JointIdentifier.commutations_``, what ``identify``
   reports by default) fitted to the same noise-free records with the 30 % prior.

5. The Gauss-Newton product ``J^T J`` of the joint fit's final stage (320 010 x 7, the
   shape on these records) with the BLAS library's default threads and with one
   (why ``JointIdentifier.fit`` and the worker pools run one, ``backlashkit.parallel``).

``--profile`` prints instead the functions with the most time of their own in one
default fit under ``cProfile`` (NumPy's ufuncs count in their callers' own time; the
profiler's overhead inflates the total).

``--stiffness-grid N`` times ``ThetaGrid(stiffness_points=N)`` in 2. instead.

``--count`` prints instead what one default fit, one of paper A's model alone (no
term tested), one with no restart at all (``BARE``), and ``cramer_rao_bound`` (of
``theta`` alone, its default, and of all seven parameters) of the same records cost
in simulations of those records: the
samples the compiled kernel advanced (every parameter row of every call, counted by
wrapping ``simulate_packed_runs``), divided by the records' samples (issue 24's
measure). The fit and the bound take the compiled sensitivities where their model is
theirs: those runs are counted apart, the fit's weighed by their time at its
simulations' rate on whole spans, and again at a steadier unit, the median of
``UNIT_REPEATS`` kernel simulations of the records timed apart; the bound's time is
also given in times of one simulation of the record (medians of 7, interleaved, in CPU
time of the process, all its threads: other jobs' time slices do not count). It
times the normal equations' products of one more fit's Levenberg-Marquardt steps
apart (``normal_equations``), and its last line tallies the Levenberg-Marquardt step
doublings of one more fit, each evaluated whether the parabola along the step tries it
or not (``doublings``).

The prior is paper A's drive with a 30 % error drawn as in the protocol.

Run: ``python benchmarks/bench_identify.py [--repeats 5] [--reproduce]
[--stiffness-grid N] [--count] [--profile]``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

import backlashkit.identify._lm as lm_mod
from backlashkit import TwoMassDrive, signals
from backlashkit.errors import CorrelatedResidualsWarning
from backlashkit.identify import (
    Record,
    RegressionIdentifier,
    TwoStepIdentifier,
    commutation_instants,
)
from backlashkit.identify._search import STAGE_NAMES
from backlashkit.identify.crb import cramer_rao_bound
from backlashkit.identify.intervals import FisherInterval
from backlashkit.identify.joint import JointIdentifier
from backlashkit.identify.noise import ARNoise
from backlashkit.identify.search import JointSearch, Restarts, ThetaGrid
from backlashkit.papers.ravanbod2002 import A1, A2, P_TRUE, T_S, THETA, TS, protocol_records


def _median(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


#: Kernel calls over fewer of the records' samples than this are the search's windows
#: (2-3 s at 1 ms on paper A's records: the first window and the continuation), the
#: others its whole spans (60-80 s): the two are timed apart (``--count``), and apart
#: from the holds the windows start after.
WINDOW_SAMPLES = 10_000
#: The compiled sensitivity runs: simulating the drive first, or along a run the fit
#: has just simulated, written out, as the Jacobian's rows or only at the run's end
#: (the first four arguments of each: parameters, t0, ts, torque).
SENSITIVITY_KERNELS = ("drive_sensitivities", "drive_sensitivities_along",
                       "drive_jacobian_rows_along", "drive_sensitivity_at_end_along")


def simulations(fn, samples: int, done=None, kernel=None, sens=None, sens_parts=None
                ) -> tuple[float, int]:
    """What ``fn()`` costs in simulations of ``samples`` samples, and the kernel's
    calls; ``done`` (a list ``[samples, calls]``) counts as it goes; ``kernel`` (a dict
    ``{"holds": [s, rows x samples], "windows": [...], "whole": [...]}``) adds up the
    kernel's wall time and work in the calls through a held torque on a coarse grid
    (another sample time than the records': ``identify._model.HOLD_STEP``), in the
    other calls shorter than :data:`WINDOW_SAMPLES` and in the rest. ``sens`` (a list
    ``[runs, samples, s]``) adds up the compiled sensitivity runs apart: they are not
    simulations, and :func:`count` weighs them by their time; ``sens_parts`` (a dict
    as ``kernel``, of ``[runs, samples, s]``) splits them the same way."""
    import backlashkit._core as core

    import backlashkit.identify._model as model
    import backlashkit.simulate as sim

    done = [0, 0] if done is None else done
    sens = [0, 0, 0.0] if sens is None else sens
    real = sim.simulate_packed_runs
    real_sens = {name: getattr(core, name) for name in SENSITIVITY_KERNELS}

    def counted_sens(kernel_fn):
        def call(p, t0, ts, u, *rest):
            start = time.perf_counter()
            out = kernel_fn(p, t0, ts, u, *rest)
            took = time.perf_counter() - start
            parts = [sens] if sens_parts is None else [sens,
                                                       sens_parts[part_of(ts, np.size(u))]]
            for part in parts:
                part[0] += 1
                part[1] += np.size(u)
                part[2] += took
            return out
        return call

    def counted(n, p, t0, ts, u, x0, **kw):
        work = np.shape(p)[0] * np.shape(u)[1]
        done[0] += work
        done[1] += 1
        start = time.perf_counter()
        out = real(n, p, t0, ts, u, x0, **kw)
        if kernel is not None:
            part = kernel[part_of(ts, np.shape(u)[1])]
            part[0] += time.perf_counter() - start
            part[1] += work
        return out

    model.simulate_packed_runs = sim.simulate_packed_runs = counted
    for name, kernel_fn in real_sens.items():
        setattr(core, name, counted_sens(kernel_fn))
    try:
        fn()
    finally:
        model.simulate_packed_runs = sim.simulate_packed_runs = real
        for name, kernel_fn in real_sens.items():
            setattr(core, name, kernel_fn)
    return done[0] / samples, done[1]


#: Timed simulations of the records for the steadier unit of ``--count``: the whole
#: spans' rate inside a fit comes from some two dozen calls among the fit's other work,
#: and moved by up to a half between runs of one commit.
UNIT_REPEATS = 7


def unit_simulation(recs, prior) -> float:
    """Median wall time in s of one simulation of all the records, by the fit's own
    kind of kernel call (``simulate_packed_runs``, one parameter row: the prior's
    drive with paper A's ``theta``, from rest), of :data:`UNIT_REPEATS`."""
    from backlashkit.identify._model import packed_row
    from backlashkit.simulate import simulate_packed_runs

    row = packed_row(prior.with_theta(THETA))[np.newaxis, :]
    times = []
    for _ in range(UNIT_REPEATS):
        start = time.perf_counter()
        for rec in recs:
            simulate_packed_runs(2, row, float(rec.t[0]), TS, rec.torque[np.newaxis, :],
                                 np.zeros((1, 3)), law="paper", workers=1)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def part_of(ts: float, n: int) -> str:
    """Which part of a fit a kernel call of ``n`` samples at ``ts`` runs: a hold on the
    coarse grid (another sample time than the records'), a window or a whole span."""
    if not np.isclose(ts, TS, rtol=1e-6, atol=0.0):
        return "holds"
    return "windows" if n < WINDOW_SAMPLES else "whole"


def normal_equations(recs, prior) -> None:
    """What the products ``J^T r`` and ``J^T J`` of Levenberg-Marquardt's steps cost in
    one more default fit: each step's, timed again apart from it (the fit's own are
    part of ``_step``), on the whole records' Jacobians (rows of both records) and on
    the shorter ones."""
    parts = {"whole": [0, 0.0], "shorter": [0, 0.0]}
    real = lm_mod._step

    def step(state, *args):
        start = time.perf_counter()
        jz = state.jac
        _ = (jz.T @ state.r, jz.T @ jz)
        part = "whole" if jz.shape[0] >= sum(r.t.size for r in recs) else "shorter"
        parts[part][0] += 1
        parts[part][1] += time.perf_counter() - start
        return real(state, *args)

    lm_mod._step = step
    try:
        JointIdentifier(prior, workers=1).fit(recs)
    finally:
        lm_mod._step = real
    print("  the normal equations' products (J^T r, J^T J) of Levenberg-Marquardt's "
          "steps, timed again apart: " + ", ".join(
              f"{n} steps on the {part} spans {sec:.3f} s" for part, (n, sec) in parts.items()))


def count(recs, prior) -> None:
    """Issue 24's measure: one fit and one bound in simulations of the records, and
    where the fit's wall time goes."""
    samples = sum(r.t.size for r in recs)
    done, kernel = [0, 0], {"holds": [0.0, 0], "windows": [0.0, 0], "whole": [0.0, 0]}
    sens = [0, 0, 0.0]
    sens_parts = {part: [0, 0, 0.0] for part in kernel}
    marks = [(0, 0, 0.0, 0, 0.0, time.perf_counter())]
    fit = JointIdentifier(prior, workers=1, progress=lambda k, total: marks.append(
        (k, total, done[0] / samples, sens[0], sens[2], time.perf_counter()))).fit
    start = time.perf_counter()
    n_fit, calls = simulations(lambda: fit(recs), samples, done, kernel, sens, sens_parts)
    wall = time.perf_counter() - start
    # a sensitivity run weighed by its time, at the simulations' rate on whole spans
    whole_sec, whole_work = kernel["whole"]
    per_sim = whole_sec / max(whole_work, 1) * samples
    for (_, _, n0, s0, c0, t0), (k, total, n, s, c, t) in zip(marks, marks[1:],
                                                              strict=False):
        if k > 0:  # stage k ended (a misfit restart repeats the stages)
            name = STAGE_NAMES[(k - 1) % len(STAGE_NAMES)]
            in_all = n - n0 + ((c - c0) / per_sim if whole_sec else 0.0)
            print(f"  stage {k}/{total}, {name}: {n - n0:.0f} simulations, "
                  f"{s - s0} sensitivity runs, {in_all:.0f} in all, {t - t0:.2f} s")
    what = {"holds": "through the held torque on a coarse grid",
            "windows": f"of the records' samples, calls of < {WINDOW_SAMPLES}",
            "whole": f"of the records' samples, calls of >= {WINDOW_SAMPLES}"}
    for part, (sec, work) in kernel.items():
        print(f"  the kernel in the {part} ({what[part]}): {sec:.2f} s, "
              f"{1e9 * sec / max(work, 1):.0f} ns per sample and parameter row")
    print(f"  the sensitivity runs: {sens[2]:.2f} s")
    for part, (runs, n, sec) in sens_parts.items():
        print(f"    in the {part}: {runs} runs, {sec:.2f} s, {1e9 * sec / max(n, 1):.0f} ns "
              "per sample")
    print(f"  one fit's wall time: {wall:.2f} s, the kernel "
          f"{sum(sec for sec, _ in kernel.values()) + sens[2]:.2f} s of it")
    normal_equations(recs, prior)
    truth = TwoMassDrive(**P_TRUE, theta=THETA)
    n_sens = sens[2] / per_sim if whole_sec else 0.0
    print(f"paper A's two 80 s records, prior error 30 %: one JointIdentifier.fit (the "
          f"default) costs {n_fit:.0f} simulations of the records in {calls} kernel calls, "
          f"and {sens[0]} sensitivity runs over {sens[1] / samples:.0f} times the records' "
          f"samples in the time of {n_sens:.0f} simulations (at the whole spans' rate): "
          f"{n_fit + n_sens:.0f} in all (issue 24's bar: 250)")
    unit = unit_simulation(recs, prior)
    print(f"  the same at a steadier unit, the median of {UNIT_REPEATS} kernel simulations of "
          f"the records timed apart ({1e3 * unit:.2f} ms): "
          f"{n_fit + sens[2] / unit:.0f} in all")
    plain = JointIdentifier(prior, workers=1, friction="viscous", actuator=None).fit
    sens_plain = [0, 0, 0.0]
    n_plain, calls = simulations(lambda: plain(recs), samples, sens=sens_plain)
    print(f"  with paper A's model alone (friction='viscous', actuator=None, no term "
          f"tested): {n_plain:.0f} simulations in {calls} kernel calls, and "
          f"{sens_plain[0]} sensitivity runs")
    bare = JointIdentifier(prior, workers=1, search=JointSearch(restarts=BARE)).fit
    sens_bare = [0, 0, 0.0]
    start = time.perf_counter()
    n_bare, calls = simulations(lambda: bare(recs), samples, sens=sens_bare)
    wall_bare = time.perf_counter() - start
    print(f"  with no restarts at all (the default model, every field of Restarts off): "
          f"{n_bare:.0f} simulations in {calls} kernel calls, and {sens_bare[0]} sensitivity "
          f"runs in {sens_bare[2]:.2f} s: {n_bare + sens_bare[2] / unit:.0f} in all at the "
          f"steadier unit; its wall time {wall_bare:.2f} s")
    for estimate in (("theta",), "all"):
        n_crb, n_sens, ratio = zip(*(crb_cost(truth, r, estimate) for r in recs),
                                   strict=True)
        print(f"cramer_rao_bound(estimate={estimate!r}) of each record costs "
              f"{sum(n_crb) / 2:.0f} simulations of it and {sum(n_sens) / 2:.0f} "
              f"sensitivity runs, in the time of "
              f"{statistics.median([r[0] for r in ratio]):.1f} simulations (bar: 3; by "
              f"central differences {statistics.median([r[1] for r in ratio]):.1f})")
    sim_s = statistics.median(r[2] for r in ratio)
    print(f"  one simulation (drive.simulate) of a record: {1e3 * sim_s:.2f} ms, "
          f"{1e9 * sim_s / recs[0].t.size:.0f} ns a sample")
    # issue 24's own measure: the fit's wall time over one simulation of the records
    # ("about 1.6 ms" for both when it was filed: the kernel's run, the steadier unit)
    print(f"  by wall time, one fit ({wall:.2f} s) costs {wall / unit:.0f} simulations of the "
          f"records at the steadier unit (issue 24's bar: 250), "
          f"{wall / (len(recs) * sim_s):.0f} at drive.simulate's")
    doublings(recs, prior)


def doublings(recs, prior) -> None:
    """One more default fit, each accepted step's first doubling within the longest
    step evaluated aside (not counted above; the fit's path is its own): how many the
    parabola along the step (``identify._lm._doubling_pays``) tries and turns away,
    and how many of each would lower the cost. Every one of them was tried before
    the parabola decided."""

    tally = {(pays, lower): 0 for pays in (True, False) for lower in (True, False)}
    real = lm_mod._extrapolate

    def extrapolate(state, fun, g, step, z_new, r_new, c_new, max_step, bounds):
        if 2.0 * float(np.max(np.abs(step))) <= max_step:
            z_try = state.z + 2.0 * step
            r_try = fun(z_try if bounds is None else np.clip(z_try, *bounds))
            lower = bool(float(r_try @ r_try) < c_new)
            tally[lm_mod._doubling_pays(state.cost, float(g @ step), c_new), lower] += 1
        return real(state, fun, g, step, z_new, r_new, c_new, max_step, bounds)

    lm_mod._extrapolate = extrapolate
    try:
        JointIdentifier(prior, workers=1).fit(recs)
    finally:
        lm_mod._extrapolate = real
    print(f"Levenberg-Marquardt's first doublings of the accepted steps: the parabola "
          f"tries {tally[True, True] + tally[True, False]} ({tally[True, True]} lower the "
          f"cost) and turns away {tally[False, True] + tally[False, False]} "
          f"({tally[False, True]} would lower it)")


#: Every restart off, the misfit's second search too: what the search costs without the
#: restarts added for drives with friction and loops at 30 dB (issue 20).
BARE = Restarts(stiffness=(), long=(), ringing=(), friction=(), misfit=False, prior=False,
                no_backlash=False)

#: Functions ``--profile`` lists.
PROFILE_TOP = 12


def profile(recs, prior) -> None:
    """One default fit under ``cProfile``, after one without it (the same work, caches
    warm): the :data:`PROFILE_TOP` functions with the most time of their own."""
    import cProfile
    import pstats

    fit = JointIdentifier(prior, workers=1).fit
    fit(recs)
    prof = cProfile.Profile()
    prof.enable()
    fit(recs)
    prof.disable()
    stats = pstats.Stats(prof)
    rows = sorted(stats.stats.items(), key=lambda kv: kv[1][2], reverse=True)
    print(f"one JointIdentifier.fit under cProfile, {stats.total_tt:.2f} s; the "
          f"{PROFILE_TOP} functions with the most time of their own:")
    for (file, line, name), (_, calls, own, cumulative, _) in rows[:PROFILE_TOP]:
        where = name if file == "~" else f"{Path(file).name}:{line}({name})"
        print(f"  {own:6.3f} s own, {cumulative:6.3f} s with callees, {calls:5d} calls: "
              f"{where}")


#: Pause before each timed call of the bound, in s (see ``crb_cost``).
SETTLE_S = 0.02


def crb_cost(drive, rec, estimate, repeats: int = 7
             ) -> tuple[float, int, tuple[float, float, float]]:
    """``cramer_rao_bound(estimate=estimate)`` of one record: simulations, compiled
    sensitivity runs, and its median time over one simulation's, with the compiled
    sensitivities and by central differences, and one simulation's median time in s."""
    import backlashkit._core as core

    from backlashkit.identify import crb

    kernels = ("drive_sensitivities", "drive_information")
    real, runs = {k: getattr(core, k) for k in kernels}, [0]

    def counted(name):
        def call(*args):
            runs[0] += 1
            return real[name](*args)
        return call

    def bound():
        return cramer_rao_bound(drive, rec.t, rec.torque, snr_db=40.0, estimate=estimate)

    for k in kernels:
        setattr(core, k, counted(k))
    try:
        n_sim = simulations(bound, rec.t.size)[0]
    finally:
        for k in kernels:
            setattr(core, k, real[k])
    exact = crb._exact_information
    times: dict[str, list[float]] = {"exact": [], "differences": [], "simulation": []}
    # CPU time of the process (all its threads; BLAS held to one): a few milliseconds
    # of wall time on a machine busy with other jobs measure their time slices more
    # than the bound. Each call waits SETTLE_S first, as the kernel's worker threads
    # spin for a while after the differences' parallel batch, in the process's time.
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in range(repeats):  # interleaved
            for name, fn in (("exact", bound), ("differences", bound),
                             ("simulation", lambda: drive.simulate(rec.t, rec.torque))):
                crb._exact_information = (exact if name == "exact"
                                          else lambda *a: (None, None))
                try:
                    time.sleep(SETTLE_S)
                    t0 = time.process_time()
                    fn()
                    times[name].append(time.process_time() - t0)
                finally:
                    crb._exact_information = exact
    med = {k: statistics.median(x) for k, x in times.items()}
    return n_sim, runs[0], (med["exact"] / med["simulation"],
                            med["differences"] / med["simulation"], med["simulation"])


def main() -> None:
    """Print the timings."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--reproduce", action="store_true")
    ap.add_argument("--stiffness-grid", type=int, default=1)
    ap.add_argument("--count", action="store_true",
                    help="only the cost of one fit and one bound in simulations")
    ap.add_argument("--profile", action="store_true",
                    help="only where one fit's own time goes, by cProfile")
    args = ap.parse_args()
    rec1, rec2, prior = protocol_records(0.3, np.random.SeedSequence(2024))
    if args.count:
        count([rec1, rec2], prior)
        return
    if args.profile:
        profile([rec1, rec2], prior)
        return
    exe = [sys.executable, "-m", "backlashkit.cli"]
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        for rec, name in ((rec1, "e1.csv"), (rec2, "e2.csv")):
            cols = np.column_stack([rec.t, rec.torque, rec.w_motor, rec.w_load])
            np.savetxt(d / name, cols, delimiter=",", header="t,torque,w_motor,w_load",
                       comments="", fmt="%.17g")
        (d / "prior.toml").write_text("[drive]\n" + "".join(
            f"{k} = {getattr(prior, k)!r}\n" for k in ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh")))
        cmd = [*exe, "identify", str(d / "e1.csv"), str(d / "e2.csv"), "--drive",
               str(d / "prior.toml"), "--json"]
        env = dict(os.environ)
        if shutil.which("taskset"):
            cmd, how = ["taskset", "-c", "0", *cmd], "taskset -c 0"
        else:
            env["RAYON_NUM_THREADS"], how = "1", "RAYON_NUM_THREADS=1"

        def run_cli() -> None:
            subprocess.run(cmd, check=True, capture_output=True, env=env)

        t_cli = _median(run_cli, args.repeats)
    recs = [rec1, rec2]
    grid = ThetaGrid(stiffness_points=args.stiffness_grid)

    def fit_with(**kwargs) -> None:
        search = JointSearch(grid=grid, **kwargs.pop("search", {}))
        JointIdentifier(prior, workers=1, search=search, **kwargs).fit(recs)

    t_joint = _median(fit_with, args.repeats)
    t_fisher = _median(lambda: fit_with(interval=FisherInterval()), args.repeats)
    # the earlier restarts (README, "Away from paper A's drive"), and an option left out
    # of the default for its cost ("Coloured noise")
    t_narrow = _median(lambda: fit_with(search={"restarts": Restarts(stiffness=(0.15,))}),
                       args.repeats)
    t_nofric = _median(lambda: fit_with(search={"restarts": Restarts(friction=())}),
                       args.repeats)
    t_noprior = _median(lambda: fit_with(search={"restarts": Restarts(prior=False)}),
                        args.repeats)
    # every restart off, the misfit's second search too: what the search costs without
    # the restarts added for drives with friction and loops at 30 dB (issue 20)
    t_bare = _median(lambda: fit_with(search={"restarts": BARE}), args.repeats)
    t_ar = _median(lambda: fit_with(noise_model=ARNoise(2)), args.repeats)
    t_two = _median(lambda: TwoStepIdentifier(prior, workers=1).fit(rec1, final_records=rec2),
                    args.repeats)
    t_reg = _median(lambda: RegressionIdentifier(prior, workers=1).fit(rec2), args.repeats)
    print(f"paper A's two 80 s records (Ts = 1 ms), prior error 30 %; medians of {args.repeats}")
    print(f"{'backlashkit identify (joint), whole command, 1 core':<55} {t_cli:7.2f} s "
          f"(target < 2 s; {how})")
    print(f"{'  JointIdentifier.fit, in process, workers=1':<55} {t_joint:7.2f} s"
          f"{f' (stiffness_points={args.stiffness_grid})' if args.stiffness_grid > 1 else ''}")
    print(f"{'    of which the profile-likelihood interval':<55} {t_joint - t_fisher:7.2f} s "
          "(the same fit with interval=FisherInterval())")
    print(f"{'    with stiffness_restarts=(0.15,) (before 0.4, 0.8)':<55} {t_narrow:7.2f} s")
    print(f"{'    with friction_restarts=() (before them)':<55} {t_nofric:7.2f} s")
    print(f"{'    with Restarts(prior=False) (none from the prior)':<55} {t_noprior:7.2f} s")
    print(f"{'    with no restarts at all (Restarts(...) all off)':<55} {t_bare:7.2f} s")
    print(f"{'    with noise_model=ARNoise(2)':<55} {t_ar:7.2f} s")
    print(f"{'  TwoStepIdentifier.fit (paper A), workers=1':<55} {t_two:7.2f} s")
    print(f"{'  RegressionIdentifier.fit (Table 2 baseline), workers=1':<55} {t_reg:7.2f} s")
    jac = np.random.default_rng(0).standard_normal((7, 320_010)).T  # as the fit lays it out
    t_gram = _median(lambda: [jac.T @ jac for _ in range(20)], args.repeats) / 20
    with threadpool_limits(limits=1, user_api="blas"):
        t_gram1 = _median(lambda: [jac.T @ jac for _ in range(20)], args.repeats) / 20
    print(f"{'  J^T J (320010 x 7), BLAS default threads / one thread':<55} "
          f"{1e3 * t_gram:5.2f} / {1e3 * t_gram1:.2f} ms")
    truth = TwoMassDrive(**P_TRUE, theta=THETA)
    t = signals.time_grid(2 * T_S, TS)
    clean = []
    for a in (A1, A2):
        r = truth.simulate(t, signals.step_down(t, a, t_s=T_S))
        lost, made = [e.time for e in r.events if e.time > T_S][:2]
        for onset in ("constant", "unloading"):
            com = commutation_instants(Record(r.t, r.torque, r.w_motor, r.w_load),
                                       P_TRUE["f_L"] / P_TRUE["J_L"], onset=onset)
            print(f"eq. 9 (onset={onset}) on noise-free data, a = {a:.3f} N m: "
                  f"t_c {(com.t_c - lost) / TS:+.2f}, t_b {(com.t_b - made) / TS:+.2f} "
                  "samples from the true contact changes")
        clean.append((Record(r.t, r.torque, r.w_motor, r.w_load), lost, made))
    with warnings.catch_warnings():  # noise-free: the residual is model error, not white
        warnings.simplefilter("ignore", CorrelatedResidualsWarning)
        joint = JointIdentifier(prior, workers=1).fit([c[0] for c in clean])
    for (rec, lost, made), (_, t_c, t_b) in zip(clean, joint.commutations_, strict=True):
        print(f"joint model instants on the same data, a = {float(rec.torque[0]):.3f} N m: "
              f"t_c {(t_c - lost) / TS:+.4f}, t_b {(t_b - made) / TS:+.4f} samples")
    # the same with noise: step-1 records of the protocol at 60 dB (30 % prior error)
    lost1 = clean[0][1]
    for onset in ("constant", "unloading"):
        errs, inis = [], []
        for i in range(40):
            rec1, rec2, pri = protocol_records(0.3, np.random.SeedSequence(100 + i),
                                               snr1=(60.0, 60.0))
            com = commutation_instants(rec1, P_TRUE["f_L"] / P_TRUE["J_L"], onset=onset)
            errs.append(abs(com.t_c - lost1) / TS)
            inis.append(TwoStepIdentifier(pri, workers=1, onset=onset)
                        .fit(rec1, final_records=rec2).theta_ini_)
        print(f"eq. 9 (onset={onset}) on 40 step-1 records at 60 dB: median |t_c error| "
              f"{statistics.median(errs):.2f} samples; eq. 6 std {np.std(inis):.2e} rad")
    if args.reproduce:
        t0 = time.perf_counter()
        subprocess.run([*exe, "reproduce", "ravanbod2002", "--runs", "10", "--jobs", "2"],
                       check=False, capture_output=True)
        print(f"{'backlashkit reproduce ravanbod2002 --runs 10 --jobs 2':<55} "
              f"{time.perf_counter() - t0:7.1f} s (target < 60 s on 2 cores; "
              f"{os.cpu_count()} cores here)")


if __name__ == "__main__":
    main()
