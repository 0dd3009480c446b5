"""Benchmark: delay_margin of a 10-state, 2-delay system (bar: median under 50 ms on one
core), beside the spectral scan (rightmost root by Chebyshev collocation on a grid of
delays, then bisection) that finds the same h_max without Chen's method, in the same run.

Run: ``python benchmarks/bench_delay.py [--repeats 7]``.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time

import numpy as np
from threadpoolctl import threadpool_limits

from backlashkit.delay import DelaySystem, delay_margin, spectral_margin

#: Seed of the benchmark system; delayed coupling strong enough for a finite margin.
SEED = 3
N_STATES, N_DELAYS = 10, 2
#: Spectral scan: delays on (0, 1.5 h_max], then bisection to this relative tolerance.
N_SCAN = 60
SCAN_XTOL = 1e-9


def bench_system() -> tuple[np.ndarray, list[np.ndarray]]:
    """A random 10-state, 2-delay system, stable at h = 0, with a finite margin."""
    rng = np.random.default_rng(SEED)
    while True:
        a = [rng.normal(size=(N_STATES, N_STATES)) * 0.5 for _ in range(N_DELAYS)]
        a0 = rng.normal(size=(N_STATES, N_STATES)) * 0.5
        a0 -= (max(np.linalg.eigvals(a0 + sum(a)).real) + 0.2) * np.eye(N_STATES)
        if math.isfinite(delay_margin(a0, a, verify=False).h_max):
            return a0, a


def _median(fn, repeats):
    """Median wall time and median CPU time of this process (the machine may be shared:
    CPU time leaves out the time the process waited for a core)."""
    wall, cpu, out = [], [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return (statistics.median(wall), statistics.median(cpu)), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    a0, a = bench_system()
    with threadpool_limits(limits=1, user_api="blas"):
        rows = []
        for label, kw in (("sweep, no check", {"verify": False}),
                          ("sweep + spectral check", {"verify": True}),
                          ("kronecker, no check", {"method": "kronecker", "verify": False})):
            t, r = _median(lambda kw=kw: delay_margin(a0, a, **kw), args.repeats)
            rows.append((label, t, r.h_max))
        h_ref = rows[0][2]
        system = DelaySystem(a0, a)
        ts, hs = _median(lambda: spectral_margin(system, 1.5 * h_ref, n_scan=N_SCAN,
                                                 xtol=SCAN_XTOL), 1)
    print(f"system: n = {N_STATES}, q = {N_DELAYS} (seed {SEED}); one BLAS thread; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"{'method':26s} {'wall [ms]':>10s} {'CPU [ms]':>9s} {'h_max [s]':>19s} "
          f"{'vs scan (CPU)':>14s}")
    for label, (tw, tc), h in rows:
        print(f"{label:26s} {1e3 * tw:10.1f} {1e3 * tc:9.1f} {h:19.15f} {ts[1] / tc:13.0f}x")
    print(f"{'spectral scan + bisection':26s} {1e3 * ts[0]:10.1f} {1e3 * ts[1]:9.1f} "
          f"{hs:19.15f} {1:13.0f}x")
    print(f"(medians of {args.repeats} runs; scan: {N_SCAN} delays on (0, 1.5 h_max], "
          f"bisection to {SCAN_XTOL:g}, 1 run; bar: sweep under 50 ms)")


if __name__ == "__main__":
    main()
