"""The independent reference simulator (:mod:`backlashkit.verify`) against closed forms
and against a plain ``solve_ivp`` with terminal events.

None of these tests uses the compiled kernel: they establish that the reference is
right, so that ``test_accuracy.py`` can judge the kernel with it.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.optimize import brentq

import backlashkit as bk
from backlashkit.verify import (
    check_conditioning,
    compare_to_reference,
    naive_simulate,
    reference_simulate,
)

# Paper A, Section 5 (Ravanbod-Shirazi & Besancon-Voda 2002; /work/shared/papers/NOTES.md).
PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2


def linear_chain_matrices(chain: bk.DriveChain) -> tuple[np.ndarray, np.ndarray]:
    """``(A, B)`` of the chain with every shaft engaged and no backlash, written out by
    hand from the equations of motion (independent of ``verify``)."""
    n = len(chain.J)
    s = 2 * n - 1
    a = np.zeros((s, s))
    for i in range(n):
        a[i, i] -= chain.f[i] / chain.J[i]
    for j in range(n - 1):
        k, d = chain.k[j], chain.d[j]
        # torque T_j = k phi_j + d (w_j - w_{j+1}) leaves inertia j, enters j + 1
        for i, sign in ((j, -1.0), (j + 1, 1.0)):
            a[i, n + j] += sign * k / chain.J[i]
            a[i, j] += sign * d / chain.J[i]
            a[i, j + 1] -= sign * d / chain.J[i]
        a[n + j, j], a[n + j, j + 1] = 1.0, -1.0
    b = np.zeros(s)
    b[0] = 1.0 / chain.J[0]
    return a, b


def zoh_linear(chain: bk.DriveChain, t: np.ndarray, u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Exact zero-order-hold response of the linear chain (uniform grid)."""
    a, b = linear_chain_matrices(chain)
    s = a.shape[0]
    big = np.zeros((s + 1, s + 1))
    big[:s, :s] = a
    big[:s, s] = b
    e = expm(big * (t[1] - t[0]))
    ad, bd = e[:s, :s], e[:s, s]
    out = np.empty((t.size, s))
    out[0] = x0
    for i in range(t.size - 1):
        out[i + 1] = ad @ out[i] + bd * u[i]
    return out


# --------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize(
    "chain",
    [
        bk.TwoMassDrive(**PAPER, theta=0.0).to_chain(),
        bk.DriveChain(J=[0.01, 0.03, 0.2], f=[0.01, 0.0, 0.05], k=[60.0, 150.0],
                      d=[0.02, 0.1], theta=[0.0, 0.0]),
    ],
    ids=["two-mass", "three-mass"],
)
def test_zero_backlash_paper_law_is_the_linear_system(chain):
    # theta = 0 with the paper law: both flanks carry k phi + d dphi/dt, so the drive is
    # linear; the twist changes sign many times (flank-to-flank switches at one instant).
    t = np.arange(1501) * 1e-3
    u = 0.3 * np.sign(np.sin(9.0 * t)) + 0.05
    x0 = np.concatenate([np.linspace(1.0, -1.0, len(chain.J)), np.full(len(chain.J) - 1, 1e-3)])
    ref = reference_simulate(chain, t, u, initial_state=x0, rtol=1e-12)
    exact = zoh_linear(chain, t, u, x0)
    scale = np.abs(exact).max(axis=0)
    assert np.all(np.abs(ref.states - exact) <= 1e-9 * scale)
    # every loss of a flank is a gain of the other at the same instant
    lost = [e for e in ref.events if e.kind == "contact_lost"]
    assert len(lost) >= 10
    for e in lost:
        nxt = ref.events[ref.events.index(e) + 1]
        assert nxt.kind == "contact_made" and nxt.shaft == e.shaft and nxt.time == e.time
        assert nxt.flank != e.flank


