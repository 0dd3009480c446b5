"""Coulomb and static friction: stick-slip located exactly, as contact changes are.

Closed forms (a block: the motor alone inside a gap wide enough never to close), the
independent scipy reference of :mod:`backlashkit.verify` (written from the physics,
with its own event location), and the plain-NumPy twin.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import backlashkit as bk
from backlashkit.errors import InputError
from backlashkit.verify import check_conditioning, compare_to_reference, reference_simulate

PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2
#: The issue's bars.
SPEED_RTOL = 1e-7
STOP_TIME_TOL = 1e-9
WIDE = 100.0  # a gap no run here closes: the motor is a free block


def block(**kw) -> bk.TwoMassDrive:
    return bk.TwoMassDrive(**{**PAPER, "theta": WIDE, **kw})


def friction_events(resp):
    return [(e.inertia, e.kind, e.direction) for e in resp.friction_events]


def test_coulomb_block_stops_at_J_w0_over_fc():
    # No viscous friction: w = w0 - fc t / J until t* = J w0 / fc, then stuck at 0.
    J, fc, w0 = PAPER["J_M"], 0.02, 3.1  # stops at 0.7564 s, between samples
    drive = block(f_M=0.0, fc_M=fc)
    t = np.arange(1001) * 1e-3
    resp = drive.simulate(t, np.zeros(t.size), initial_state=[w0, 0.0, 0.0])
    t_stop = J * w0 / fc
    assert friction_events(resp) == [(0, "stuck", "none")]
    (ev,) = resp.friction_events
    print(f"\nstop time {ev.time!r} s vs J w0 / fc = {t_stop!r} s: {ev.time - t_stop:.1e} s")
    assert abs(ev.time - t_stop) <= STOP_TIME_TOL
    moving = t < t_stop
    np.testing.assert_allclose(resp.w_motor[moving], w0 - fc * t[moving] / J, rtol=0,
                               atol=1e-12)
    assert np.all(resp.w_motor[~moving] == 0.0)
    assert np.array_equal(resp.stuck[:, 0], ~moving)
    assert not resp.stuck[:, 1].any()


def test_coulomb_and_viscous_block_closed_form():
    # J w' = -f w - fc: w = (w0 + fc/f) exp(-f t/J) - fc/f, stop at (J/f) ln(1 + f w0/fc).
    J, f, fc, w0 = PAPER["J_M"], 0.01, 0.015, 4.0
    drive = block(f_M=f, fc_M=fc, fs_M=0.03)
    t = np.arange(2001) * 1e-3
    resp = drive.simulate(t, np.zeros(t.size), initial_state=[w0, 0.0, 0.0])
    t_stop = (J / f) * math.log1p(f * w0 / fc)
    (ev,) = resp.friction_events
    assert ev.kind == "stuck" and abs(ev.time - t_stop) <= STOP_TIME_TOL, ev
    moving = t < t_stop
    w = (w0 + fc / f) * np.exp(-f * t / J) - fc / f
    np.testing.assert_allclose(resp.w_motor[moving], w[moving], rtol=0, atol=1e-12)
    assert np.all(resp.w_motor[~moving] == 0.0)


def test_breakaway_at_the_ramps_crossing_of_fs():
    # A staircase ramp u_k = 0.003 k: held over the sample, it first exceeds fs = 0.05 at
    # k = 17 (0.051), so the block breaks away at exactly t = 17 ts.
    drive = block(fc_M=0.03, fs_M=0.05)
    ts = 1e-3
    t = np.arange(40) * ts
    u = 0.003 * np.arange(t.size)
    resp = drive.simulate(t, u)
    assert friction_events(resp) == [(0, "breakaway", "positive")]
    k = int(np.argmax(u > 0.05))
    assert k == 17 and resp.friction_events[0].time == pytest.approx(k * ts, abs=1e-15)
    assert np.all(resp.w_motor[: k + 1] == 0.0) and np.all(resp.w_motor[k + 1 :] > 0)


def test_breakaway_through_the_current_loop():
    # Through a current loop the torque is a continuous ramp-like exponential,
    # T = u (1 - exp(-t / tau)): breakaway at its crossing of fs, inside a sample.
    fs, u, tau = 0.05, 0.08, 3e-3
    drive = block(fc_M=0.03, fs_M=fs)
    t = np.arange(30) * 1e-3
    resp = drive.simulate(t, np.full(t.size, u), actuator=bk.CurrentLoop(tau),
                          initial_state=[0.0, 0.0, 0.0, 0.0])
    (ev,) = resp.friction_events
    expect = -tau * math.log1p(-fs / u)
    assert ev.kind == "breakaway" and abs(ev.time - expect) < 1e-12, (ev, expect)


@pytest.mark.parametrize("u, kinds", [
    (0.04, [(0, "stuck", "none")]),  # |u| < fs: sticks when the speed reaches zero
    (0.08, [(0, "reversal", "positive")]),  # |u| > fs: turns round without sticking
])
def test_stick_or_reverse_at_zero_speed(u, kinds):
    drive = block(fc_M=0.03, fs_M=0.05)
    t = np.arange(500) * 1e-3
    resp = drive.simulate(t, np.full(t.size, u), initial_state=[-1.0, 0.0, 0.0])
    assert friction_events(resp) == kinds


def test_zero_friction_is_the_frictionless_drive():
    t = np.arange(4001) * 1e-3
    u = np.where(t < 2.0, 0.157, 0.0)
    plain = bk.TwoMassDrive(**PAPER, theta=THETA).simulate(t, u)
    zero = bk.TwoMassDrive(**PAPER, theta=THETA, fc_M=0.0, fc_L=0.0).simulate(t, u)
    assert np.array_equal(plain.states, zero.states)
    assert zero.friction_modes is None and not zero.stuck.any()


def paper_step_to_zero(n_samples: int = 30001):
    # Paper A's drive with Coulomb friction, from the steady state of 0.942 N m, the
    # torque stepped to 0 at t = 0.
    drive = bk.TwoMassDrive(**PAPER, theta=THETA, fc_M=0.01, fc_L=0.02)
    t = np.arange(n_samples) * 1e-3
    u = np.zeros(t.size)
    return drive, t, u, drive.steady_state(0.942)


def test_paper_drive_stepped_to_zero_matches_the_reference():
    drive, t, u, x0 = paper_step_to_zero()
    with warnings.catch_warnings():
        warnings.simplefilter("error", bk.SensitivityWarning)
        resp = drive.simulate(t, u, initial_state=x0)
    ref = reference_simulate(drive, t, u, initial_state=x0, rtol=1e-13)
    report = compare_to_reference(resp, ref)
    print(f"\npaper drive with Coulomb friction, 0.942 N m -> 0: speed error ratio "
          f"{report.speed_error_ratio:.2e}, {report.n_events} events, max event-time "
          f"difference {report.max_event_time_diff:.2e} s")
    kinds = [(e.inertia, e.kind) for e in resp.friction_events]
    assert (0, "stuck") in kinds and (1, "stuck") in kinds  # both end at rest
    assert report.same_event_sequence
    assert report.speed_error_ratio <= SPEED_RTOL
    assert report.max_event_time_diff <= 1e-6
    assert np.array_equal(resp.stuck, ref.stuck_array)


@pytest.mark.parametrize("law", ["paper", "no-pull", "modelica"])
def test_stick_slip_chain_matches_the_reference(law):
    # A chain driven back and forth through its gaps, with stiction on every inertia:
    # sticking, breakaway and reversal events, contact changes in between.
    chain = bk.DriveChain(J=[0.01, 0.03, 0.2], f=[0.01, 0.02, 0.05], k=[60.0, 150.0],
                          d=[0.2, 0.5], theta=[0.02, 0.01], fc=[0.05, 0.02, 0.1],
                          fs=[0.08, 0.03, 0.15])
    t = np.arange(2001) * 1e-3  # everything sticks by 1.9 s
    u = np.where((t // 0.2) % 2 == 0, 1.0, -0.8) * (t < 1.0)
    resp = chain.simulate(t, u, law=law)
    ref = reference_simulate(chain, t, u, law=law, rtol=1e-13)
    report = compare_to_reference(resp, ref)
    kinds = {e.kind for e in resp.friction_events}
    assert len(resp.contact_events) > 5 and {"stuck", "breakaway", "reversal"} <= kinds
    assert resp.stuck[-1].all()
    assert report.same_event_sequence, (resp.events, ref.events)
    assert report.speed_error_ratio <= SPEED_RTOL, report
    assert report.max_event_time_diff <= 1e-6, report


@pytest.mark.parametrize("law", ["paper", "modelica"])
def test_numpy_twin_matches_kernel(law):
    chain = bk.DriveChain(J=[0.01, 0.03, 0.2], f=[0.01, 0.02, 0.05], k=[60.0, 150.0],
                          d=[0.2, 0.5], theta=[0.02, 0.01], fc=[0.05, 0.0, 0.1],
                          fs=[0.08, 0.03, 0.15])
    t = np.arange(801) * 1e-3
    u = np.where((t // 0.2) % 2 == 0, 1.0, -0.8) * (t < 0.6)
    kw = dict(law=law, actuator=bk.CurrentLoop(2e-3))
    a = bk.simulate_drive(chain, t, u, **kw)
    b = bk.simulate_drive(chain, t, u, backend="numpy", **kw)
    assert len(a.friction_events) > 3
    np.testing.assert_allclose(a.states, b.states, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(a.stuck, b.stuck)
    np.testing.assert_allclose(a.event_array, b.event_array, rtol=0, atol=1e-12)


def test_batch_with_friction_matches_single_runs():
    drives = [bk.TwoMassDrive(**PAPER, theta=th, fc_M=0.01, fc_L=0.02) for th in (0.02, 0.04)]
    t = np.arange(2001) * 1e-3
    u = np.where(t < 1.0, 0.3, 0.0)
    batch = bk.simulate_batch(drives, t, u, workers=2)
    for d, r in zip(drives, batch, strict=True):
        one = d.simulate(t, u)
        assert np.array_equal(r.states, one.states)
        assert np.array_equal(r.event_array, one.event_array)
        assert np.array_equal(r.stuck, one.stuck)


@pytest.mark.parametrize("kw, match", [
    (dict(fc_M=0.02, fs_M=0.01), "fs_M must be >= fc_M"),
    (dict(fc_L=-0.01), "fc_L must be >= 0"),
    (dict(fs_L=-0.01), "fs_L must be >= 0"),
    (dict(fc_M=math.nan), "fc_M must be finite"),
])
def test_bad_friction_is_refused(kw, match):
    with pytest.raises(InputError, match=match) as info:
        bk.TwoMassDrive(**PAPER, theta=THETA, **kw)
    assert "\n" not in str(info.value)


def test_bad_chain_friction_is_refused():
    base = dict(J=[1.0, 1.0], f=[0.0, 0.0], k=[1.0], d=[0.0], theta=[0.1])
    with pytest.raises(InputError, match=r"fs\[1\] must be >= fc\[1\]"):
        bk.DriveChain(**base, fc=[0.0, 0.2], fs=[0.0, 0.1])
    with pytest.raises(InputError, match=r"fc\[0\] must be >= 0"):
        bk.DriveChain(**base, fc=[-0.1, 0.0])
    with pytest.raises(InputError, match="fc must have 2 entries"):
        bk.DriveChain(**base, fc=[0.1])


# --------------------------------------------------------------------------- random

#: Random stick-slip cases whose bars must be asserted, of 25 drawn (derandomized;
#: ``-s`` prints the counts). Which cases are drawn depends on hypothesis's version:
#: with 6.170, 2 of the 25 make the scipy reference stop on "contact chatter" (one
#: shrinks to theta at its 1e-4 floor with breakaway equal to Coulomb), its own limit,
#: counted apart; 23 are checked.
MIN_FRICTION_CHECKED = 22
#: Smallest half-width drawn (rad): a dead zone of 0 or 1e-12 rad makes each contact
#: change a crossing of a vanishing gap, whose instant no two simulators agree on (a
#: drawn case with theta 1e-12 matched the reference's speeds to 7e-13 and its event
#: times only to 5e-5 s; one with theta 0 made the reference chatter).
MIN_THETA = 1e-4


@st.composite
def friction_cases(draw):
    """Two or three inertias with resonances of 5 .. 100 rad/s, Coulomb torques of 1 ..
    30 % of the drive torque and breakaway 1 .. 2 times Coulomb, under a square-wave
    torque that stops halfway (so the record ends in sticking)."""
    n = draw(st.integers(2, 3))
    J = np.array([10 ** draw(st.floats(-3, 0)) for _ in range(n)])
    j_red = J[:-1] * J[1:] / (J[:-1] + J[1:])
    k = np.array([(10 ** draw(st.floats(0.7, 2))) ** 2 for _ in range(n - 1)]) * j_red
    d = np.array([draw(st.floats(0.0, 0.3)) for _ in range(n - 1)]) * 2 * np.sqrt(k * j_red)
    f = J * np.array([draw(st.floats(0.0, 2.0)) for _ in range(n)])
    theta = np.array([draw(st.floats(MIN_THETA, 0.05)) for _ in range(n - 1)])
    amp = J.sum() * draw(st.floats(5.0, 50.0))
    fc = amp * np.array([draw(st.floats(0.01, 0.3)) for _ in range(n)])
    fs = fc * np.array([draw(st.floats(1.0, 2.0)) for _ in range(n)])
    chain = bk.DriveChain(J=J, f=f, k=k, d=d, theta=theta, fc=fc, fs=fs)
    t = np.arange(801) * 1e-3
    period = draw(st.floats(0.05, 0.3))
    u = amp * np.where((t // period) % 2 == 0, 1.0, -0.7) * (t < 0.4)
    law = draw(st.sampled_from(["paper", "no-pull", "modelica"]))
    return chain, t, u, law


def test_random_stick_slip_matches_the_reference():
    counts = {"checked": 0, "warned": 0, "ill-conditioned": 0, "reference chatters": 0}

    @settings(max_examples=25, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(case=friction_cases())
    def one_case(case):
        chain, t, u, law = case
        try:
            cond = check_conditioning(chain, t, u, law=law)
        except RuntimeError as exc:  # the reference's limit, not the kernel's
            if "contact chatter" not in str(exc):
                raise
            counts["reference chatters"] += 1
            return
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", bk.SensitivityWarning)
            resp = chain.simulate(t, u, law=law)
        if not cond.well_conditioned:
            counts["ill-conditioned"] += 1
            return
        if resp.near_grazing:
            counts["warned"] += 1
            return
        report = compare_to_reference(resp, cond.reference)
        assert report.same_event_sequence, (resp.events, cond.reference.events)
        assert report.speed_error_ratio <= SPEED_RTOL, report
        assert report.max_event_time_diff <= 1e-6, report
        counts["checked"] += 1

    one_case()
    print(f"\nrandom stick-slip cases: {counts}")
    assert counts["checked"] >= MIN_FRICTION_CHECKED, counts


def test_sensitivity_check_handles_friction_events():
    drive, t, u, x0 = paper_step_to_zero(30001)
    report = bk.assess_sensitivity(drive, t[::10], u[::10], initial_state=x0, refine=2)
    assert report.same_events and not report.sensitive, report
