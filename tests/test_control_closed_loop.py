"""Closed loop of paper B (Section IV, Figs. 5-6) and beyond."""

import re

import control  # a test dependency: paper B's checks fail, not skip, without it
import numpy as np
import pytest

from backlashkit import (
    AdaptiveLaw,
    Backlash,
    ExactInverse,
    GainOnlyInverse,
    InputError,
    NoInverse,
    SmoothFilterInverse,
    SmoothRampInverse,
    SumOfSines,
    TableReference,
    simulate_closed_loop,
)
from backlashkit.control.closed_loop import build_problem, run_problem
from backlashkit.control.design import design_mrc
from backlashkit.papers.tao1995 import run_tao1995

# Paper B, Section IV: theta_b* = (0.91, 0.7, -0.35); Gamma = 5 I;
# theta_b(0) = (1.51, 0.2, -0.55); r = 10 sin(1.3 t); 60 s.
THETA_STAR = np.array([0.91, 0.7, -0.35])
PLANT = ([1.0], [1.0, -0.5, -1.5])
TRUE_B = Backlash(0.7, 1.3, -0.5)
LAW = AdaptiveLaw(gamma=5.0, theta_b0=(1.51, 0.2, -0.55), m0=0.02)
REF = SumOfSines([10.0], [1.3])


@pytest.fixture(scope="module")
def paper_runs():
    return run_tao1995(ts=1e-3)


def test_fig5_exact_adaptive_inverse(paper_runs):
    r = paper_runs["exact"]
    assert r.t[-1] == pytest.approx(60.0)
    assert r.rms_error_last() <= 1e-3  # last 20 s
    np.testing.assert_allclose(r.theta_b[-1], THETA_STAR, rtol=0.01)


def test_fig6_smooth_filter_inverse_alpha_6(paper_runs):
    assert paper_runs["smooth-filter"].rms_error_last() <= 2e-2


@pytest.mark.parametrize("name", ["none", "gain-only"])
def test_comparisons_error_remains_large(paper_runs, name):
    # Section IV: "In the latter cases, the tracking error remains large for large t."
    assert paper_runs[name].rms_error_last() >= 0.5


def test_gain_only_keeps_c_hat_zero(paper_runs):
    th = paper_runs["gain-only"].theta_b
    assert np.all(th[:, 0] == 0) and np.all(th[:, 2] == 0)
    th_none = paper_runs["none"].theta_b
    np.testing.assert_array_equal(th_none[-1], [1.51, 0.2, -0.55])


@pytest.mark.parametrize("name", ["exact", "smooth-filter", "none", "gain-only"])
def test_trace_plant_part_is_consistent(paper_runs, name):
    """Re-simulate y = G[B(v)] from the logged signals with python-control."""
    r = paper_runs[name]
    # u is B(v) of the same row: u lies between the two sides at v
    assert np.all(r.u >= TRUE_B.m * (r.v - TRUE_B.c_r) - 1e-9)
    assert np.all(r.u <= TRUE_B.m * (r.v - TRUE_B.c_l) + 1e-9)
    # independent integration (python-control, linear interpolation of the logged u) in
    # 0.5 s windows started from the logged plant state: the plant is unstable (pole
    # 1.5), so one 60 s open-loop re-simulation would amplify rounding by exp(90)
    from backlashkit.lti import as_state_space

    a, bb, c, _ = as_state_space(PLANT)
    sys = control.ss(a, bb[:, None], c[None, :], 0)
    scale = np.max(np.abs(r.y))
    worst = 0.0
    for k0 in range(0, r.t.size - 1, 500):
        sl = slice(k0, k0 + 501)
        res = control.forced_response(sys, T=r.t[sl], U=r.u[sl], X0=r.plant_state[k0])
        err = np.max(np.abs(res.outputs - r.y[sl]))
        worst = max(worst, err)
        if r.t[k0] >= 10.0:  # after the transient (no large jumps of u inside a sample)
            assert err <= 1e-5 * scale
    assert worst <= 1e-3 * scale  # includes interpolation across the early jumps of u


def test_result_does_not_change_when_the_step_is_refined():
    out = {}
    for h in (2e-3, 1e-3, 2.5e-4):
        out[h] = simulate_closed_loop(
            PLANT, TRUE_B, reference=REF, duration=30, ts=0.01, step=h, adaptation=LAW
        )
    for h in (2e-3, 1e-3):
        assert np.max(np.abs(out[h].y - out[2.5e-4].y)) < 1e-5
        assert np.max(np.abs(out[h].theta_b - out[2.5e-4].theta_b)) < 1e-5
    assert out[1e-3].n_switches == out[2.5e-4].n_switches


@pytest.mark.parametrize(
    "inverse",
    [
        ExactInverse(),
        SmoothFilterInverse(alpha=6.0),
        SmoothRampInverse(beta_r=2.0, beta_l=3.0),
        NoInverse(),
        GainOnlyInverse(),
    ],
)
def test_rust_kernel_matches_numpy_reference(inverse):
    d = design_mrc(PLANT)
    rng = np.random.default_rng(0)
    prob = build_problem(
        PLANT,
        TRUE_B,
        inverse=inverse,
        adaptation=LAW,
        reference=REF,
        duration=4.0,
        ts=0.01,
        step=1e-3,
        design=d,
        output_noise=lambda t: 0.01 * rng.uniform(-1, 1, t.size),
    )
    a = run_problem(prob, backend="rust")
    b = run_problem(prob, backend="numpy")
    for k in ("y", "ym", "ud", "v", "u", "thb"):
        np.testing.assert_allclose(a[k], b[k], rtol=1e-9, atol=1e-10)
    assert int(a["n_switches"]) == int(b["n_switches"])