@pytest.mark.parametrize("law", ["paper", "no-pull"])
def test_free_flight_inside_the_gap_is_first_order_decay(law):
    jm, jl, fm, fl, u = PAPER["J_M"], PAPER["J_L"], PAPER["f_M"], PAPER["f_L"], 0.05
    drive = bk.TwoMassDrive(**PAPER, theta=5.0)  # never closed within 0.5 s
    t = np.arange(501) * 1e-3
    w0m, w0l = 3.0, -1.0
    ref = reference_simulate(drive, t, np.full(t.size, u), law=law,
                             initial_state=[w0m, w0l, 0.0], rtol=1e-12)
    assert ref.events == () and np.all(ref.modes == 0)
    wi, tau_m, tau_l = u / fm, jm / fm, jl / fl
    w_m = wi + (w0m - wi) * np.exp(-t / tau_m)
    w_l = w0l * np.exp(-t / tau_l)
    phi = wi * t + (w0m - wi) * tau_m * (1 - np.exp(-t / tau_m)) - w0l * tau_l * (
        1 - np.exp(-t / tau_l))
    np.testing.assert_allclose(ref.w_motor, w_m, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(ref.w_load, w_l, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(ref.phi_d, phi, rtol=0, atol=1e-11)


@pytest.mark.parametrize("rtol", [1e-10, 1e-12])
def test_loop_steps_keep_free_flight_behind_a_current_loop_exact(rtol):
    """Free flight behind a current loop of 1 ms, against its closed form: the loop's
    torque ``u + (T0 - u) e^(-t / tau_i)`` drives the motor, the load coasts. DOP853's
    steps had outgrown the loop's stability interval once its decay lay below the error
    control's notice: at ``rtol`` 1e-12 the loop's torque grew back and the motor's
    speed drifted from the closed form (``_reference_engine.LOOP_MAX_STEP``)."""
    jm, jl, fm, fl, u, t0q, tau = (PAPER["J_M"], PAPER["J_L"], PAPER["f_M"], PAPER["f_L"],
                                   0.0, 0.157, 1e-3)
    drive = bk.TwoMassDrive(**PAPER, theta=50.0)  # never closed within 1.5 s
    t = np.arange(1501) * 1e-3
    w0m, w0l = 16.0, 15.0
    ref = reference_simulate(drive, t, np.full(t.size, u), initial_state=[w0m, w0l, 0.0, t0q],
                             actuator=bk.CurrentLoop(tau_i=tau), rtol=rtol)
    assert ref.events == () and np.all(ref.modes == 0)
    b = (t0q - u) / (fm - jm / tau)  # the loop's share of the motor's speed
    w_m = u / fm + (w0m - u / fm - b) * np.exp(-t * fm / jm) + b * np.exp(-t / tau)
    torque = u + (t0q - u) * np.exp(-t / tau)
    for got, want in ((ref.loop_torque, torque), (ref.w_motor, w_m),
                      (ref.w_load, w0l * np.exp(-t * fl / jl))):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


def test_loop_max_step_lies_within_every_explicit_methods_stability_interval(capsys):
    """The stability intervals ``LOOP_MAX_STEP``'s comment cites, from scipy's own
    Butcher tableaux: ``|R(z)| <= 1`` for the stability function ``R(z) = 1 + z b^T (I -
    z A)^-1 1`` on the negative real axis down to the printed boundary (``-s``), and
    the bound of two lags inside each."""
    from scipy.integrate._ivp import rk

    from backlashkit._reference_engine import LOOP_MAX_STEP

    for method in (rk.RK23, rk.RK45, rk.DOP853):
        b = np.asarray(method.B, float)
        a = np.zeros((b.size, b.size))  # RK45's A leaves out its last, zero column
        given = np.asarray(method.A, float)[: b.size, : b.size]
        a[:, : given.shape[1]] = given

        def r(z, a=a, b=b):
            return 1.0 + z * b @ np.linalg.solve(np.eye(b.size) - z * a, np.ones(b.size))

        zs = -np.arange(1, 100_001) * 1e-4  # to -10
        edge = zs[np.argmax([abs(r(z)) > 1.0 for z in zs])]
        with capsys.disabled():
            print(f"{method.__name__}: stable on the negative real axis down to {edge:.2f}")
        assert -edge > LOOP_MAX_STEP and all(abs(r(z)) <= 1.0 for z in zs[zs > edge])


def test_paper_step_down_behind_a_loop_matches_the_kernel(capsys):
    """Paper A's step-down (0.942 N m held, 0 at 2 s, 8 s) with Coulomb friction
    behind a 1 ms loop, the records ``benchmarks/real_drive.py`` makes: the reference
    at its default ``rtol`` against the kernel's exact flow. Before the loop bounded
    its steps they differed by 1.0e-7 rad/s (``-s`` prints the difference)."""
    drive = bk.TwoMassDrive(**PAPER, theta=THETA, fc_M=0.01, fc_L=0.02)
    t = np.arange(8000) * 1e-3
    u = np.where(t < 2.0, 0.942, 0.0)
    loop, x0 = bk.CurrentLoop(tau_i=1e-3), drive.steady_state(0.942)
    ref = reference_simulate(drive, t, u, actuator=loop, initial_state=x0)
    kernel = drive.simulate(t, u, actuator=loop, initial_state=x0)
    gap = float(np.max(np.abs(ref.states[:, :2] - kernel.states[:, :2])))
    with capsys.disabled():
        print(f"reference against kernel behind a 1 ms loop: {gap:.2g} rad/s at most")
    assert [e.kind for e in ref.events] == [e.kind for e in kernel.events]
    assert gap < 1e-8


@pytest.mark.parametrize("law", ["paper", "no-pull"])
@pytest.mark.parametrize("flank", [1, -1])
def test_contact_time_of_a_coasting_drive_is_exact(law, flank):
    # No friction and no torque: the twist grows linearly until it meets the flank.
    chain = bk.DriveChain(J=[0.02, 0.05], f=[0.0, 0.0], k=[80.0], d=[0.3], theta=[0.04])
    rel = 0.7 * flank
    x0 = [rel, 0.0, -0.01 * flank]
    t = np.arange(201) * 1e-3
    ref = reference_simulate(chain, t, np.zeros(t.size), law=law, initial_state=x0)
    first = ref.events[0]
    assert (first.kind, first.flank) == ("contact_made", "positive" if flank > 0 else "negative")
    t_c = (0.04 + 0.01) / 0.7
    assert abs(first.time - t_c) < 1e-14
    # before it: exact uniform motion
    before = t < t_c
    np.testing.assert_allclose(ref.phi_d[before], -0.01 * flank + rel * t[before], rtol=0,
                               atol=1e-15)
    assert np.all(ref.modes[before] == 0) and np.all(ref.modes[t > t_c + 1e-9][:5] == flank)


@pytest.mark.parametrize("law", ["paper", "no-pull"])
def test_event_states_lie_on_their_switching_surfaces(law):
    chain = bk.DriveChain(J=[0.01, 0.03, 0.2], f=[0.01, 0.02, 0.05], k=[60.0, 150.0],
                          d=[0.2, 0.5], theta=[0.02, 0.01])
    t = np.arange(1201) * 1e-3
    u = np.repeat([0.6, -0.5, 0.2, -0.8, 0.0, 0.7], 201)[: t.size]
    ref = reference_simulate(chain, t, u, law=law, rtol=1e-12)
    assert len(ref.events) > 20
    n = 3
    for e, x in zip(ref.events, ref.event_states, strict=True):
        j = e.shaft
        side = 1.0 if e.flank == "positive" else -1.0
        gap = side * x[n + j] - chain.theta[j]  # twist beyond the flank, rad
        torque = side * (chain.k[j] * (x[n + j] - side * chain.theta[j])
                         + chain.d[j] * (x[j] - x[j + 1]))  # pushing spring-damper torque
        if law == "paper":
            assert abs(gap) < 1e-13
        elif e.kind == "contact_made":
            # closes when both the twist and the spring-damper torque reach the flank
            assert gap > -1e-13 and torque > -1e-10
            assert min(abs(gap), abs(torque) / chain.k[j]) < 1e-13
        else:
            assert abs(torque) / chain.k[j] < 1e-13 and gap > -1e-13


def test_both_laws_coincide_without_shaft_damping():
    chain = bk.DriveChain(J=[0.01, 0.03], f=[0.01, 0.02], k=[60.0], d=[0.0], theta=[0.02])
    t = np.arange(801) * 1e-3
    u = np.repeat([0.6, -0.5, 0.2, -0.8], 201)[: t.size]
    a = reference_simulate(chain, t, u, law="paper")
    b = reference_simulate(chain, t, u, law="no-pull")
    np.testing.assert_array_equal(a.states, b.states)
    assert a.events == b.events


# --------------------------------------------------------------------------- grazing


def tangent_case(margin_rel: float):
    """Free flight towards the positive flank with motor friction, decelerated by a
    constant torque, so that the twist peaks at ``theta (1 - margin_rel)`` (closed
    form: ``w_M = w_i + (w_0 - w_i) exp(-t / tau)``, load at rest)."""
    jm, jl, fm, k, d, theta, w0, u0 = 0.01, 1.0, 0.02, 100.0, 0.5, 0.02, 1.0, -0.4
    wi, tau = u0 / fm, jm / fm
    t_peak = tau * np.log((w0 - wi) / -wi)
    rise = wi * t_peak + (w0 - wi) * tau * (1 - np.exp(-t_peak / tau))
    chain = bk.DriveChain(J=[jm, jl], f=[fm, 0.0], k=[k], d=[d], theta=[theta])
    x0 = np.array([w0, 0.0, theta * (1 - margin_rel) - rise])

    def phi(tt):
        return x0[2] + wi * tt + (w0 - wi) * tau * (1 - np.exp(-tt / tau))

    return chain, x0, t_peak, phi


@pytest.mark.parametrize("law", ["paper", "no-pull"])
def test_near_miss_is_recorded_as_a_graze(law):
    chain, x0, t_peak, _ = tangent_case(1e-9)
    t = np.arange(41) * 1e-3
    ref = reference_simulate(chain, t, np.full(t.size, -0.4), law=law, initial_state=x0,
                             rtol=1e-12)
    assert ref.events == ()
    (g,) = ref.grazes
    assert g.shaft == 0 and abs(g.time - t_peak) < 1e-6
    assert g.margin == pytest.approx(-1e-9 * 0.02, rel=0.05)


@pytest.mark.parametrize("law", ["paper", "no-pull"])
@pytest.mark.parametrize("depth", [1e-3, 1e-7, 1e-10])
def test_short_poke_past_the_flank_is_caught(law, depth):
    # The twist pokes depth * theta past the flank: contact for a few microseconds at
    # most, well inside one solver step.
    chain, x0, t_peak, phi = tangent_case(-depth)
    t = np.arange(41) * 1e-3
    ref = reference_simulate(chain, t, np.full(t.size, -0.4), law=law, initial_state=x0,
                             rtol=1e-12)
    made, lost = ref.events
    assert (made.kind, lost.kind) == ("contact_made", "contact_lost")
    t_made = brentq(lambda s: phi(s) - 0.02, 0.0, t_peak, xtol=1e-16)
    assert abs(made.time - t_made) < 1e-9
    assert made.time < lost.time < t_peak + 2 * (t_peak - t_made)


# --------------------------------------------------------------------------- machinery


def _solve_ivp_paper_law(drive, t, u_level, t_end):
    """Paper law for a two-mass drive with scipy's own terminal events (constant input)."""
    jm, jl, k, fm, fl, fs, th = (drive.J_M, drive.J_L, drive.k_sh, drive.f_M, drive.f_L,
                                 drive.f_sh, drive.theta)

    def rhs(_t, x, mode):
        tq = 0.0 if mode == 0 else k * (x[2] - mode * th) + fs * (x[0] - x[1])
        return [(u_level - fm * x[0] - tq) / jm, (tq - fl * x[1]) / jl, x[0] - x[1]]

    def make(mode):
        evs = []
        if mode == 0:
            up = lambda _t, x, m: x[2] - th  # noqa: E731
            up.terminal, up.direction = True, 1
            dn = lambda _t, x, m: x[2] + th  # noqa: E731
            dn.terminal, dn.direction = True, -1
            evs = [up, dn]
        else:
            out = lambda _t, x, m: x[2] - mode * th  # noqa: E731
            out.terminal, out.direction = True, -mode
            evs = [out]
        return evs

    x, t0, mode = np.zeros(3), 0.0, 0
    states = np.empty((t.size, 3))
    events = []
    while True:
        # max_step: solve_ivp only checks the sign of an event function at step ends;
        # after a contact loss the twist dips below theta and comes back within ~5 ms,
        # and a longer first step would "find" the crossing at the restart point itself
        sol = solve_ivp(rhs, (t0, t_end), x, method="DOP853", rtol=1e-13,
                        atol=[1e-12, 1e-12, 1e-14], events=make(mode), args=(mode,),
                        dense_output=True, max_step=1e-3)
        stop = sol.t[-1]
        mask = (t >= t0) & (t < stop) if sol.status == 1 else (t >= t0) & (t <= t_end)
        if mask.any():
            states[mask] = sol.sol(t[mask]).T
        if sol.status != 1:
            return states, events
        x, t0 = sol.y[:, -1], stop
        if mode == 0:
            mode = 1 if x[2] > 0 else -1
            events.append((stop, "contact_made"))
        else:
            mode = 0
            events.append((stop, "contact_lost"))


def test_matches_solve_ivp_with_terminal_events_on_the_paper_drive():
    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    t = np.arange(3001) * 1e-3
    states, events = _solve_ivp_paper_law(drive, t, 0.157, 3.0)
    ref = reference_simulate(drive, t, np.full(t.size, 0.157), rtol=1e-12)
    assert [e.kind for e in ref.events] == [k for _, k in events]
    np.testing.assert_allclose([e.time for e in ref.events], [s for s, _ in events], rtol=0,
                               atol=1e-9)
    scale = np.abs(states).max(axis=0)
    assert np.all(np.abs(ref.states - states) <= 1e-9 * scale)


def test_one_restart_per_input_change_and_per_event():
    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    t = np.arange(6001) * 1e-3
    u = np.where(t < 3.0, 0.157, 0.0)  # 3000 equal samples form one segment
    ref = reference_simulate(drive, t, u)
    assert ref.n_restarts == 2 + len(ref.events)
    assert ref.modes.dtype == np.int8 and ref.modes.shape == (t.size, 1)


def test_paper_experiment_references_agree_and_event_location_matters():
    # Paper A, Section 5: a1 = 0.157 N m for 40 s then 0, Ts = 1 ms (here 10 s + 10 s).
    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    t = np.arange(20001) * 1e-3
    u = np.where(t < 10.0, 0.157, 0.0)
    report = check_conditioning(drive, t, u)
    assert report.well_conditioned, report.reasons
    assert report.max_speed_rel_diff < 1e-8 and report.max_event_time_diff < 1e-8
    ref = report.reference
    # the loose reference with event location is far better than the same solver
    # stepping over the switches (its order drops to one at each switch)
    located = reference_simulate(drive, t, u, method="RK45", rtol=1e-8)
    naive = naive_simulate(drive, t, u, method="RK45", rtol=1e-8)
    err_located = compare_to_reference(located, ref).max_speed_error
    err_naive = float(np.max(np.abs(naive[:, :2] - ref.speeds)))
    # measured: 1.3e-2 rad/s without event location, 7e-5 rad/s with it
    assert err_naive > 1e-3
    assert err_naive > 50 * err_located


def test_conditioning_flags_references_that_part_ways():
    # A graze missed by 1e-6 theta: a loose RK23 reference cannot tell it from a hit.
    chain, x0, _, _ = tangent_case(1e-6)
    t = np.arange(301) * 1e-3
    u = np.where(t < 0.1, -0.4, np.where(t < 0.2, 0.3, 0.0))
    good = check_conditioning(chain, t, u, initial_state=x0)
    assert good.well_conditioned
    loose = (("RK23", 1e-3), ("DOP853", 1e-12))
    bad = check_conditioning(chain, t, u, initial_state=x0, runs=loose)
    assert not bad.well_conditioned and bad.reasons


def test_invalid_arguments():
    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    t = np.arange(10) * 1e-3
    with pytest.raises(bk.InputError, match="method"):
        reference_simulate(drive, t, np.zeros(10), method="Euler")
    with pytest.raises(bk.InputError, match="one sample per time step"):
        reference_simulate(drive, t, np.zeros(9))
    with pytest.raises(bk.InputError, match="initial_state"):
        reference_simulate(drive, t, np.zeros(10), initial_state=[0.0, 0.0])
    with pytest.raises(bk.InputError, match="law must be one of"):
        reference_simulate(drive, t, np.zeros(10), law="elastic")
    with pytest.raises(bk.InputError, match="increasing"):
        reference_simulate(drive, t[::-1], np.zeros(10))
