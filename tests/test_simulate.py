"""The compiled drive simulator: parity with its NumPy reference, closed forms,
batch determinism, near-grazing detection and the response object."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import StateSpace, lsim

import backlashkit as bk
from backlashkit import _core
from backlashkit.simulate import simulate_drive

# Paper A, Section 5 (Ravanbod-Shirazi & Besancon-Voda 2002).
PAPER = dict(J_M=4.88e-3, J_L=6.8e-2, k_sh=78.0, f_M=0.5e-2, f_L=0.5e-2, f_sh=1.575e-2)
THETA = 3.49e-2


def random_chain(rng: np.random.Generator, n: int) -> bk.DriveChain:
    return bk.DriveChain(
        J=rng.uniform(2e-3, 0.1, n),
        f=rng.uniform(0.0, 0.05, n),
        k=rng.uniform(10.0, 200.0, n - 1),
        d=rng.uniform(0.0, 0.05, n - 1),
        theta=rng.uniform(0.0, 0.05, n - 1),
    )


def random_torque(rng: np.random.Generator, n: int) -> np.ndarray:
    levels = rng.uniform(-0.4, 0.4, n // 50 + 1)
    return np.repeat(levels, 50)[:n]


@pytest.mark.parametrize("law", ["paper", "no-pull"])
@pytest.mark.parametrize("n_inertias", [2, 3])
@pytest.mark.parametrize("seed", range(4))
def test_rust_kernel_matches_numpy_reference(law, n_inertias, seed):
    rng = np.random.default_rng(seed)
    chain = random_chain(rng, n_inertias)
    t = np.arange(600) * 1e-3
    u = random_torque(rng, t.size)
    x0 = np.concatenate([rng.normal(0, 2, n_inertias), rng.uniform(-0.05, 0.05, n_inertias - 1)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bk.SensitivityWarning)
        fast = simulate_drive(chain, t, u, law=law, initial_state=x0)
        ref = simulate_drive(chain, t, u, law=law, initial_state=x0, backend="numpy")
    scale = np.abs(ref.states).max(axis=0) + 1e-12
    assert np.all(np.abs(fast.states - ref.states) <= 1e-9 * scale)
    assert np.array_equal(fast.modes, ref.modes)
    assert [(e.shaft, e.kind, e.flank) for e in fast.events] == [
        (e.shaft, e.kind, e.flank) for e in ref.events
    ]
    assert len(fast.events) > 0
    np.testing.assert_allclose(
        [e.time for e in fast.events], [e.time for e in ref.events], rtol=0, atol=1e-10
    )


@pytest.mark.parametrize("seed", range(5))
def test_matrix_exponential_and_integral_match_scipy(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(3, 3)) * rng.choice([1.0, 100.0, 2e4], size=(3, 3))
    tau = 1e-3
    e, f = _core.expm_and_integral3(a, tau)
    big = np.zeros((6, 6))
    big[:3, :3] = a
    big[:3, 3:] = np.eye(3)
    ref = expm(big * tau)
    np.testing.assert_allclose(e, ref[:3, :3], rtol=1e-11, atol=1e-13 * np.abs(ref[:3, :3]).max())
    np.testing.assert_allclose(f, ref[:3, 3:], rtol=1e-11, atol=1e-13 * np.abs(ref[:3, 3:]).max())


def test_zero_backlash_is_the_linear_two_mass_system():
    # theta = 0 with the paper's law is linear: compare with scipy.signal.lsim (ZOH input).
    drive = bk.TwoMassDrive(**PAPER, theta=0.0)
    jm, jl, k, fm, fl, fs = (PAPER[n] for n in ("J_M", "J_L", "k_sh", "f_M", "f_L", "f_sh"))
    a = np.array(
        [
            [-(fm + fs) / jm, fs / jm, -k / jm],
            [fs / jl, -(fl + fs) / jl, k / jl],
            [1.0, -1.0, 0.0],
        ]
    )
    sys = StateSpace(a, np.array([[1 / jm], [0], [0]]), np.eye(3), np.zeros((3, 1)))
    t = np.arange(3000) * 1e-3
    u = np.sin(7 * t) * 0.3
    u[t > 2] = -0.2
    _, _, x = lsim(sys, u, t, interp=False)
    r = drive.simulate(t, u)
    np.testing.assert_allclose(r.states, x, rtol=0, atol=1e-9 * np.abs(x).max())


def test_free_flight_inside_the_gap_is_first_order_decay():
    drive = bk.TwoMassDrive(**PAPER, theta=2.0)  # the gap is never closed in 0.2 s
    t = np.arange(201) * 1e-3
    r = drive.simulate(t, np.zeros(t.size), initial_state=[3.0, -1.0, 0.0])
    assert r.events == ()
    np.testing.assert_allclose(
        r.w_motor, 3.0 * np.exp(-PAPER["f_M"] / PAPER["J_M"] * t), rtol=1e-13
    )
    np.testing.assert_allclose(
        r.w_load, -1.0 * np.exp(-PAPER["f_L"] / PAPER["J_L"] * t), rtol=1e-13
    )


@pytest.mark.parametrize("law", ["paper", "no-pull"])
def test_steady_state_is_an_equilibrium(law):
    chain = bk.DriveChain(
        J=[0.01, 0.02, 0.05], f=[0.01, 0.02, 0.03], k=[50, 80], d=[0.01, 0.02], theta=[0.01, 0.03]
    )
    for torque in (0.6, -0.4):
        x0 = chain.steady_state(torque)
        t = np.arange(500) * 1e-3
        r = chain.simulate(t, np.full(t.size, torque), law=law, initial_state=x0)
        assert r.events == ()
        np.testing.assert_allclose(r.states[-1], x0, rtol=1e-10)
        assert np.all(r.modes == np.sign(torque))
        # every shaft carries the friction torque of the inertias beyond it
        np.testing.assert_allclose(r.shaft_torques[0], np.array([0.05, 0.03]) * x0[0], rtol=1e-10)


def test_paper_experiment_events_and_relation_4():
    # Paper A, eq. 4 / Fig. 5: after the step-down at t_s = 40 s the shaft leaves the
    # positive flank (t_c) and meets the negative one (t_b); the twist travels 2 theta.
    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    t = np.arange(80001) * 1e-3
    u = np.where(t < 40.0, 0.157, 0.0)
    r = drive.simulate(t, u)
    after = [e for e in r.events if e.time > 40.0]
    assert (after[0].kind, after[0].flank) == ("contact_lost", "positive")
    assert (after[1].kind, after[1].flank) == ("contact_made", "negative")
    assert 40.0 < after[0].time < after[1].time < 41.0
    # speeds settle to a1 * g_s = 0.157 * 100 = 15.7 rad/s before t_s (Section 5)
    assert abs(r.w_motor[39999] - 15.7) < 0.1
    assert r.near_grazing == ()
    # relation (4) itself: integral_{t_c}^{t_b} (w_M - w_L) dt = -2 theta, the speeds
    # integrated by the trapezoidal rule on a 1 us grid between the located events
    t_c, t_b = after[0].time, after[1].time
    i0 = 39_990  # restart 10 ms before t_s from the state on the grid
    x0 = [r.w_motor[i0], r.w_load[i0], r.phi_d[i0]]
    fine = t[i0] + np.arange(int(round((t_b + 1e-3 - t[i0]) / 1e-6)) + 1) * 1e-6
    rf = drive.simulate(fine, np.where(fine < 40.0, 0.157, 0.0), initial_state=x0)
    d = rf.w_motor - rf.w_load
    inside = (fine > t_c) & (fine < t_b)
    ends = np.interp([t_c, t_b], fine, d)
    tt = np.concatenate([[t_c], fine[inside], [t_b]])
    dd = np.concatenate([[ends[0]], d[inside], [ends[1]]])
    integral = float(np.sum(0.5 * (dd[1:] + dd[:-1]) * np.diff(tt)))
    assert abs(integral + 2 * THETA) < 1e-6 * THETA, integral


def _tangent_case(margin_rel: float):
    """Free flight towards the positive flank, decelerating so that the twist peaks at
    theta - margin_rel * theta (closed form: no friction, constant torque)."""
    jm, w0, theta = 0.01, 1.0, 0.02
    a = jm * w0 / 0.0255  # the twist peaks at t = 25.5 ms, in the middle of a sample
    drive = bk.DriveChain(J=[jm, 1.0], f=[0.0, 0.0], k=[100.0], d=[0.0], theta=[theta])
    peak = w0**2 * jm / (2 * a)
    phi0 = theta - peak - margin_rel * theta
    t = np.arange(50) * 1e-3  # the motor reverses and would reach -theta at 0.07 s
    return drive, t, np.full(t.size, -a), [w0, 0.0, phi0], jm * w0 / a


def test_near_grazing_is_reported_and_warned():
    drive, t, u, x0, t_peak = _tangent_case(1e-9)
    with pytest.warns(bk.SensitivityWarning, match="grazing"):
        r = drive.simulate(t, u, initial_state=x0)
    assert r.events == ()
    (g,) = r.near_grazing
    assert g.shaft == 0 and abs(g.time - t_peak) < 1e-6 and -2e-9 < g.margin < 0


def test_clear_miss_is_not_reported():
    drive, t, u, x0, _ = _tangent_case(1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = drive.simulate(t, u, initial_state=x0)
    assert r.events == () and r.near_grazing == ()


def test_short_graze_inside_one_sample_is_caught():
    # The twist pokes 1e-4 theta past the flank for well under one sample: a check of the
    # grid values alone would miss the contact.
    drive, t, u, x0, t_peak = _tangent_case(-1e-4)
    r = drive.simulate(t, u, initial_state=x0)
    made, lost = r.events
    assert made.kind == "contact_made" and lost.kind == "contact_lost"
    assert made.time < t_peak < lost.time and lost.time - made.time < 1e-3
    assert np.floor(made.time / 1e-3) == np.floor(lost.time / 1e-3)


def test_batch_equals_single_runs_whatever_the_workers():
    thetas = np.linspace(0.0, 0.05, 12)
    drives = [bk.TwoMassDrive(**PAPER, theta=th) for th in thetas]
    t = np.arange(4000) * 1e-3
    u = np.where(t < 2.0, 0.157, -0.05)
    one = bk.simulate_batch(drives, t, u, workers=1)
    two = bk.simulate_batch(drives, t, u, workers=2)
    for d, a, b in zip(drives, one, two, strict=True):
        single = d.simulate(t, u)
        assert np.array_equal(a.states, single.states) and np.array_equal(b.states, single.states)
        assert a.events == single.events == b.events


def test_batch_with_a_current_loop_and_angles_matches_single_runs():
    """``simulate_batch`` takes the current loop and the angles as ``simulate_drive``
    does, and gives each drive's run, with Coulomb friction."""
    t = np.arange(1500) * 1e-3
    u = np.where(t < 0.5, 0.157, 0.0)
    drives = [bk.TwoMassDrive(**PAPER, theta=th, fc_M=fc) for th, fc in
              ((THETA, 0.01), (0.5 * THETA, 0.02), (2.0 * THETA, 0.005))]
    loop = bk.CurrentLoop(tau_i=1e-3)
    x0 = drives[0].steady_state(0.157)
    batch = bk.simulate_batch(drives, t, u, actuator=loop, positions=True, workers=2,
                              initial_state=x0)
    for d, a in zip(drives, batch, strict=True):
        single = d.simulate(t, u, actuator=loop, positions=True, initial_state=x0)
        assert np.array_equal(a.states, single.states) and a.events == single.events
        assert np.array_equal(a.phi_motor, single.phi_motor)
        assert np.array_equal(a.motor_torque, single.motor_torque)
    plain = bk.TwoMassDrive(**PAPER, theta=THETA)  # a loop without friction
    (alone,) = bk.simulate_batch([plain], t, u, actuator=loop)
    assert np.array_equal(alone.states, plain.simulate(t, u, actuator=loop).states)
    given = bk.simulate_batch(drives[:1], t, u, actuator=loop, initial_state=np.r_[x0, 0.0])
    assert given[0].motor_torque[0] == 0.0  # the loop's torque as given, not settled
    with pytest.raises(bk.InputError, match=r"initial_state must have shape \(3,\) or \(3, 3\)"):
        bk.simulate_batch(drives, t, u, initial_state=np.r_[x0, 0.0])


