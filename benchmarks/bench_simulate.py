"""Speed and accuracy of the drive simulator against its peers, measured in one run.

Workload: paper A's experiment (Section 5): the two-mass drive, torque 0.157 N m for
40 s then 0 for 40 s, sampled at 1 ms (80 001 samples), from rest, paper law.

Peers, all measured here, in this process, on this machine:

* ``scipy reference``: :func:`backlashkit.verify.reference_simulate`, scipy's DOP853 at
  rtol 1e-10, restarted at every located contact change (timed); speed errors are
  measured against the same reference at rtol 1e-12;
* ``solve_ivp with events``: what a user would write with plain
  :func:`scipy.integrate.solve_ivp`: DOP853 with terminal events on the twist's flank
  crossings, restarted in the new contact mode at each one and at the input's change.
  Configured to our accuracy: ``rtol = 1e-12``, ``atol = 1e-12`` times the state
  scales (15.7 rad/s, 15.7 rad/s, 0.05 rad), and ``max_step = 2 ms`` (``solve_ivp``
  compares the sign of an event function at the ends of each step only; with unbounded
  steps it misses short contacts and ends 1.4x the largest speed away). Its achieved
  speed error against the exact answer (the rtol 1e-13 reference) is printed beside it;
* ``python-control``: ``input_output_response`` of a ``NonlinearIOSystem`` with the same
  right-hand side (no event location; python-control interpolates the input linearly);
* ``numpy reference``: the plain-NumPy twin of the compiled kernel;
* ``bare loop``: the hand-written recurrence ``x <- E x + fb u + fc`` with no event
  checks (the latency bound of any sequential simulation of this drive).

The same workload with Coulomb friction and stiction (``fc_M = 0.01``, ``fc_L = 0.02``,
``fs_M = 0.015``, ``fs_L = 0.03`` N m; the drive sticks after the step-down) is timed
against the run without, in the same process (target: at most 1.3x).

Each timing is the median of ``--repeats`` runs. Usage::

    python benchmarks/bench_simulate.py [--repeats 7] [--quick] [--json FILE]

``--quick`` skips the slow peers' repeats (one run each) for a fast look.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
import warnings

import numpy as np

import backlashkit as bk
from backlashkit import _core

PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2
#: Coulomb and breakaway torques of the friction variant, N m.
FRICTION = dict(fc_M=0.01, fc_L=0.02, fs_M=0.015, fs_L=0.03)


def median_time(fn, repeats: int, warmup: bool = True) -> tuple[float, object]:
    if warmup:
        fn()
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def paper_rhs(drive: bk.TwoMassDrive):
    jm, jl, k, fm, fl, fs, th = (
        drive.J_M,
        drive.J_L,
        drive.k_sh,
        drive.f_M,
        drive.f_L,
        drive.f_sh,
        drive.theta,
    )

    def rhs(t, x, u, params=None):
        wm, wl, phi = x
        if phi >= th:
            c = k * (phi - th) + fs * (wm - wl)
        elif phi <= -th:
            c = k * (phi + th) + fs * (wm - wl)
        else:
            c = 0.0
        u0 = float(np.atleast_1d(u)[0])
        return np.array([(u0 - fm * wm - c) / jm, (c - fl * wl) / jl, wm - wl])

    return rhs


#: solve_ivp peer's settings, chosen to reach the simulator's accuracy (see the module
#: docstring): tolerances relative to the state scales, and a step bound so that the
#: sign test at step ends sees every short contact.
PEER_RTOL = 1e-12
PEER_SCALES = np.array([15.7, 15.7, 0.05])
PEER_MAX_STEP = 2e-3


def solve_ivp_events(drive: bk.TwoMassDrive, t: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Paper law with plain ``solve_ivp``: terminal flank events, restarted at each."""
    from scipy.integrate import solve_ivp

    jm, jl, k, fm, fl, fsh, th = (
        drive.J_M, drive.J_L, drive.k_sh, drive.f_M, drive.f_L, drive.f_sh, drive.theta
    )

    def rhs(_t, x, ui, mode):
        wm, wl, phi = x
        c = 0.0 if mode == 0 else k * (phi - mode * th) + fsh * (wm - wl)
        return [(ui - fm * wm - c) / jm, (c - fl * wl) / jl, wm - wl]

    def upper(_t, x, ui, mode):
        return x[2] - th

    def lower(_t, x, ui, mode):
        return x[2] + th

    upper.terminal = lower.terminal = True
    # Directions that leave each mode: (upper, lower); 0 disables a crossing.
    directions = {0: (1, -1), 1: (-1, 0), -1: (0, 1)}
    out = np.empty((t.size, 3))
    x, mode = np.zeros(3), 0
    out[0] = x
    change = np.flatnonzero(np.diff(u[:-1]) != 0) + 1
    bounds = np.concatenate([[0], change, [t.size - 1]])
    for i0, i1 in zip(bounds[:-1], bounds[1:], strict=True):
        ui, tc = float(u[i0]), float(t[i0])
        while True:
            upper.direction, lower.direction = directions[mode]
            sel = np.flatnonzero((t > tc) & (t <= t[i1]))
            sol = solve_ivp(
                rhs, (tc, float(t[i1])), x, method="DOP853", rtol=PEER_RTOL,
                atol=PEER_RTOL * PEER_SCALES, max_step=PEER_MAX_STEP, t_eval=t[sel],
                events=[upper, lower], args=(ui, mode),
            )
            out[sel[: len(sol.t)]] = sol.y.T
            if sol.status != 1:
                x = sol.y[:, -1].copy()
                break
            hit = 0 if sol.t_events[0].size else 1
            tc, x = float(sol.t_events[hit][0]), sol.y_events[hit][0].copy()
            mode = (1 if hit == 0 else -1) if mode == 0 else 0
    return out


