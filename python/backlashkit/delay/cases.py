"""The validation cases of docs/validation/delay-margins.md, and the command that prints
their table and draws their figures::

    python -m backlashkit.delay.cases [--figures DIR]

Every number of that page comes from this command (or from the tests and the benchmark
named there).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from .loops import (
    input_delay_loop,
    mrc_delay_system,
    pi_controller,
    siso_delay_margin,
    two_mass_contact,
)
from .margin import delay_margin, margin_of_system

__all__ = ["PUBLISHED", "critical_gains", "main", "paper_b_loop", "paper_b_margins",
           "two_mass_margins"]

#: (name, A0, A, B, published value of h_max in s, where it is published)
PUBLISHED = [
    ("x' = -x(t-h)", 0.0, [-1.0], None, math.pi / 2, "closed form pi/(2a)"),
    ("x' = 0.5x - 2x(t-h)", 0.5, [-2.0], None,
     math.acos(-0.5 / -2.0) / math.sqrt(4 - 0.25), "Hayes 1950 closed form"),
    ("x' - 0.5x'(t-h) = -x - 2x(t-h)", -1.0, [-2.0], [0.5], math.pi / 4,
     "neutral closed form"),
    ("diag(-2,-0.9), [[-1,0],[-1,-1]]", np.diag([-2.0, -0.9]),
     [np.array([[-1.0, 0.0], [-1.0, -1.0]])], None, 6.1725, "classic (Gu et al. 2003)"),
    ("25/(s^3+10s^2+10s+10), loop delay",
     np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-10.0, -10.0, -10.0]]),
     [np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-25.0, 0.0, 0.0]])], None, 0.2847,
     "MATLAB allmargin"),
    ("Olgac & Sipahi 2002 (3x3)",
     np.array([[-1.0, 13.5, -1.0], [-3.0, -1.0, -2.0], [-2.0, -1.0, -4.0]]),
     [np.array([[-5.9, 7.1, -70.3], [2.0, -1.0, 5.0], [2.0, 0.0, 6.0]])], None, 0.1624,
     "Olgac & Sipahi 2002 (matrices as in Haag et al. 2009, ex. 3)"),
]

#: Paper B, Section IV: plant and the backlash slopes (true, initial estimate).
PAPER_B_PLANT = ([1.0], [1.0, -0.5, -1.5])
M_TRUE, M_HAT_0 = 0.7, 0.2
#: Paper A's drive and the PI speed gains of the two-mass case.
PAPER_A_DRIVE = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2,
                     f_sh=1.575e-2)
PI_GAINS = [(0.05, 0.5), (0.2, 2.0), (0.5, 10.0)]


def paper_b_loop(gain: float):
    """Paper B's model-reference loop with loop gain ``gain = m / m_hat``.

    Parameters
    ----------
    gain : float
        Gain of backlash and inverse in the moving regime.

    Returns
    -------
    plant : tuple (A, B, C, D)
        The plant in controllable form.
    controller : tuple (A, B, C, D)
        :func:`~backlashkit.delay.loops.mrc_controller`.
    system : DelaySystem
        Delay at the plant input.
    """
    from ..control import design_mrc

    return mrc_delay_system(design_mrc(PAPER_B_PLANT), gain=gain)


def paper_b_margins(gains) -> list[tuple[float, float, float, float]]:
    """``(gain, h_max, omega, SISO margin)`` of paper B's loop for each gain.

    Parameters
    ----------
    gains : iterable of float
        Loop gains ``m / m_hat``.

    Returns
    -------
    list of tuple
        s, rad/s, s.
    """
    out = []
    for g in gains:
        plant, ctrl, system = paper_b_loop(g)
        r = margin_of_system(system, verify=False)
        siso = siso_delay_margin(plant, ctrl, sign=+1.0)[0] if r.stable_at_zero else math.nan
        out.append((g, r.h_max, r.omega, siso))
    return out


def critical_gains(lo: float = 0.5, mid: float = 1.0, hi: float = 3.5,
                   iterations: int = 40) -> tuple[float, float]:
    """Loop gains ``m / m_hat`` at which paper B's loop loses stability at ``h = 0``.

    Parameters
    ----------
    lo, mid, hi : float
        ``mid`` stable, ``lo`` and ``hi`` unstable.
    iterations : int
        Bisection steps.

    Returns
    -------
    tuple of float
        Lower and upper gains.
    """
    def stable(g):
        return paper_b_loop(g)[2].unstable_at_zero() == 0

    out = []
    for a, b in ((mid, lo), (mid, hi)):
        for _ in range(iterations):
            m = 0.5 * (a + b)
            a, b = (m, b) if stable(m) else (a, m)
        out.append(0.5 * (a + b))
    return out[0], out[1]


def two_mass_margins() -> list[tuple[float, float, float, float, float]]:
    """``(kp, ki, h_max, omega, SISO margin)`` of paper A's drive under PI speed control.

    Returns
    -------
    list of tuple
        Gains, s, rad/s, s.
    """
    from ..plants import TwoMassDrive

    plant = two_mass_contact(TwoMassDrive(**PAPER_A_DRIVE))
    out = []
    for kp, ki in PI_GAINS:
        r = margin_of_system(input_delay_loop(plant, pi_controller(kp, ki)))
        out.append((kp, ki, r.h_max, r.omega, siso_delay_margin(plant, pi_controller(kp, ki))[0]))
    return out


def _figures(out: Path) -> None:
    from matplotlib.figure import Figure

    name, a0, a, b, _, _ = PUBLISHED[5]
    delay_margin(a0, a, b).plot(h_range=(0.0, 0.4)).savefig(out / "delay-olgac-sipahi.png",
                                                            dpi=100)
    gains = np.linspace(0.25, 3.5, 53)
    rows = paper_b_margins(gains)
    fig = Figure(figsize=(6, 4), layout="constrained")
    ax = fig.subplots()
    ax.plot(gains, [r[1] for r in rows], label="h_max (Chen sweep)")
    ax.plot(gains, [r[3] for r in rows], "--", label="min PM_i / omega_i (python-control)")
    for g, lab in ((1.0, "theta_b*"), (M_TRUE / M_HAT_0, "theta_b(0)")):
        ax.axvline(g, color="k", lw=0.8, ls=":")
        ax.annotate(lab, (g, 0.05), rotation=90, ha="right")
    ax.set_xlabel("loop gain m / m_hat of backlash and inverse (-)")
    ax.set_ylabel("delay margin (s)")
    ax.set_title("paper B's MRC loop, delay at the plant input")
    ax.legend(loc="upper right")
    fig.savefig(out / "delay-paper-b-gain.png", dpi=100)


def main(argv=None) -> int:
    """Print the validation table; with ``--figures DIR``, draw the figures there.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments.

    Returns
    -------
    int
        0.
    """
    p = argparse.ArgumentParser(prog="python -m backlashkit.delay.cases")
    p.add_argument("--figures", metavar="DIR", help="write the figures into DIR")
    args = p.parse_args(argv)
    print("| case | sweep h_max (s) | kronecker h_max (s) | published | source |")
    print("|---|---|---|---|---|")
    for name, a0, a, b, ref, src in PUBLISHED:
        hs = delay_margin(a0, a, b).h_max
        hk = delay_margin(a0, a, b, method="kronecker").h_max
        print(f"| {name} | {hs:.12g} | {hk:.12g} | {ref:.12g} | {src} |")
    name, a0, a, b, _, _ = PUBLISHED[5]
    r = delay_margin(a0, a, b)
    print(f"{name}: windows on [0, 2] s: "
          + ", ".join(f"({lo:.6f}, {hi:.6f})" for lo, hi in r.stability_windows((0.0, 2.0)))
          + "; crossing frequencies " + ", ".join(f"{c.omega:.4f}" for c in r.crossings))
    print("\npaper B loop (gain, h_max, omega, SISO):")
    for g, h, w, siso in paper_b_margins([1.0, 1.5, 2.0, 2.5, 3.0, M_TRUE / M_HAT_0]):
        print(f"| {g:.3g} | {h:.10g} | {w:.10g} | {siso:.10g} |")
    plant, ctrl, _ = paper_b_loop(1.0)
    for w, pm in siso_delay_margin(plant, ctrl, sign=+1.0)[1]:
        print(f"paper B loop, theta_b*: gain crossover {w:.6g} rad/s, phase margin "
              f"{pm:.6g} deg, PM/omega_c = {math.radians(pm) / w:.10g} s")
    g_lo, g_hi = critical_gains()
    print(f"paper B loop stable at h = 0 for {g_lo:.4f} < m/m_hat < {g_hi:.4f}")
    print("\ntwo-mass drive, PI (kp, ki, h_max, omega, SISO):")
    for kp, ki, h, w, siso in two_mass_margins():
        print(f"| {kp:g} | {ki:g} | {h:.10g} | {w:.10g} | {siso:.10g} |")
    if args.figures:
        out = Path(args.figures)
        out.mkdir(parents=True, exist_ok=True)
        _figures(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
