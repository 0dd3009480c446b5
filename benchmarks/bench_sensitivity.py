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

Usage::

    python benchmarks/bench_sensitivity.py [--repeats 5] [--seconds 8] [--digest]
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import time

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=DURATION,
                    help=f"record length in s (default {DURATION:g})")
    ap.add_argument("--digest", action="store_true",
                    help="print the sensitivities' SHA-1 digests instead of timing")
    args = ap.parse_args()

    drive = bk.TwoMassDrive(**P_TRUE, theta=THETA)
    t = bk.signals.time_grid(args.seconds, TS)
    u = bk.signals.step_down(t, A1, t_s=args.seconds / 2)
    values = {n: getattr(drive, n) for n in PARAMS}
    if args.digest:
        print(f"paper A's drive, {t.size} samples")
        digests(t, u)
        return
    # imported here, so that --digest runs at commits before it existed
    from backlashkit._sensitivity import LINEAR_AND_THETA, trajectory_and_information

    perturbed = [drive] + [bk.TwoMassDrive(**{**values, n: values[n] * (1 + FD_STEP)})
                           for n in PARAMS]

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