def test_response_columns_plot_and_pandas():
    import matplotlib.pyplot as plt

    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    t = np.arange(2000) * 1e-3
    r = drive.simulate(t, np.where(t < 1.0, 0.157, 0.0))
    cols = r.to_columns()
    assert list(cols) == ["t", "torque", "w_motor", "w_load", "phi_d", "shaft_torque"]
    df = r.to_pandas()
    assert df.index.name == "t" and np.array_equal(df["w_load"].to_numpy(), r.w_load)
    # an encoder drive's run tracks the angles, and a current loop's adds its torque
    tracked = drive.simulate(t, np.where(t < 1.0, 0.157, 0.0), positions=True,
                             actuator=bk.CurrentLoop(tau_i=1e-3)).to_pandas()
    assert list(tracked) == ["torque", "motor_torque", "w_motor", "w_load", "phi_d",
                             "shaft_torque", "phi_motor", "phi_load"]
    w = tracked["w_motor"].to_numpy()
    assert tracked["phi_motor"].iloc[0] == 0.0
    # the trapezoid of the speeds, within its own error (Ts^2 / 12 of the acceleration)
    assert np.allclose(np.diff(tracked["phi_motor"].to_numpy()), 0.5e-3 * (w[1:] + w[:-1]),
                       atol=1e-5)
    before = plt.get_fignums()
    fig = r.plot()
    assert len(fig.axes) == 3 and plt.get_fignums() == before
    # shaft torque is zero in the gap and spring + damper in contact
    gap = r.modes[:, 0] == 0
    assert np.all(r.shaft_torque[gap] == 0)
    assert np.any(r.shaft_torque[~gap] != 0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(J_M=-1.0), "J_M must be > 0"),
        (dict(k_sh=0.0), "k_sh must be > 0"),
        (dict(f_L=-0.1), "f_L must be >= 0"),
        (dict(theta=-0.01), "theta must be >= 0"),
        (dict(J_L=float("nan")), "J_L must be finite"),
    ],
)
def test_invalid_drive_parameters(kwargs, match):
    params = {**PAPER, "theta": THETA, **kwargs}
    with pytest.raises(bk.InputError, match=match):
        bk.TwoMassDrive(**params)