def bare_loop_args(drive: bk.TwoMassDrive, ts: float):
    from scipy.linalg import expm

    jm, jl, k, fm, fl, fs = (drive.J_M, drive.J_L, drive.k_sh, drive.f_M, drive.f_L, drive.f_sh)
    a = np.array(
        [[-(fm + fs) / jm, fs / jm, -k / jm], [fs / jl, -(fl + fs) / jl, k / jl], [1.0, -1.0, 0.0]]
    )
    big = np.zeros((6, 6))
    big[:3, :3], big[:3, 3:] = a * ts, np.eye(3) * ts
    m = expm(big)
    return m[:3, :3].copy(), m[:3, 3:] @ np.array([1 / jm, 0.0, 0.0]), np.zeros(3)


def first_call_latency(repeats: int) -> tuple[float, float]:
    """Wall time of a fresh interpreter that imports backlashkit and simulates 1 s, and of
    one that only starts (so the difference is what a CLI user waits for)."""
    code = (
        "import numpy as np, backlashkit as bk; d = bk.TwoMassDrive(J_M=4.88e-3, J_L=6.8e-2,"
        " k_sh=78, f_M=5e-3, f_L=5e-3, f_sh=1.575e-2, theta=0.0349);"
        " t = np.arange(1001) * 1e-3; d.simulate(t, np.full(t.size, 0.157))"
    )
    run = lambda c: subprocess.run([sys.executable, "-c", c], check=True)  # noqa: E731
    sim, _ = median_time(lambda: run(code), repeats)
    bare, _ = median_time(lambda: run("import numpy"), repeats)
    return sim, bare



