"""Benchmark: paper B's 60 s closed loop (exact adaptive inverse), compiled kernel vs the
NumPy reference (same algorithm), median of several runs measured in the same process.

Run: ``python benchmarks/bench_control.py``.
"""

from __future__ import annotations

import statistics
import time

from backlashkit.control.adaptive import AdaptiveLaw
from backlashkit.control.closed_loop import SumOfSines, build_problem, run_problem
from backlashkit.control.design import design_mrc
from backlashkit.nonlinearities import Backlash
from backlashkit.papers.tao1995 import PAPER, VARIANTS


def _median(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main() -> None:
    d = design_mrc(
        PAPER["plant"], reference_model=PAPER["reference_model"], filter=PAPER["filter"]
    )
    law = AdaptiveLaw(gamma=PAPER["gamma"], theta_b0=PAPER["theta_b0"], m0=0.02)
    rows = []
    for name in ("exact", "smooth-filter"):
        prob = build_problem(
            PAPER["plant"],
            Backlash(*PAPER["backlash"]),
            inverse=VARIANTS[name],
            adaptation=law,
            reference=SumOfSines(*PAPER["reference"]),
            duration=60.0,
            ts=0.01,
            step=1e-3,
            design=d,
        )
        tr, out = _median(lambda p=prob: run_problem(p, backend="rust"), 7)
        tn, _ = _median(lambda p=prob: run_problem(p, backend="numpy"), 1)
        e = out["y"] - out["ym"]
        rms = float((e[out["t"] >= 40.0] ** 2).mean() ** 0.5)
        rows.append((name, tr, tn, rms))
    print(
        f"{'variant':15s} {'rust [s]':>10s} {'numpy [s]':>10s} {'speed-up':>9s} "
        f"{'RMS e last 20 s':>16s}"
    )
    for name, tr, tn, rms in rows:
        print(f"{name:15s} {tr:10.4f} {tn:10.2f} {tn / tr:9.0f} {rms:16.3e}")
    print("(60 s, RK4 step 1 ms with located switches; rust: median of 7, numpy: 1 run)")


if __name__ == "__main__":
    main()