@pytest.mark.parametrize(
    ("t", "u", "match"),
    [
        ([0.0, 0.001, 0.003], [0, 0, 0], "uniformly sampled"),
        ([0.0, 0.002, 0.001], [0, 0, 0], "strictly increasing"),
        ([0.0], [0.0], "at least 2 samples"),
        ([0.0, 0.001, 0.002], [0, np.nan, 0], r"torque has a non-finite value \(nan\) at index 1"),
        ([0.0, 0.001, 0.002], [0, 0], "one sample per time step"),
    ],
)
def test_invalid_signals(t, u, match):
    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    with pytest.raises(bk.InputError, match=match):
        drive.simulate(t, u)


def test_unknown_law_and_missing_theta():
    t = np.arange(10) * 1e-3
    with pytest.raises(bk.InputError, match="law must be one of"):
        bk.TwoMassDrive(**PAPER, theta=THETA).simulate(t, np.zeros(10), law="elastic")
    with pytest.raises(bk.InputError, match="no backlash value"):
        bk.TwoMassDrive(**PAPER).simulate(t, np.zeros(10))


def test_stiff_drive_uses_substeps_and_stays_exact():
    # A shaft resonance of ~3e4 rad/s at Ts = 1 ms: the kernel subdivides the sample
    # internally; compare with a run at a 50x finer grid sampled back.
    chain = bk.DriveChain(J=[1e-4, 2e-4], f=[1e-3, 1e-3], k=[5e4], d=[0.05], theta=[1e-3])
    t = np.arange(200) * 1e-3
    u = np.where(t < 0.1, 0.2, -0.2)
    coarse = chain.simulate(t, u)
    tf = np.arange(199 * 50 + 1) * 2e-5
    fine = chain.simulate(tf, np.repeat(u, 50)[: tf.size])
    np.testing.assert_allclose(
        coarse.states, fine.states[::50], rtol=0, atol=1e-8 * np.abs(fine.states).max()
    )


