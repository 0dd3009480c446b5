"""Accuracy of the compiled simulator against the independent ODE reference.

The reference (:mod:`backlashkit.verify`) integrates the drive with scipy's DOP853 and
locates every contact change by root finding; it shares no code with the kernel
(matrix exponentials). Bars, never loosened:

* ``max |w_sim - w_ref| <= 1e-7 * max |w_ref|`` over the grid and all inertias;
* the same contact changes (shaft, kind, flank) in the same order, times within 1e-6 s.

A case on which two tight references (DOP853 at rtol 1e-12 and 1e-13) disagree is
ill-conditioned (a near-grazing contact decides the rest of the run): it says nothing
about the simulator and is excluded, and the simulator must have warned about it
(``near_grazing``). When the references agree and the simulator reports no
near-grazing, the bars must hold.

Reproduce the figures of the report: ``python -m pytest tests/test_accuracy.py -s``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st

import backlashkit as bk
from backlashkit.verify import check_conditioning, compare_to_reference

SPEED_RTOL = 1e-7
EVENT_TOL = 1e-6
TS = 1e-3

# Paper A, Section 5 (Ravanbod-Shirazi & Besancon-Voda 2002; see
# /work/shared/papers/NOTES.md): the two-mass drive of eq. 2.
PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2
A1 = 0.157  # a1 = 0.1 a_max, N m


def simulate(drive, t, u, law, x0=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bk.SensitivityWarning)
        return drive.simulate(t, u, law=law, initial_state=x0)


def _note(text: str) -> None:
    """``hypothesis.note`` inside a hypothesis test, nothing elsewhere."""
    try:
        note(text)
    except Exception:  # noqa: BLE001 - outside @given hypothesis refuses notes
        pass


def judge(drive, t, u, law, x0=None):
    """Compare simulator and reference; returns ``(status, report)``.

    ``status`` is "ill-conditioned" (references disagree; the simulator must have warned),
    "warned" (references agree, the simulator reported a near-grazing pass; bars not
    enforced) or "checked" (the bars were asserted).
    """
    cond = check_conditioning(drive, t, u, law=law, initial_state=x0)
    sim = simulate(drive, t, u, law, x0)
    report = compare_to_reference(sim, cond.reference)
    _note(
        f"conditioning: {cond.well_conditioned} {cond.reasons}; accuracy: {report}; "
        f"near-grazing: {sim.near_grazing}"
    )
    if not cond.well_conditioned:
        # The case says nothing about the simulator, but users must be able to tell it
        # is sensitive: by the near-grazing report, or by assess_sensitivity.
        assert (
            sim.near_grazing
            or bk.assess_sensitivity(drive, t, u, law=law, initial_state=x0).sensitive
        ), f"references disagree ({cond.reasons}) but nothing flags the run"
        return "ill-conditioned", report
    if sim.near_grazing:
        return "warned", report
    assert report.same_event_sequence, (
        [(e.shaft, e.kind, e.flank) for e in sim.events],
        [(e.shaft, e.kind, e.flank) for e in cond.reference.events],
    )
    assert report.speed_error_ratio <= SPEED_RTOL, report
    assert report.max_event_time_diff <= EVENT_TOL, report
    return "checked", report


# --------------------------------------------------------------------------- paper A


@pytest.mark.parametrize("law", ["paper", "no-pull"])
def test_paper_experiment(law):
    # Section 5: torque a1 = 0.157 N m for t_s = 40 s, then 0 for 40 s, Ts = 1 ms, from
    # rest (twist in the middle of the gap).
    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    t = np.arange(80001) * TS
    u = np.where(t < 40.0, A1, 0.0)
    cond = check_conditioning(drive, t, u, law=law)
    assert cond.well_conditioned, cond.reasons
    sim = simulate(drive, t, u, law)
    assert sim.near_grazing == ()
    report = compare_to_reference(sim, cond.reference)
    print(
        f"\npaper experiment [{law}]: speed error ratio {report.speed_error_ratio:.2e} "
        f"(max |dw| {report.max_speed_error:.2e} rad/s), {report.n_events} events, "
        f"max event-time difference {report.max_event_time_diff:.2e} s; references agree "
        f"to {cond.max_speed_rel_diff:.1e} / {cond.max_event_time_diff:.1e} s"
    )
    assert report.n_events > 50  # the start-up chatter of the load on the positive flank
    assert report.same_event_sequence
    assert report.speed_error_ratio <= SPEED_RTOL
    assert report.max_event_time_diff <= EVENT_TOL
    # modes agree away from the contact changes
    times = cond.reference.event_times
    near = np.min(np.abs(t[:, None] - times[None, :]), axis=1) < 1e-6
    assert np.array_equal(sim.modes[~near], cond.reference.modes[~near])


# --------------------------------------------------------------------------- random drives


def log_uniform(lo: float, hi: float):
    return st.floats(np.log10(lo), np.log10(hi)).map(lambda e: float(10.0**e))


#: Fractions in [-1, 1] on a grid of 0.01: an initial state drawn from raw floats can be
#: a subnormal 1e-300, where neither simulator nor reference has any precision left.
GRID = st.integers(-100, 100).map(lambda i: i / 100)


@st.composite
def drive_cases(draw, n_inertias: int):
    """A chain with resonances of 5 .. 300 rad/s, damping ratios 0 .. 0.3, backlash
    0 .. 0.1 rad, a short record (0.3 .. 1 s at Ts = 1 ms) and a piecewise-constant
    torque with sign changes large enough to cross the gaps often."""
    n = n_inertias
    J = np.array([draw(log_uniform(1e-3, 1.0)) for _ in range(n)])
    j_red = J[:-1] * J[1:] / (J[:-1] + J[1:])
    omega = np.array([draw(log_uniform(5.0, 300.0)) for _ in range(n - 1)])
    k = omega**2 * j_red
    zeta = np.array([draw(st.floats(0.0, 0.3)) for _ in range(n - 1)])
    d = 2 * zeta * np.sqrt(k * j_red)
    f = J * np.array([draw(st.one_of(st.just(0.0), log_uniform(1e-2, 3.0))) for _ in range(n)])
    theta = np.array([draw(st.one_of(st.just(0.0), st.floats(1e-3, 0.1))) for _ in range(n - 1)])
    chain = bk.DriveChain(J=J, f=f, k=k, d=d, theta=theta)

    n_samples = draw(st.integers(300, 1000)) + 1
    t = np.arange(n_samples) * TS
    amp = J.sum() * max(theta.max(), 0.01) * draw(log_uniform(30.0, 3000.0))
    lengths, levels = [], []
    while sum(lengths) < n_samples:
        lengths.append(draw(st.integers(5, 150)))
        level = draw(st.one_of(st.just(0.0), st.floats(0.05, 1.0)))
        levels.append(amp * level * draw(st.sampled_from([-1.0, 1.0])))
    u = np.repeat(levels, lengths)[:n_samples]
    x0 = None
    if draw(st.booleans()):
        x0 = np.concatenate(
            [
                [draw(GRID) * 0.1 * amp / J.sum() for _ in range(n)],
                [1.5 * draw(GRID) * th for th in theta],
            ]
        )
    return chain, t, u, x0


HYPOTHESIS = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)


#: Least number of random cases whose bars were asserted ("checked": references agree,
#: no near-grazing warning), per test. ``assume`` discards the ill-conditioned ones, so
#: without this floor the tests could pass having checked nothing. Measured (derandomized):
#: 40 of 40 checked for both sizes, no case discarded; ``python -m pytest
#: tests/test_accuracy.py -s -k random`` prints the counts.
MIN_CHECKED = {2: 36, 3: 36}


def run_random_cases(n_inertias: int) -> dict[str, int]:
    """Run the random cases of ``n_inertias`` and count them by ``judge`` status."""
    counts = {"checked": 0, "warned": 0, "ill-conditioned": 0}

    @HYPOTHESIS
    @given(case=drive_cases(n_inertias), law=st.sampled_from(["paper", "no-pull"]))
    def one_case(case, law):
        chain, t, u, x0 = case
        status, _ = judge(chain, t, u, law, x0)
        counts[status] += 1
        assume(status != "ill-conditioned")

    one_case()
    print(f"\nrandom {n_inertias}-inertia cases: {counts}")
    return counts


def test_random_two_mass_drives():
    counts = run_random_cases(2)
    assert counts["checked"] >= MIN_CHECKED[2], counts


def test_random_three_mass_chains():
    counts = run_random_cases(3)
    assert counts["checked"] >= MIN_CHECKED[3], counts


# --------------------------------------------------------------------------- chains


THREE_MASS = [
    # a stiff motor shaft and a soft load shaft, both with play
    bk.DriveChain(
        J=[0.01, 0.03, 0.2], f=[0.01, 0.02, 0.05], k=[60.0, 150.0], d=[0.2, 0.5], theta=[0.02, 0.01]
    ),
    # a light middle inertia (fast inner mode), one shaft without play
    bk.DriveChain(
        J=[0.05, 0.002, 0.1], f=[0.02, 0.0, 0.03], k=[40.0, 25.0], d=[0.01, 0.05], theta=[0.0, 0.05]
    ),
    # the paper drive with a gearbox inertia between motor and load
    bk.DriveChain(
        J=[4.88e-3, 1e-2, 6.8e-2],
        f=[0.5e-2, 0.0, 0.5e-2],
        k=[78.0, 150.0],
        d=[1.575e-2, 3e-2],
        theta=[3.49e-2, 1e-2],
    ),
]


@pytest.mark.parametrize("law", ["paper", "no-pull"])
@pytest.mark.parametrize("index", range(len(THREE_MASS)))
def test_three_mass_chains(index, law):
    chain = THREE_MASS[index]
    t = np.arange(3001) * TS
    u = 0.4 * np.repeat([1.0, -0.8, 0.3, 0.0, -1.0, 0.6, -0.2, 0.9], 376)[: t.size]
    status, report = judge(chain, t, u, law)
    print(
        f"\nthree-mass chain {index} [{law}]: {status}, speed error ratio "
        f"{report.speed_error_ratio:.2e}, {report.n_events} events, max event-time "
        f"difference {report.max_event_time_diff:.2e} s"
    )
    # chain 2 (the paper drive with a gearbox inertia) rattles through ~190 impacts in 3 s
    # and amplifies rounding: its references disagree and assess_sensitivity flags it.
    assert status == ("ill-conditioned" if index == 2 else "checked")
    assert report.n_events > 10


# --------------------------------------------------------------------------- near grazing


def tangent_case(margin_rel: float):
    """Free flight towards the positive flank, decelerated so that the twist peaks at
    ``theta (1 - margin_rel)`` at ``t = 24.4 ms`` (closed form, motor friction, load at
    rest); then the motor reverses to the negative flank and is driven back. Negative
    ``margin_rel``: a poke past the flank."""
    jm, jl, fm, k, d, theta, w0, u0 = 0.01, 1.0, 0.02, 100.0, 0.5, 0.02, 1.0, -0.4
    wi, tau = u0 / fm, jm / fm
    t_peak = tau * np.log((w0 - wi) / -wi)
    rise = wi * t_peak + (w0 - wi) * tau * (1 - np.exp(-t_peak / tau))
    chain = bk.DriveChain(J=[jm, jl], f=[fm, 0.0], k=[k], d=[d], theta=[theta])
    t = np.arange(301) * TS
    u = np.where(t < 0.1, u0, np.where(t < 0.2, 0.3, 0.0))
    return chain, t, u, [w0, 0.0, theta * (1 - margin_rel) - rise]


@pytest.mark.parametrize("law", ["paper", "no-pull"])
@pytest.mark.parametrize(
    "margin",
    [1e-3, 1e-5, 1e-7, 1e-9, 1e-11, -1e-11, -1e-9, -1e-7, -1e-5, -1e-3],
)
def test_near_grazing_family(margin, law):
    # Pokes of 1e-7..1e-11 theta used to end in a false "contact chatter" error (fixed).
    chain, t, u, x0 = tangent_case(margin)
    status, report = judge(chain, t, u, law, x0)
    sim = simulate(chain, t, u, law, x0)
    if abs(margin) >= 1e-5:
        assert status == "checked"
    if 0 < abs(margin) <= 1e-7:  # a near miss or a barely-crossed poke must be reported
        assert sim.near_grazing and abs(sim.near_grazing[0].time - 0.0244) < 1e-3
