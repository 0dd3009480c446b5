"""The simulation kernel on drives as they are: a current loop, Coulomb friction, and a
torque that changes every sample, against paper A's drive on paper A's record.

A current loop's lag is the drive's fastest mode: at 1 ms the engine splits each sample
into internal steps (``rho(A) h <= 1/2``), the more the faster the loop. A torque that
changes every sample (a controller's output, or a record's measured torque) is never
held long enough for the engine to prove that no contact can change (its settling), so
every sample is checked. Both are what real drives bring to the
fits of issue 20 and to the fleet.

Workloads: paper A's experiment (0.157 N m for 40 s, then 0 for 40 s, at 1 ms, 80 001
samples, from rest), and the same with a rattle: a uniform torque of +-0.02 N m added
to every sample of its first and last 10 s (the drive rattles in its backlash there),
seeded. Drives: paper A's, with Coulomb friction and breakaway torques
(``bench_simulate.py``'s), with a current loop of 1 ms and of 0.25 ms, and with both
(friction and a 1 ms loop).

Each row is the median of ``--repeats`` runs of the compiled kernel
(``_core.simulate_chain_batch``, one worker), in ms and per sample, and its ratio to
paper A's drive on the same record, measured interleaved in the same run.

``--base PATH`` loads another build of the kernel (the ``_core.abi3.so`` of another
commit: ``maturin build --release`` in a worktree of it, the file taken from the wheel)
into the same process and times it interleaved with this one on every row, and checks
that both give the same states, modes and contact changes to the bit.

Run: ``python benchmarks/bench_engine.py [--repeats 21] [--base PATH]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import time
from pathlib import Path

import numpy as np

import backlashkit as bk
from backlashkit import _core
from backlashkit.identify._model import packed_row
from backlashkit.laws import ShaftLaw

PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2
#: Coulomb and breakaway torques of the friction variant, N m (``bench_simulate.py``'s).
FRICTION = dict(fc_M=0.01, fc_L=0.02, fs_M=0.015, fs_L=0.03)
#: The rattle's half-range in N m, and the seconds of it at each end of the record.
RATTLE, RATTLE_S = 0.02, 10.0
TS = 1e-3

#: name -> (drive, current loop's time constant in s, 0: none)
DRIVES = {
    "paper A": (bk.TwoMassDrive(**PAPER, theta=THETA), 0.0),
    "Coulomb": (bk.TwoMassDrive(**PAPER, theta=THETA, **FRICTION), 0.0),
    "loop 1 ms": (bk.TwoMassDrive(**PAPER, theta=THETA), 1e-3),
    "loop 0.25 ms": (bk.TwoMassDrive(**PAPER, theta=THETA), 2.5e-4),
    "Coulomb, loop 1 ms": (bk.TwoMassDrive(**PAPER, theta=THETA, **FRICTION), 1e-3),
}


def records(seed: int) -> dict[str, np.ndarray]:
    """Paper A's torque, and the same with the rattle, each ``(1, 80 001)``."""
    t = np.arange(80_001) * TS
    step = np.where(t < 40.0, 0.157, 0.0)
    ends = (t < RATTLE_S) | (t >= t[-1] - RATTLE_S)
    noise = np.random.default_rng(seed).uniform(-RATTLE, RATTLE, t.size)
    return {"paper A's record": step[np.newaxis, :],
            "rattled": (step + np.where(ends, noise, 0.0))[np.newaxis, :]}


def load_build(path: str):
    """The kernel module of another build, loaded beside this one."""
    spec = importlib.util.spec_from_file_location("backlashkit._core", Path(path))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def run(core, drive, tau_i: float, torque: np.ndarray):
    """One kernel simulation of ``torque`` from rest."""
    p = packed_row(drive, tau_i)[np.newaxis, :]
    x0 = np.zeros((1, 4 if tau_i > 0 else 3))
    return core.simulate_chain_batch(2, p, ShaftLaw.parse("paper").code, 0.0, TS,
                                     np.ascontiguousarray(torque), x0, 1, False)


def same(a, b) -> bool:
    """Whether two kernel outputs hold the same states, modes and changes."""
    return (np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
            and repr(a[2]) == repr(b[2]))


def time_row(builds: dict, drive, tau_i: float, torque: np.ndarray, repeats: int
             ) -> dict[str, float]:
    """Median seconds per build, the builds' runs interleaved."""
    times: dict[str, list[float]] = {name: [] for name in builds}
    for core in builds.values():  # warm-up
        run(core, drive, tau_i, torque)
    for _ in range(repeats):
        for name, core in builds.items():
            t0 = time.perf_counter()
            run(core, drive, tau_i, torque)
            times[name].append(time.perf_counter() - t0)
    return {name: statistics.median(v) for name, v in times.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--base", metavar="PATH", help="another build's _core.abi3.so")
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args(argv)
    builds = {"this": _core}
    if args.base:
        builds["base"] = load_build(args.base)
    n = 80_001
    head = f"{'record':17s} {'drive':19s} {'ms':>7s} {'ns/sample':>10s} {'vs paper A':>11s}"
    print(head + (f" {'base ms':>8s} {'base/this':>10s} {'same bits':>10s}" if args.base else ""))
    for rec_name, torque in records(args.seed).items():
        plain = None
        for name, (drive, tau_i) in DRIVES.items():
            t = time_row(builds, drive, tau_i, torque, args.repeats)
            plain = t["this"] if plain is None else plain
            line = (f"{rec_name:17s} {name:19s} {t['this'] * 1e3:7.2f} "
                    f"{t['this'] / n * 1e9:10.1f} {t['this'] / plain:10.2f}x")
            if args.base:
                ok = same(run(_core, drive, tau_i, torque), run(builds["base"], drive, tau_i,
                                                                  torque))
                line += f" {t['base'] * 1e3:8.2f} {t['base'] / t['this']:9.2f}x {str(ok):>10s}"
            print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