@pytest.mark.parametrize("law", ["paper", "no-pull"])
@pytest.mark.parametrize("poke", [1e-7, 1e-9, 1e-11])
@pytest.mark.parametrize("backend", ["rust", "numpy"])
def test_tiny_poke_is_one_short_contact_and_flagged(law, poke, backend):
    # Regression: a twist poking past the flank by 1e-7..1e-11 theta used to switch back
    # and forth at the contact instant until the chatter guard gave up.
    jm, w0, theta = 0.01, 1.0, 0.02
    a = jm * w0 / 0.0255
    drive = bk.DriveChain(J=[jm, 1.0], f=[0.0, 0.0], k=[100.0], d=[0.5], theta=[theta])
    t = np.arange(50) * 1e-3
    x0 = [w0, 0.0, theta - w0**2 * jm / (2 * a) + poke * theta]
    with pytest.warns(bk.SensitivityWarning):
        r = simulate_drive(
            drive, t, np.full(t.size, -a), law=law, initial_state=x0, backend=backend
        )
    made, lost = r.events
    assert (made.kind, lost.kind) == ("contact_made", "contact_lost")
    assert 0 < lost.time - made.time < 1e-4
    (g,) = r.near_grazing
    assert abs(g.time - 0.0255) < 1e-6 and g.margin == pytest.approx(poke, rel=0.01)