def _verdict(met: bool) -> str:
    """A target's outcome, said in words (a missed target is printed, not hidden)."""
    return "MET" if met else "MISSED"

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args(argv)
    slow_repeats = 1 if args.quick else 3

    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    ts = 1e-3
    t = np.arange(80001) * ts
    u = np.where(t < 40.0, 0.157, 0.0)
    chain = drive.to_chain()
    kargs = [np.asarray(v) for v in (chain.J, chain.f, chain.k, chain.d, chain.theta)]
    x0 = np.zeros(3)
    rows = {}

    print("measuring backlashkit ...", file=sys.stderr)
    rows["backlashkit simulate()"], ours = median_time(lambda: drive.simulate(t, u), args.repeats)
    sticky = bk.TwoMassDrive(**PAPER, theta=THETA, **FRICTION)
    # Interleaved with runs without friction, so that both see the same machine load.
    with_friction = sticky.simulate(t, u)
    pairs: dict[str, list[float]] = {"without": [], "with": []}
    for _ in range(3 * args.repeats):
        for key, d in (("without", drive), ("with", sticky)):
            t0 = time.perf_counter()
            d.simulate(t, u)
            pairs[key].append(time.perf_counter() - t0)
    friction_ratio = statistics.median(pairs["with"]) / statistics.median(pairs["without"])
    rows["compiled kernel alone"], _ = median_time(
        lambda: _core.simulate_chain(*kargs, 0, 0.0, ts, u, x0), args.repeats
    )
    e, fb, fc = bare_loop_args(drive, ts)
    rows["bare loop (latency bound)"], _ = median_time(
        lambda: _core.bare_recurrence(e, fb, fc, u, x0), args.repeats
    )
    print("measuring the scipy event-located reference ...", file=sys.stderr)
    from backlashkit.verify import reference_simulate

    rows["scipy reference (DOP853 1e-10)"], _ = median_time(
        lambda: reference_simulate(drive, t, u, method="DOP853", rtol=1e-10),
        slow_repeats,
        warmup=False,
    )
    # Speed errors are judged against a tighter run: at rtol 1e-10 the reference's own
    # error on this record is ~3e-8 of the speed.
    ref = reference_simulate(drive, t, u, method="DOP853", rtol=1e-13)
    print("measuring plain solve_ivp with terminal events ...", file=sys.stderr)
    rows["solve_ivp with events (DOP853 1e-12)"], peer = median_time(
        lambda: solve_ivp_events(drive, t, u), slow_repeats, warmup=False
    )
    print("measuring the NumPy reference kernel ...", file=sys.stderr)
    rows["numpy reference kernel"], npref = median_time(
        lambda: bk.simulate_drive(drive, t, u, backend="numpy"), slow_repeats, warmup=False
    )
    print("measuring python-control ...", file=sys.stderr)
    import control as ct

    sys_ = ct.nlsys(paper_rhs(drive), None, states=3, inputs=1, outputs=3, name="drive")
    rows["python-control input_output_response"], ctl = median_time(
        lambda: ct.input_output_response(
            sys_, t, u, X0=x0, solve_ivp_method="RK45", solve_ivp_kwargs=dict(rtol=1e-8, atol=1e-10)
        ),
        slow_repeats,
        warmup=False,
    )

    speed_ref = ref.states[:, :2]
    scale = np.abs(speed_ref).max()
    err = {
        "backlashkit simulate()": np.abs(ours.states[:, :2] - speed_ref).max() / scale,
        "numpy reference kernel": np.abs(npref.states[:, :2] - speed_ref).max() / scale,
        "solve_ivp with events (DOP853 1e-12)": np.abs(peer[:, :2] - speed_ref).max() / scale,
        "python-control input_output_response": np.abs(
            np.asarray(ctl.states).T[:, :2] - speed_ref
        ).max()
        / scale,
    }
    ev_ours = np.array([ev.time for ev in ours.events])
    ev_ref = np.array([ev.time for ev in ref.events])
    event_err = (
        float(np.abs(ev_ours - ev_ref).max()) if ev_ours.size == ev_ref.size else float("nan")
    )

    print("measuring a batch of 1000 runs (theta grid) on 1 and 2 workers ...", file=sys.stderr)
    # 8 s records (the same step-down, held 4 s): with the full 80 s records the batch
    # writes 1.9 GB of fresh output, and page faulting that memory, not the simulation,
    # decides the timing (measured 1.4x to 2.8x from run to run).
    drives = [drive.with_theta(th) for th in np.linspace(0.5, 5.0, 1000) * np.pi / 180]
    tb = t[:8001]
    ub = np.where(tb < 4.0, 0.157, 0.0)
    batch_times: dict[int, list[float]] = {1: [], 2: []}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bk.SensitivityWarning)
        for workers in (1, 2):  # warm-up of each, then interleaved runs
            bk.simulate_batch(drives, tb, ub, workers=workers)
        for _ in range(max(3, slow_repeats)):
            for workers in (1, 2):
                t0 = time.perf_counter()
                bk.simulate_batch(drives, tb, ub, workers=workers)
                batch_times[workers].append(time.perf_counter() - t0)
    b1, b2 = (statistics.median(batch_times[w]) for w in (1, 2))
    print("measuring first-call latency (fresh interpreters) ...", file=sys.stderr)
    fc_sim, fc_base = first_call_latency(3)

    base = rows["backlashkit simulate()"]
    print(
        f"\nPaper A experiment, 80 s at 1 ms (80 001 samples); medians of {args.repeats} runs "
        f"(slow peers: {slow_repeats}); {os.cpu_count()} cores\n"
    )
    print(f"{'simulator':42s} {'time [ms]':>11s} {'vs backlashkit':>15s} {'max speed err':>14s}")
    for name, sec in rows.items():
        e_ = err.get(name)
        e_s = f"{e_:.1e}" if e_ is not None else ("(reference)" if "scipy" in name else "")
        print(f"{name:42s} {sec * 1e3:11.3f} {sec / base:14.2f}x {e_s:>14s}")
    kernel, bare = rows["compiled kernel alone"], rows["bare loop (latency bound)"]
    print(
        f"\nscipy reference / backlashkit: {rows['scipy reference (DOP853 1e-10)'] / base:.0f}x "
        f"(target >= 500x: {_verdict(rows['scipy reference (DOP853 1e-10)'] / base >= 500)})"
    )
    print(
        "solve_ivp with events / backlashkit: "
        f"{rows['solve_ivp with events (DOP853 1e-12)'] / base:.0f}x at speed errors "
        f"{err['solve_ivp with events (DOP853 1e-12)']:.1e} vs {err['backlashkit simulate()']:.1e}"
    )
    print(
        f"kernel / bare loop: {kernel / bare:.2f}x; simulate() / bare loop: {base / bare:.2f}x "
        f"(target <= 2x: {_verdict(base / bare <= 2)})"
    )
    print(f"max |event time - reference|: {event_err:.1e} s over {ev_ours.size} contact changes")
    print(
        f"Coulomb + stiction / without (interleaved runs): {friction_ratio:.2f}x "
        f"(target <= 1.3x: {_verdict(friction_ratio <= 1.3)}; "
        f"{len(with_friction.contact_events)} contact and "
        f"{len(with_friction.friction_events)} friction events)"
    )
    print(
        f"batch of 1000 (8 s records): 1 worker {b1:.3f} s, 2 workers {b2:.3f} s, "
        f"speed-up {b1 / b2:.2f}x (target >= 1.7x: {_verdict(b1 / b2 >= 1.7)}; a machine "
        "busy with other work cannot show it)"
    )
    print(
        f"first call (fresh interpreter, import + 1 s simulation): {fc_sim * 1e3:.0f} ms; "
        f"interpreter + numpy alone: {fc_base * 1e3:.0f} ms"
    )
    if args.json:
        with open(args.json, "x") as fh:
            json.dump(
                {
                    "times_s": rows,
                    "rel_speed_error": err,
                    "event_time_error_s": event_err,
                    "batch_1000_s": {"1": b1, "2": b2},
                    "first_call_s": {"backlashkit": fc_sim, "baseline": fc_base},
                },
                fh,
                indent=2,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
