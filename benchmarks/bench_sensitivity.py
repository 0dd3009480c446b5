"""Cost of the exact forward sensitivities against what a Jacobian costs today.

Workload: paper A's drive (``backlashkit.papers.ravanbod2002``: ``P_TRUE``, ``THETA``)
under an 8 s record at Ts = 1 ms (8 001 samples): torque ``A1`` = 0.157 N m from rest,
stepped down to 0 at 4 s, paper law.

Timed in this process, each the median of ``--repeats`` runs after one warm-up, all
interleaved (one run of each per round) and BLAS held to one thread (the twin's small
products gain nothing from more), in CPU time of the process (a busy machine's other
jobs then weigh on none of them):

* ``compiled sensitivities``: :func:`backlashkit._sensitivity.sensitivities` (the
  kernel simulates the drive once for its contact changes, then integrates the seven
  sensitivities along them);
* ``compiled, theta alone``: the same for the one parameter ``theta`` (what
  ``cramer_rao_bound`` computes by default: the kernel carries only the columns
  asked for);
* ``compiled information``: :func:`backlashkit._sensitivity.trajectory_and_information`
  of the seven, the sums of the speeds' outer products that the white-noise bound
  weighs, summed as the kernel walks (nothing written out);
* ``numpy twin``: :func:`backlashkit._numpy_sensitivity.sensitivities`, the same
  recurrence in plain NumPy;
* ``1 simulation``: the compiled simulator at the nominal parameters
  (``TwoMassDrive.simulate``), the unit of issue 24's bars;
* ``8 simulations``: it and the seven parameters each perturbed by a relative 1e-6 --
  a forward-difference Jacobian, as the estimators difference simulations today.

``--seconds 80`` times paper A's 80 s records instead (the step-down half-way), where
the output, tens of megabytes, weighs on the compiled run.

``--digest`` times nothing and prints the SHA-1 of the compiled sensitivities' bytes
for several sets of columns, with and without Coulomb friction: run at two commits, it
shows whether a change of the kernel kept its values to the bit.

``--holds`` times instead where a held torque's run costs, on the coarse grid the
joint fit simulates paper A's 40 s holds on (``identify._model.hold_grid``): each
hold's simulation and the walk of its sensitivities to its end (what each window's
Jacobian starts from), whole and from the sample after its last contact change on
(the same run cut there: the tail that the engine settles, without a contact
change), medians of ``--repeats`` after a warm-up, in CPU time.

Usage::

    python benchmarks/bench_sensitivity.py [--repeats 5] [--seconds 8] [--digest] [--holds]
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import time
from functools import partial

import numpy as np
from threadpoolctl import threadpool_limits

import backlashkit as bk
from backlashkit._numpy_sensitivity import PARAMS
from backlashkit._numpy_sensitivity import sensitivities as numpy_sensitivities
from backlashkit._sensitivity import sensitivities
from backlashkit.papers.ravanbod2002 import A1, P_TRUE, THETA

#: Record length, s (issue 24's benchmark record), stepped down half-way.
DURATION = 8.0
TS = 1e-3
#: Relative step of the forward differences timed (its value does not change the cost).
FD_STEP = 1e-6


def median_times(fns, repeats: int) -> tuple[list[float], list[object]]:
    """Median CPU times of ``repeats`` rounds of one call of each of ``fns``, after one
    warm-up round, and their last results."""
    outs = [fn() for fn in fns]
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(repeats):
        for i, fn in enumerate(fns):
            t0 = time.process_time()
            outs[i] = fn()
            times[i].append(time.process_time() - t0)
    return [statistics.median(ts) for ts in times], outs


#: Column sets of ``--digest``: the seven, one, a few out of order, and with Coulomb
#: friction all nine and two.
DIGESTS = ((None, None), (None, ("theta",)), (None, ("theta", "k_sh", "J_L")),
           ((0.01, 0.02), None), ((0.01, 0.02), ("fc_L", "theta")))


def digests(t: np.ndarray, u: np.ndarray) -> None:
    """Print the SHA-1 of the compiled sensitivities of each of :data:`DIGESTS`."""
    for coulomb, params in DIGESTS:
        fc = {} if coulomb is None else {"fc_M": coulomb[0], "fc_L": coulomb[1]}
        drive = bk.TwoMassDrive(**P_TRUE, theta=THETA, **fc)
        sens = sensitivities(drive, t, u, params=params, states=True)
        print(f"  Coulomb {coulomb}, params {params}: {sens.shape}, sha1 "
              f"{hashlib.sha1(sens.tobytes()).hexdigest()}")


def hold_run(p: np.ndarray, span, k: int = 0, x0: np.ndarray | None = None):
    """The fit's simulation of ``span``'s hold (packed parameter rows ``p``) on its
    coarse grid, from its sample ``k`` on (from rest, or from ``x0``)."""
    from backlashkit.identify._model import hold_grid, initial_states
    from backlashkit.simulate import simulate_packed_runs

    n, step = hold_grid(span)
    x0 = initial_states(p, None, span.level) if x0 is None else x0
    return simulate_packed_runs(2, p, k * step, step, np.full((1, n + 1 - k), span.level),
                                x0, law="paper", workers=1)


def hold_costs(drive, span, repeats: int) -> str:
    """One line of ``--holds``: ``span``'s hold, whole and from the sample after its
    last contact change on."""
    from backlashkit._sensitivity import sensitivities_along, sensitivity_at_end_along
    from backlashkit.identify._model import packed_row
    from backlashkit.simulate import PackedRun

    p = packed_row(drive)[np.newaxis, :]
    runs = hold_run(p, span)
    run = runs.run(0)
    k = int(np.ceil(run.events[-1, 0] / run.ts - 1e-9)) + 1
    tail = PackedRun(k * run.ts, run.ts, run.torque[k:], run.states[k:], runs.modes[0, k],
                     np.empty((0, 4)))
    s_k = sensitivities_along(drive, run)[k]
    with threadpool_limits(1):
        (sim, sim_tail, walk, walk_tail), _ = median_times(
            [partial(hold_run, p, span), partial(hold_run, p, span, k, run.states[k:k + 1]),
             partial(sensitivity_at_end_along, drive, run),
             partial(sensitivity_at_end_along, drive, tail, initial_sensitivity=s_k)],
            repeats)
    return (f"  {span.record.name}: {len(run.torque)} samples of {1e3 * run.ts:g} ms, "
            f"{len(run.events)} changes of mode up to {run.events[-1, 0]:.3g} s (sample "
            f"{k}); simulation {1e6 * sim:.0f} us, its tail alone {1e6 * sim_tail:.0f} us; "
            f"sensitivities' walk to the end {1e6 * walk:.0f} us, its tail alone "
            f"{1e6 * walk_tail:.0f} us")


def holds(repeats: int) -> None:
    """Print the cost of paper A's two holds, whole and from their last contact change
    on (``--holds``), at the true parameters."""
    from backlashkit.identify._model import screen_spans, spans
    from backlashkit.papers.ravanbod2002 import protocol_records

    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    records = list(protocol_records(0.3, np.random.SeedSequence(2024))[:2])
    noise = [(1.0, 1.0)] * len(records)  # the spans' cut does not depend on it
    print(f"paper A's holds on the fit's coarse grid, median of {repeats}, CPU time")
    for span in screen_spans(spans(records, "auto", 1.0, noise)):
        if span.hold is not None:
            print(hold_costs(drive, span, repeats))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=DURATION,
                    help=f"record length in s (default {DURATION:g})")
    ap.add_argument("--digest", action="store_true",
                    help="print the sensitivities' SHA-1 digests instead of timing")
    ap.add_argument("--holds", action="store_true",
                    help="time paper A's holds, whole and from their last change on")
    args = ap.parse_args()
    if args.holds:
        holds(args.repeats)
        return

    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(args.seconds, TS)
    u = bk.signals.step_down(t, A1, t_s=args.seconds / 2)
    # the drive's parameters (the loop's tau_i is not one of them)
    values = {n: getattr(drive, n) for n in PARAMS if hasattr(drive, n)}
    if args.digest:
        print(f"paper A's drive, {t.size} samples")
        digests(t, u)
        return
    # imported here, so that --digest runs at commits before it existed
    from backlashkit._sensitivity import LINEAR_AND_THETA, trajectory_and_information

    perturbed = [drive] + [bk.TwoMassDrive(**{**values, n: values[n] * (1 + FD_STEP)})
                           for n in values]

    with threadpool_limits(1):
        (t_fast, t_one, t_info, t_np, t_sim, t_fd), (fast, _, _, ref, _, _) = median_times(
            [lambda: sensitivities(drive, t, u),
             lambda: sensitivities(drive, t, u, params=("theta",)),
             lambda: trajectory_and_information(drive, t, u, params=LINEAR_AND_THETA),
             lambda: numpy_sensitivities(drive, t, u), lambda: drive.simulate(t, u),
             lambda: [d.simulate(t, u) for d in perturbed]], args.repeats)

    n_changes = len(drive.simulate(t, u).contact_events)
    diff = np.max(np.max(np.abs(fast - ref), axis=(0, 1)) / np.max(np.abs(ref), axis=(0, 1)))
    print(f"paper A's drive, {t.size} samples, {n_changes} contact changes, "
          f"median of {args.repeats}")
    print(f"  compiled sensitivities {1e3 * t_fast:9.2f} ms   ({t_fast / t_sim:.2f} simulations)")
    print(f"  compiled, theta alone  {1e3 * t_one:9.2f} ms   ({t_one / t_sim:.2f} simulations)")
    print(f"  compiled information   {1e3 * t_info:9.2f} ms   ({t_info / t_sim:.2f} simulations)")
    print(f"  numpy twin             {1e3 * t_np:9.2f} ms   ({t_np / t_fast:.1f}x compiled)")
    print(f"  1 simulation           {1e3 * t_sim:9.2f} ms")
    print(f"  8 simulations          {1e3 * t_fd:9.2f} ms   ({t_fd / t_fast:.2f}x compiled)")
    print(f"  compiled vs numpy twin: largest relative difference {diff:.1e}")


if __name__ == "__main__":
    main()