def test_assess_sensitivity_separates_well_and_ill_conditioned_runs():
    # The paper experiment is well conditioned (two grids agree to rounding); a three-mass
    # drive rattling through ~190 impacts in 3 s amplifies rounding to 1e-4 and beyond.
    drive = bk.TwoMassDrive(**PAPER, theta=THETA)
    t = np.arange(20001) * 1e-3
    calm = bk.assess_sensitivity(drive, t, np.where(t < 10.0, 0.157, 0.0))
    assert not calm.sensitive and calm.same_events and calm.speed_rel_diff < 1e-9
    chain = bk.DriveChain(
        J=[4.88e-3, 1e-2, 6.8e-2],
        f=[0.5e-2, 0.0, 0.5e-2],
        k=[78.0, 150.0],
        d=[1.575e-2, 3e-2],
        theta=[3.49e-2, 1e-2],
    )
    t = np.arange(3001) * 1e-3
    u = 0.4 * np.repeat([1.0, -0.8, 0.3, 0.0, -1.0, 0.6, -0.2, 0.9], 376)[: t.size]
    rattle = bk.assess_sensitivity(chain, t, u)
    assert rattle.sensitive and rattle.speed_rel_diff > 1e-6
    with pytest.raises(bk.InputError, match="refine must be an integer >= 2"):
        bk.assess_sensitivity(drive, t, np.zeros(t.size), refine=1)


def test_ringing_frequency_is_the_contact_modes_undamped_frequency():
    """``TwoMassDrive.ringing_frequency`` (used by the sampling checks and the current
    loop's bound) against the eigenvalues of the undamped contact mode's matrix in
    ``[w_M, w_L, phi_d]``."""
    d = bk.TwoMassDrive(**PAPER)
    a = np.array([[0.0, 0.0, -d.k_sh / d.J_M], [0.0, 0.0, d.k_sh / d.J_L], [1.0, -1.0, 0.0]])
    assert np.max(np.abs(np.linalg.eigvals(a).imag)) == pytest.approx(d.ringing_frequency,
                                                                      rel=1e-12)