def test_robust_bounded_with_noise_and_disturbance_500s():
    """Section III-C: sigma-modification keeps every signal bounded."""
    rng = np.random.default_rng(42)
    law = AdaptiveLaw(gamma=5.0, theta_b0=(1.51, 0.2, -0.55), m0=0.02, sigma=0.5, sigma_bound=3.0)
    r = simulate_closed_loop(
        PLANT,
        TRUE_B,
        reference=REF,
        duration=500.0,
        ts=0.05,
        adaptation=law,
        step=2e-3,
        output_noise=lambda t: 0.05 * rng.uniform(-1, 1, t.size),
        input_disturbance=lambda t: 0.3 * np.sign(np.sin(0.37 * t)),
    )
    for sig in (r.y, r.v, r.u, r.u_d, r.theta_b):
        assert np.all(np.isfinite(sig))
    late = r.t > 250
    # bounded: no growth from the first to the second half, errors of the order of the noise
    mid = (r.t > 50) & ~late
    for sig in (r.e, r.v, r.u):
        assert np.max(np.abs(sig[late])) <= 1.2 * np.max(np.abs(sig[mid]))
    assert np.max(np.abs(r.e[late])) < 5.0
    assert np.max(np.linalg.norm(r.theta_b, axis=1)) < 6.0
    assert r.theta_b[:, 1].min() >= 0.02 - 1e-12  # projection m_hat >= m0


PLANTS = {
    "o1-unstable-nstar1": ([2.0], [1.0, -1.0]),
    "o1-stable-nstar1": ([1.0], [1.0, 1.0]),
    "o2-unstable-nstar1": ([1.0, 1.0], [1.0, 1.0, -2.0]),
    "o2-stable-nstar2": ([3.0], [1.0, 2.0, 5.0]),
    "o3-stable-nstar2": ([1.0, 2.0], list(np.polymul([1, 1], [1, 1, 4]))),
    "o3-unstable-nstar2": ([-1.0, -3.0], list(np.polymul([1, -1], [1, 3, 2]))),
    "o4-unstable-nstar2": (
        list(np.polymul([1, 1], [1, 3])),
        list(np.polymul([1, 2, 5], np.polymul([1, -0.5], [1, 4]))),
    ),
    "o4-stable-nstar1": (
        list(np.polymul([1, 1], np.polymul([1, 3], [1, 2]))),
        list(np.polymul([1, 2, 5], np.polymul([1, 0.5], [1, 4]))),
    ),
}


@pytest.mark.parametrize("name", sorted(PLANTS))
@pytest.mark.parametrize("backlash", [Backlash(1.5, 0.4, -1.0), Backlash(0.3, 0.0, -0.6)])
def test_other_plants_and_backlash_shapes_track(name, backlash):
    th = backlash.theta_b
    law = AdaptiveLaw(gamma=5.0, theta_b0=(1.5 * th[0] + 0.1, 0.5 * th[1], 1.5 * th[2] - 0.1))
    r = simulate_closed_loop(
        PLANTS[name],
        backlash,
        reference=SumOfSines([5.0, 3.0], [1.3, 0.5]),
        duration=100.0,
        adaptation=law,
    )
    assert r.rms_error_last() <= 1e-2 * np.max(np.abs(r.y_m))
    np.testing.assert_allclose(r.theta_b[-1], th, atol=2e-3 * np.max(np.abs(th)))
    # and without the inverse the same loop is clearly worse
    if name == "o3-stable-nstar2":
        r0 = simulate_closed_loop(
            PLANTS[name],
            backlash,
            reference=SumOfSines([5.0, 3.0], [1.3, 0.5]),
            duration=100.0,
            adaptation=law,
            inverse=NoInverse(),
        )
        assert r0.rms_error_last() > 10 * r.rms_error_last()


def test_table_reference_and_plot():
    t = np.linspace(0, 40, 401)
    ref = TableReference(t, 10 * np.sin(1.3 * t))
    r = simulate_closed_loop(PLANT, TRUE_B, reference=ref, duration=40, adaptation=LAW)
    assert r.rms_error_last() < 0.05
    fig = r.plot()
    assert len(fig.axes) == 5
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    assert r.plot(ax=ax) is ax.figure
    # five Axes take the five panels, as the drive's response takes its three
    five = Figure().subplots(5, 1)
    assert r.plot(ax=five) is five[0].figure
    assert [a.get_ylabel() for a in five][:2] == ["output", "error e = y - y_m"]
    with pytest.raises(InputError, match="ax must be 5 Axes"):
        r.plot(ax=Figure().subplots(2, 1))
    # a table shorter than the run would be held at its last value: refused (a QA pass)
    with pytest.raises(InputError, match=re.escape(
            "the reference table ends at t = 40 s, before the run's end at duration = 60 s "
            "(it would hold its last value there)")):
        simulate_closed_loop(PLANT, TRUE_B, reference=ref, duration=60, adaptation=LAW)


def test_bad_arguments():
    from backlashkit import InputError

    with pytest.raises(InputError, match="A1"):
        simulate_closed_loop(([1.0, -2.0], [1.0, 1.0, 1.0]), TRUE_B, reference=REF, duration=1)
    with pytest.raises(InputError, match="ts must be <= duration"):
        simulate_closed_loop(PLANT, TRUE_B, reference=REF, duration=1, ts=2)
    with pytest.raises(InputError, match="theta_b0 must satisfy A3"):
        AdaptiveLaw(theta_b0=(-1.0, 0.2, -0.5))
    with pytest.raises(InputError, match="m0 must be <="):
        AdaptiveLaw(theta_b0=(1.0, 0.2, -0.5), m0=0.5)
